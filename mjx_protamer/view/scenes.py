"""The scene that draws a run's env: the infant (MuJoCo renderer) or the toy point (2-D drawing).

Every scene has `region_names`, `start_pose()`, `chunk_poses(obs, actions, continues)` (the poses of a
chunk's steps), `touched(pose)`, `frame(pose, now, before)` and `close()`. The infant needs offscreen OpenGL: `gl.choose_backend()` first.
"""

from __future__ import annotations


def make_scene(run_config, width: int = 480, height: int = 480):
    """The scene for a PretrainConfig (its `env_name` and env section)."""
    if run_config.env_name == "toy":
        from mjx_protamer.view.point_scene import PointScene

        return PointScene(run_config.toy, width, height)
    from mjx_protamer.view.gl import choose_backend

    choose_backend()
    from mjx_protamer.view.infant_scene import InfantScene

    return InfantScene(run_config.env, width, height)


def step_seconds(run_config) -> float:
    """Real time of one env step: the self-touch env's physics timestep (200 Hz); the toy env has no
    physical time and is shown at 20 steps a second."""
    if run_config.env_name == "toy":
        return 0.05
    from mjx_protamer.envs.model import build_model

    return float(build_model(run_config.env).mj_model.opt.timestep)


def prepare_gl_for(checkpoint) -> str | None:
    """Before JAX starts its threads (the probe runs child processes): choose the OpenGL backend when the
    run at `checkpoint` is a self-touch run. Returns the backend, or None for a toy run."""
    from mjx_protamer.experiments.run_loader import read_run_config, resolve_checkpoint
    from mjx_protamer.view.gl import choose_backend

    # the run's config as `load_run` reads it (validated, no JAX work, no mujoco import before the choice)
    if read_run_config(resolve_checkpoint(checkpoint)[0]).env_name == "toy":
        return None
    return choose_backend()
