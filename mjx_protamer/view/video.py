"""Write frames as a video (.mp4 through the packaged ffmpeg of imageio-ffmpeg, or .gif) or one .png,
atomically: the file appears complete under its name or not at all."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mjx_protamer.atomic import replacing

FORMATS = (".mp4", ".gif", ".png")


def check_path(path: str | Path) -> Path:
    path = Path(path)
    if path.suffix.lower() not in FORMATS:
        raise ValueError(f"--out {path}: the file name must end in {', '.join(FORMATS)}")
    if not path.parent.exists():
        raise ValueError(f"--out {path}: the folder {path.parent} does not exist")
    return path


def write_frames(path: str | Path, frames: list[np.ndarray], fps: float) -> Path:
    """mp4/gif: every frame at `fps`; png: frames[0] (the caller picks which frame that is)."""
    import imageio.v3 as iio

    path = check_path(path)
    suffix = path.suffix.lower()
    with replacing(path) as tmp:
        if suffix == ".png":
            iio.imwrite(tmp, frames[0])
        elif suffix == ".gif":
            iio.imwrite(tmp, np.stack(frames), duration=1000.0 / fps, loop=0)
        else:
            _write_mp4(tmp, frames, fps)
    return path


def _write_mp4(path: Path, frames: list[np.ndarray], fps: float) -> None:
    import imageio_ffmpeg

    h, w = frames[0].shape[:2]
    writer = imageio_ffmpeg.write_frames(str(path), (w, h), fps=fps, codec="libx264", pix_fmt_out="yuv420p",
                                         macro_block_size=1, output_params=["-movflags", "+faststart"])
    writer.send(None)
    for f in frames:
        writer.send(np.ascontiguousarray(f))
    writer.close()
