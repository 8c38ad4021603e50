"""Session-scoped fixtures for the env tests: the twin and MJX envs, and the jitted MJX functions.

Each jitted function here is one compiled shape (30-60 s on this machine, cached on disk afterwards);
tests reuse them instead of compiling their own.
"""

from __future__ import annotations

import numpy as np
import pytest

# The equivalence config: the shipping model with the constraint solver run to convergence, so native C
# (float64) and MJX (float32) solve the same problem to the same answer and the comparison isolates
# collision, sensing and float precision. At the shipping 2 Newton iterations the two solvers' forces
# differ (see test_equivalence.py).
CONVERGED_ITERATIONS = 50
CONVERGED_LS_ITERATIONS = 25


def _converged_config(**kw):
    from mjx_protamer.envs.config import EnvConfig, PhysicsConfig

    return EnvConfig(physics=PhysicsConfig(iterations=CONVERGED_ITERATIONS, ls_iterations=CONVERGED_LS_ITERATIONS),
                     **kw)


@pytest.fixture(scope="session")
def eq_twin():
    from mjx_protamer.envs.twin import SelfTouchTwinEnv

    # No action filter: the held-target sweep jumps straight to each target, reaching the poses it was
    # seeded to find (states are compared one by one; the trajectory fixtures below keep the filter).
    return SelfTouchTwinEnv(_converged_config(action_filter_s=0.0))


@pytest.fixture(scope="session")
def eq_mjx_env():
    from mjx_protamer.envs.self_touch import SelfTouchEnv

    return SelfTouchEnv(_converged_config(action_filter_s=0.0))


@pytest.fixture(scope="session")
def eq_mjx_evaluate(eq_mjx_env):
    """Jitted: physics state -> mjx.forward -> the env's obs, reward, metrics and raw contacts."""
    import jax
    import jax.numpy as jnp
    from mujoco import mjx

    env = eq_mjx_env

    @jax.jit
    def evaluate(qpos, qvel, ctrl, warmstart, prev_touch, prev_regions, action, familiarity):
        d = env.init_data.replace(qpos=qpos, qvel=qvel, ctrl=ctrl, qacc_warmstart=warmstart)
        d = mjx.forward(env.mjx_model, d)
        touch, regions, extended = env.sense(d)
        obs, reward, metrics, _ = env._transition(d, touch, regions, extended, prev_touch, prev_regions, action,
                                                  familiarity)
        geom, _, dist, normal = env.contacts(d)
        return dict(obs=obs, reward=reward, touch=touch, region_mask=regions, extended_region_mask=extended,
                    metrics=metrics, geom=geom, dist=dist, normal=normal)

    def call(qpos, qvel, ctrl, warmstart, prev_touch, prev_regions, action, familiarity=np.zeros(8)):
        f32 = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
        out = evaluate(f32(qpos), f32(qvel), f32(ctrl), f32(warmstart), f32(prev_touch),
                       jnp.asarray(prev_regions, bool), f32(action), f32(familiarity))
        return jax.tree.map(np.asarray, out)

    return call


@pytest.fixture(scope="session")
def trajectory_fn():
    """The jitted trajectory of any env on the env contract (MJX or native), as `_trajectory_fn`."""
    return _trajectory_fn


def _trajectory_fn(env):
    """Jitted: (reset key, actions (T, 14)) -> per-step obs, qpos, reward, region masks, NaN resets."""
    import jax

    @jax.jit
    def roll(rng, actions):
        def body(s, a):
            s = env.step(s, a)
            return s, (s.obs, s.data.qpos, s.reward, s.metrics["region_mask"], s.metrics["nan_reset"])
        state = env.reset(rng)
        return state.obs, jax.lax.scan(body, state, actions)[1]

    return lambda rng, actions: jax.tree.map(np.asarray, roll(rng, actions))


@pytest.fixture(scope="session")
def traj_envs_converged():
    """(twin, MJX trajectory fn) at converged solver settings, no reset noise (same start state)."""
    from mjx_protamer.envs.self_touch import SelfTouchEnv
    from mjx_protamer.envs.twin import SelfTouchTwinEnv

    cfg = _converged_config(reset_noise_steps=0)
    return SelfTouchTwinEnv(cfg), _trajectory_fn(SelfTouchEnv(cfg))


@pytest.fixture(scope="session")
def traj_envs_shipping():
    """(twin, MJX trajectory fn) at the shipping (fast) settings, no reset noise."""
    from mjx_protamer.envs.config import EnvConfig
    from mjx_protamer.envs.self_touch import SelfTouchEnv
    from mjx_protamer.envs.twin import SelfTouchTwinEnv

    cfg = EnvConfig(reset_noise_steps=0)
    return SelfTouchTwinEnv(cfg), _trajectory_fn(SelfTouchEnv(cfg))
