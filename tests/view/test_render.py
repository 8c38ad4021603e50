"""Offscreen rendering of the infant, `protamer render` and body maps."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONUNBUFFERED": "1"}


def protamer(*argv) -> list[str]:
    return [sys.executable, "-m", "mjx_protamer.cli", *map(str, argv)]


def _red(frame: np.ndarray) -> np.ndarray:
    f = frame.astype(int)
    return (f[..., 0] > 120) & (f[..., 0] > f[..., 1] + 60) & (f[..., 0] > f[..., 2] + 60)


def test_backend_is_egl_or_osmesa_and_a_bad_choice_is_a_clear_error(gl_backend):
    assert gl_backend in ("egl", "osmesa")
    if os.environ.get("DISPLAY"):
        pytest.skip("GLX works where there is a display")
    code = ("import sys; from mjx_protamer.view.gl import choose_backend, GLUnavailable\n"
            "try:\n    choose_backend()\nexcept GLUnavailable as e:\n    print(e); sys.exit(7)")
    # a user's MUJOCO_GL wins; GLX cannot work without a display
    p = subprocess.run([sys.executable, "-c", code], env={**ENV, "MUJOCO_GL": "glx"},
                       capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert p.returncode == 7 and "apt-get install" in p.stdout and "MUJOCO_GL=glx" in p.stdout


def test_infant_frame_is_480_square_and_lights_up_the_touched_regions(infant):
    from mjx_protamer.envs import body

    pose = infant.start_pose()
    plain = infant.frame(pose)
    assert plain.shape == (480, 480, 3) and plain.dtype == np.uint8 and plain.std() > 10
    now = np.zeros(8, bool)
    now[body.REGIONS.index("upper_body")] = True
    lit = infant.frame(pose, now)
    assert _red(lit).sum() > _red(plain).sum() + 2000  # the trunk turns red
    head = np.zeros(8, bool)
    head[body.REGIONS.index("head")] = True
    # a different region lights a different place
    assert (_red(infant.frame(pose, head)) & ~_red(lit)).sum() > 1000


def test_poses_from_a_chunk_put_the_arms_where_the_env_had_them(infant):
    """The live view rebuilds poses from (obs, action): the joints in the observation exactly, the other
    wrist joints from the servo targets (the actions through the env's low-pass, carried across chunks)."""
    twin = infant.twin
    twin.reset(seed=3)
    rng = np.random.default_rng(0)
    chunks = []
    for c in range(4):  # 4 chunks of 50 steps, the action held within a chunk
        action = rng.uniform(-1, 1, twin.action_size)
        obs, qpos = [], []
        for _ in range(50):
            o, *_ = twin.step(action)
            obs.append(o)
            qpos.append(twin.data.qpos.copy())
        chunks.append((np.array(obs), np.tile(action, (50, 1)), np.array(qpos)))
    errors = []
    for i, (obs, actions, qpos) in enumerate(chunks):
        poses = infant.chunk_poses(obs, actions, continues=i > 0)
        idx = infant.model.qpos_idx
        np.testing.assert_allclose(poses[:, idx], qpos[:, idx], atol=1e-5)  # obs is float32
        errors.append(np.abs(poses[-1] - qpos[-1]).max())
    # the wrists lag their targets while moving (up to ~0.5 rad after a full-range jump of the action) and
    # have caught up at the end of each chunk of a held action; the first chunk's low-pass starts from
    # rest, not from the episode's start
    assert max(errors[1:]) < 0.1, errors
    pose = chunks[-1][2][-1]
    np.testing.assert_array_equal(infant.touched(pose), twin.sense()[1])


def test_body_map_colours_regions_by_frequency_and_writes_a_png(gl_backend, tmp_path):
    import imageio.v3 as iio

    from mjx_protamer.view.bodymap import region_colors, write_body_map

    freq = [0.0, 0.05, 0.6, 0.0, 0.1, 0.0, 0.3, 0.0]
    colors, top = region_colors(freq)
    assert top == 0.6
    untouched = colors[0]
    assert all(np.allclose(colors[i], untouched) for i in (0, 3, 5, 7))
    # more touches, darker (YlOrRd): the luminance falls with the frequency
    lum = colors[:, :3] @ [0.3, 0.6, 0.1]
    assert lum[2] < lum[6] < lum[4] < lum[1]
    path = write_body_map(freq, tmp_path / "map.png", "test")
    img = iio.imread(path)
    assert img.shape[0] >= 400 and img.shape[1] >= 900
    assert not list(tmp_path.glob(".*tmp*"))  # written atomically: no temporary left
    with pytest.raises(ValueError, match="8 region frequencies"):
        write_body_map([0.1, 0.2], tmp_path / "bad.png")


def render_main(*argv) -> int:
    from mjx_protamer.cli import main
    return main(["render", *map(str, argv)])


@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")  # imageio-ffmpeg execs ffmpeg at once
def test_render_command_writes_a_video_a_gif_and_a_png_of_the_toy_run(toy_run, tmp_path, capsys):
    import imageio.v3 as iio

    mp4, gif, png = tmp_path / "ep.mp4", tmp_path / "ep.gif", tmp_path / "ep.png"
    for out in (mp4, gif, png):
        assert render_main("--checkpoint", toy_run, "--out", out, "--episodes", "2") == 0
        assert f"[render] wrote {out}" in capsys.readouterr().out
    frames = iio.imread(mp4)
    # 2 episodes of 50 steps at 20 steps/s, shown at 20 fps: 51 frames each
    assert frames.shape == (102, 480, 480, 3)
    assert np.abs(frames[0].astype(int) - frames[40].astype(int)).mean() > 0.5  # it moves
    assert iio.imread(gif).shape[0] == 102
    assert iio.imread(png).shape == (480, 480, 3)


def test_render_command_errors_are_one_clear_line(toy_run, tmp_path, capsys):
    cases = [(["--checkpoint", toy_run, "--out", tmp_path / "x.avi"], "must end in .mp4, .gif, .png"),
             (["--checkpoint", toy_run, "--out", tmp_path / "no" / "x.mp4"], "does not exist"),
             (["--checkpoint", toy_run, "--out", tmp_path / "x.mp4", "--episodes", "0"],
              "--episodes must be a whole number within 1.."),
             (["--checkpoint", tmp_path, "--out", tmp_path / "x.mp4"], "is not a pretrain run directory")]
    for argv, said in cases:
        assert render_main(*argv) == 2
        err = capsys.readouterr().err
        assert said in err and err.count("\n") == 1, err
    assert not list(tmp_path.glob("*.mp4"))


@pytest.mark.slow
def test_render_and_eval_body_map_of_a_self_touch_run(gl_backend, tmp_path):
    """The real infant end to end: a tiny self-touch pretrain (minutes to compile on 2 cores), then
    `protamer render` (MuJoCo offscreen) and `protamer eval` (writes the body map)."""
    import imageio.v3 as iio

    run = tmp_path / "st"
    subprocess.run(protamer("pretrain", "--out", run, "--no-progress", "--set", "train.num_envs=2",
                            "--set", "env.episode_length=200", "--set", "train.episode_length=200",
                            "--set", "train.total_env_steps=800", "--set", "train.warmup_env_steps=400",
                            "--set", "train.chunk_steps=200", "--set", "ddpg.actor_hidden=[32]",
                            "--set", "ddpg.critic_hidden=[32,32]"),
                   check=True, capture_output=True, env=ENV, cwd=ROOT, timeout=1800)
    p = subprocess.run(protamer("render", "--checkpoint", run, "--out", tmp_path / "ep.mp4"),
                       capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=900)
    assert p.returncode == 0 and f"renderer {gl_backend}" in p.stdout, p.stdout + p.stderr
    assert iio.imread(tmp_path / "ep.mp4").shape == (26, 480, 480, 3)  # 200 steps at 200 Hz, 25 fps
    p = subprocess.run(protamer("eval", "--checkpoint", run, "--episodes", "2", "--json"),
                       capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=900)
    assert p.returncode == 0, p.stderr
    import json
    summary = json.loads(p.stdout)
    assert len(summary["region_touch_frequency"]) == 8 and Path(summary["body_map"]).is_file()


def test_table2_body_maps_one_per_condition_averaged_over_seeds(gl_backend, tmp_path):
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.experiments.table2.artifacts import region_frequencies
    from mjx_protamer.view.bodymap import write_condition_body_maps

    f = np.eye(8)
    evals = {"DDPG": {0: {"region_touch_frequency": f[0] * 0.2}, 1: {"region_touch_frequency": f[0] * 0.4}},
             "DTK": {0: {"region_touch_frequency": f[3] * 0.5}, 1: {"region_touch_frequency": f[2] * 0.5}}}
    freq = region_frequencies(evals)
    np.testing.assert_allclose(freq["DDPG"]["frequency"], f[0] * 0.3)
    np.testing.assert_allclose(freq["DTK"]["frequency"], (f[3] + f[2]) * 0.25)
    assert freq["DTK"]["seeds"] == 2
    paths = write_condition_body_maps(PretrainConfig(), freq, tmp_path)
    assert [p.name for p in paths] == ["body_map_DDPG.png", "body_map_DTK.png"] and all(p.is_file() for p in paths)
    import dataclasses
    assert write_condition_body_maps(dataclasses.replace(PretrainConfig(), env_name="toy"), freq, tmp_path) == []
