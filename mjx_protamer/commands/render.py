"""`protamer render`: watch a trained policy. Test episodes of the deterministic actor, rendered offscreen.

    protamer render --checkpoint RUN --out episode.mp4 [--episodes 2] [--seed S] [--fps 25] [--size 480]
    protamer render --checkpoint RUN --out frame.png

The episodes run in one jit (as `protamer eval`); their poses are drawn with MuJoCo's renderer on
offscreen OpenGL (EGL through Mesa, OSMesa as the fallback; the one used is printed). Touched regions
light up as they are touched (red now, amber touched earlier in the episode); a caption shows the step,
the contact rate so far and the regions touched so far. The 200 Hz steps are subsampled to --fps so
the video plays in real time. A .png is the last frame of the first episode.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "render",
        help="render test episodes of a trained policy to .mp4, .gif or .png",
        description="Runs test episodes with the deterministic actor of a checkpoint and renders them offscreen "
        "(no display or GPU needed), touched regions highlighted, with a caption.",
    )
    p.add_argument("--checkpoint", type=Path, required=True,
                   help="a pretrain or finetune run directory, its checkpoints/ directory, or one step in it")
    p.add_argument("--out", type=Path, required=True, help="output file: .mp4, .gif or .png")
    p.add_argument("--episodes", default=1, help="test episodes (default 1)")
    p.add_argument("--seed", default=None, help="test-episode seed, 0..2^32-1 (default: the run's eval seed)")
    p.add_argument("--fps", default=25.0, help="frames per second of the video (real-time playback; default 25)")
    p.add_argument("--size", default=480, help="frame width and height in pixels (an even number, 64..4096)")
    p.set_defaults(handler=_render)


def _fail(msg: str) -> int:
    print(f"protamer render: {msg}", file=sys.stderr, flush=True)
    return 2


def _render(args: argparse.Namespace) -> int:
    from mjx_protamer.experiments.run_loader import resolve_checkpoint
    from mjx_protamer.view.video import check_path

    from mjx_protamer.cli_numbers import number, seed
    from mjx_protamer.commands.train import MAX_EPISODES
    from mjx_protamer.config import ConfigError

    try:
        args.episodes = number("--episodes", args.episodes, 1, MAX_EPISODES, integer=True)
        args.seed = seed("--seed", args.seed)
        args.fps = number("--fps", args.fps, 0.01, 1000)
        args.size = number("--size", args.size, 64, 4096, integer=True)
    except ConfigError as e:
        return _fail(str(e))
    if args.size % 2:
        return _fail(f"--size must be an even number (the video's encoder needs one), got {args.size}")
    try:
        check_path(args.out)
        resolve_checkpoint(args.checkpoint)
    except (ValueError, FileNotFoundError) as e:
        return _fail(str(e))
    try:
        import imageio  # noqa: F401
        import imageio_ffmpeg  # noqa: F401
    except ImportError as e:
        return _fail(f"{e.name} is missing: install the view extra (pip install -e '.[view]'; "
                     f"scripts/test.sh does)")

    from mjx_protamer.view.gl import GLUnavailable
    from mjx_protamer.view.scenes import prepare_gl_for

    try:
        prepare_gl_for(args.checkpoint)
    except GLUnavailable as e:
        return _fail(str(e))
    from mjx_protamer.compile_cache import enable as _enable_compile_cache

    _enable_compile_cache()
    try:
        with contextlib.redirect_stdout(sys.stderr):  # library chatter (mjx's "Failed to import warp")
            frames, fps, backend = render_episodes(args.checkpoint, args.episodes, args.seed, args.fps, args.size)
    except GLUnavailable as e:
        return _fail(str(e))
    from mjx_protamer.view.video import write_frames

    if args.out.suffix.lower() == ".png":
        frames = [frames[len(frames) // args.episodes - 1]]
    write_frames(args.out, frames, fps)
    print(f"[render] wrote {args.out}: {len(frames)} frame(s), {args.size}x{args.size}, {fps:.1f} fps "
          f"(real time), renderer {backend}", flush=True)
    return 0


def render_episodes(checkpoint, episodes: int, seed, fps: float, size: int):
    """(frames, exact fps, backend) of `episodes` test episodes of the checkpoint's deterministic actor."""
    import os

    import jax
    import numpy as np

    from mjx_protamer.agents.ddpg.evaluate import make_rollout
    from mjx_protamer.experiments.evaluate import eval_seed, load_run
    from mjx_protamer.view.caption import draw_caption
    from mjx_protamer.view.scenes import make_scene, step_seconds

    config, env, state, step = load_run(checkpoint)
    scene = make_scene(config, size, size)
    backend = os.environ.get("MUJOCO_GL", "none") if config.env_name != "toy" else "2-D drawing (toy env)"
    print(f"[render] checkpoint step {step}; renderer: {backend}", file=sys.__stdout__, flush=True)
    dt = step_seconds(config)
    stride = max(1, round(1.0 / (fps * dt)))
    seed = eval_seed(config) if seed is None else seed
    rollout = make_rollout(env, config.train.episode_length, config.ddpg.actor_hidden,
                           keep=("pose", "region_mask", "self_contact"), start=True)
    out = jax.device_get(rollout(state.actor_params, jax.random.split(jax.random.PRNGKey(seed), episodes)))
    frames = []
    names = scene.region_names
    try:
        for e in range(episodes):
            masks = np.asarray(out["region_mask"][e], bool)
            contact = np.asarray(out["self_contact"][e], np.float64)
            T = masks.shape[0] - 1
            for t in list(range(0, T + 1, stride)) + ([T] if T % stride else []):
                so_far = masks[:t + 1].any(axis=0)
                rate = contact[1:t + 1].mean() if t else 0.0
                touched = ", ".join(n for n, on in zip(names, so_far) if on) or "none"
                frame = scene.frame(np.asarray(out["pose"][e, t]), masks[t], so_far)
                frames.append(draw_caption(frame, [
                    f"episode {e + 1}/{episodes}  step {t}/{T}  t={t * dt:.2f} s  contact so far {rate:.2f}",
                    f"regions touched ({int(so_far.sum())}): {touched}"], size=max(11, size // 32)))
    finally:
        scene.close()
    return frames, 1.0 / (stride * dt), backend
