"""Body maps: the infant with each body region coloured by how often it was touched (the paper's
Figure 2 question, where the touches go), next to a bar per region with the numbers.

`write_body_map(frequency, path)` takes the fraction of test steps each of the 8 regions was touched
(`metrics.summarize(...)["region_touch_frequency"]`) and writes a PNG atomically. It needs offscreen
OpenGL (gl.choose_backend) for the self-touch infant.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mjx_protamer.atomic import replacing
from mjx_protamer.envs import body

UNTOUCHED = (0.78, 0.78, 0.80, 1.0)


def region_colors(frequency, cmap_name: str = "YlOrRd") -> tuple[np.ndarray, float]:
    """(8, 4) RGBA per region on a scale from 0 to the largest frequency, untouched regions grey; the scale top."""
    import matplotlib

    f = np.asarray(frequency, np.float64)
    top = float(f.max()) if f.size and f.max() > 0 else 1.0
    cmap = matplotlib.colormaps[cmap_name]
    colors = np.array([cmap(0.15 + 0.85 * v / top) if v > 0 else UNTOUCHED for v in f])
    return colors, top


def write_body_map(frequency, path: str | Path, title: str = "", env_config=None, size: int = 480) -> Path:
    """PNG of the infant coloured by `frequency` (8 values in body.REGIONS order, fractions of steps)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mjx_protamer.view.gl import choose_backend

    f = np.asarray(frequency, np.float64).reshape(-1)
    if f.shape != (len(body.REGIONS),):
        raise ValueError(f"a body map needs {len(body.REGIONS)} region frequencies, got {f.shape}")
    choose_backend()
    from mjx_protamer.view.infant_scene import InfantScene

    colors, top = region_colors(f)
    scene = InfantScene(env_config, size, size)
    try:
        image = scene.colored_frame(colors)
    finally:
        scene.close()
    fig, (ax_img, ax_bar) = plt.subplots(1, 2, figsize=(10, 4.6), gridspec_kw={"width_ratios": [1, 1.1]})
    ax_img.imshow(image)
    ax_img.set_axis_off()
    ax_img.set_title("seen from the feet: head at the top, its left arm on the left", fontsize=9)
    y = np.arange(len(f))[::-1]
    ax_bar.barh(y, f, color=colors, edgecolor="0.3")
    ax_bar.set_yticks(y, [n.replace("_", " ") for n in body.REGIONS])
    ax_bar.set_xlabel("fraction of test steps the region was touched")
    ax_bar.set_xlim(0, max(top * 1.15, 0.01))
    for yi, v in zip(y, f):
        ax_bar.text(v, yi, f" {v:.3f}", va="center", fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    try:
        with replacing(path) as tmp:
            fig.savefig(tmp, dpi=100, format="png")
    finally:
        plt.close(fig)
    return path


def write_condition_body_maps(run_config, frequencies: dict, out_dir: str | Path) -> list[Path]:
    """One body map per condition of a table2 run, as body_map_<condition>.png in out_dir, from
    `table2.artifacts.region_frequencies` ({condition: {"frequency": per region, "seeds": n}}). Nothing for the
    toy env; a machine without offscreen OpenGL gets a note instead of the pictures."""
    import sys

    from mjx_protamer.view.gl import GLUnavailable

    if run_config.env_name == "toy":
        return []
    paths = []
    try:
        for name, per in frequencies.items():
            paths.append(write_body_map(np.asarray(per["frequency"]), Path(out_dir) / f"body_map_{name}.png",
                                        f"{name}: where the hands touch ({per['seeds']} seed(s))", run_config.env))
    except GLUnavailable as e:
        print(f"note: no body maps: {e}", file=sys.stderr)
    return paths
