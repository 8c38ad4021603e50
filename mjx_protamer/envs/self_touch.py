"""The self-touch environment on MuJoCo-MJX: pure `reset(rng) -> State`, `step(state, action) -> State`.

Written for one world; `wrappers.wrap_for_training` batches it. One control step is one physics step
(5 ms); the touch observation, regions and reward are computed from the step's MJX contacts with the
shared NumPy/JAX code in `sensing.py` and `reward.py`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from mjx_protamer.quiet_mjx import mjx  # mujoco.mjx, without its "Failed to import warp" notice

from mjx_protamer.envs import body, sensing
from mjx_protamer.envs.base import State
from mjx_protamer.envs.config import REWARD_TERMS, EnvConfig
from mjx_protamer.envs.model import arm_speed, build_model, observe
from mjx_protamer.envs.reward import familiarity_signals, reward_terms


class SelfTouchEnv:
    backend = "mjx"

    def __init__(self, config: EnvConfig | None = None):
        self.config = config or EnvConfig()
        self.model = build_model(self.config)
        m = self.model.mj_model
        self.observation_size = self.config.observation_size
        self.action_size = m.nu
        self.reward_term_names = REWARD_TERMS
        self.region_names = body.REGIONS  # the order of metrics["region_mask"]
        self.reward_weights = self.config.reward.weights()
        self._tables = self.model.sensing.as_xp(jnp)
        self._weights = jnp.asarray(self.reward_weights, jnp.float32)
        # The settled state (`init_data`, where a diverged world is restored) and the pool of episode
        # starts (model.py), both forwarded by the physics backend; the starts are sensed once here, so
        # a reset is a gather.
        self.init_data, pool = self._setup_physics()
        self._start_states = jax.jit(jax.vmap(self._start_state))(pool)

    # --- the physics backend (MJX here; native_env.py overrides these four and `sense`) --------
    def _setup_physics(self):
        """The device model; returns the forwarded settled state and the forwarded pool of starts."""
        m = self.model.mj_model
        self.mjx_model = mjx.put_model(m)
        d = mjx.make_data(self.mjx_model)
        d = d.replace(qpos=jnp.asarray(self.model.init_qpos, jnp.float32),
                      qvel=jnp.asarray(self.model.init_qvel, jnp.float32),
                      ctrl=jnp.asarray(self.model.rest_ctrl, jnp.float32),
                      qacc_warmstart=jnp.asarray(self.model.init_warmstart, jnp.float32))
        init_data = jax.jit(mjx.forward)(self.mjx_model, d)
        # Contact slots are grouped by condim in MJX; each slot's dimension is fixed by the model.
        # Only the self-contact group's slots can touch a hand (when the floor has its own condim).
        dim = np.asarray(init_data._impl.contact.dim)
        phys = self.config.physics
        self._self_slots = (np.arange(len(dim)) if phys.self_condim == phys.floor_condim
                            else np.where(dim == phys.self_condim)[0])
        self._n_pyramid = np.where(dim == 1, 1, 2 * (dim - 1))[self._self_slots]
        pool = jax.tree.map(lambda x: jnp.broadcast_to(x, (self.config.reset_pool_size,) + x.shape), d)
        pool = pool.replace(qpos=jnp.asarray(self.model.start_qpos, jnp.float32),
                            qvel=jnp.asarray(self.model.start_qvel, jnp.float32),
                            ctrl=jnp.asarray(self.model.start_ctrl, jnp.float32),
                            qacc_warmstart=jnp.asarray(self.model.start_warmstart, jnp.float32))
        return init_data, jax.jit(jax.vmap(lambda d: mjx.forward(self.mjx_model, d)))(pool)

    def _physics_step(self, d, action):
        """One physics step from `d` under `action`: the new data and whether the world diverged."""
        ctrl = self.model.next_ctrl(jnp, d.ctrl, action, self.config.action_smoothing).astype(jnp.float32)
        d = mjx.step(self.mjx_model, d.replace(ctrl=ctrl))
        bad = ~(jnp.all(jnp.isfinite(d.qpos)) & jnp.all(jnp.isfinite(d.qvel)))
        return d, bad

    def _restore_start(self, d, bad):
        """A diverged world's integrated state back to the settled start (the rest of mjx.Data is
        recomputed from it by the next step)."""
        init = self.init_data
        return d.replace(**{f: jnp.where(bad, getattr(init, f), getattr(d, f))
                            for f in ("qpos", "qvel", "act", "qacc_warmstart")})

    # --- contacts and sensing -------------------------------------------------------------------
    def contacts(self, d: mjx.Data):
        """MJX contact slots that can be self-contacts, as (geom pairs, positions, depth, normal force)."""
        c, slots = d._impl.contact, self._self_slots
        efc_address = jnp.asarray(c.efc_address)[slots]
        efc_force = d._impl.efc_force
        offsets = jnp.arange(4)
        rows = jnp.clip(efc_address[:, None] + offsets[None, :], 0, efc_force.shape[0] - 1)
        used = offsets[None, :] < jnp.asarray(self._n_pyramid)[:, None]
        normal = jnp.sum(efc_force[rows] * used, axis=1) * (efc_address >= 0)
        return c.geom[slots], c.pos[slots], c.dist[slots], normal

    def sense(self, d: mjx.Data):
        """Touch features, main region mask (8,) and extended region mask (4,) of a forwarded state."""
        geom, pos, dist, normal = self.contacts(d)
        return sensing.sense(jnp, self._tables, self.config.k, geom, pos, dist, normal,
                             d.geom_xpos, d.geom_xmat)

    def _transition(self, d, touch, regions, extended, prev_touch, prev_regions, action, familiarity):
        """Observation, reward, metrics and the familiarity trace after this step (zeros without habituation)."""
        speed = arm_speed(jnp, self.model, d.qvel)
        read, after = familiarity_signals(jnp, self.config, familiarity, regions)
        terms = reward_terms(jnp, self.config.reward, touch, prev_touch, regions, prev_regions, speed,
                             d.actuator_force, action, read)
        obs = observe(jnp, self.model, touch, d.qpos, d.qvel, d.actuator_force, d.time, self.config.oscillator_hz,
                      after)
        metrics = {
            "reward_terms": terms,
            "self_contact": jnp.any(regions).astype(jnp.float32),
            "region_mask": regions.astype(jnp.float32),
            "extended_region_mask": extended.astype(jnp.float32),
            "arm_speed": speed,
        }
        return obs, terms @ self._weights, metrics, familiarity if after is None else after

    # --- the env API ----------------------------------------------------------------------------
    def _start_state(self, d: mjx.Data) -> State:
        touch, regions, extended = self.sense(d)
        zero_action = jnp.zeros(self.action_size)
        obs, _, metrics, familiarity = self._transition(d, touch, regions, extended, touch, regions, zero_action,
                                                        jnp.zeros(regions.shape, jnp.float32))
        metrics = dict(metrics, reward_terms=jnp.zeros_like(metrics["reward_terms"]), nan_reset=jnp.zeros(()))
        info = {"prev_touch": touch, "prev_regions": regions, "familiarity": familiarity,
                "rng": jnp.zeros((2,), jnp.uint32)}
        return State(data=d, obs=obs, reward=jnp.zeros(()), done=jnp.zeros(()), metrics=metrics, info=info)

    def reset(self, rng: jax.Array) -> State:
        # The start states (physics, observation, signals) are precomputed: a reset is a gather, so
        # frequent resets of staggered batched episodes cost next to nothing.
        rng, pick = jax.random.split(rng)
        index = jax.random.randint(pick, (), 0, self.config.reset_pool_size)
        state = jax.tree.map(lambda x: x[index], self._start_states)
        return state.replace(info=dict(state.info, rng=rng))

    def step(self, state: State, action: jax.Array) -> State:
        if action.shape != (self.action_size,):
            raise ValueError(f"action must have shape ({self.action_size},) per env, got {action.shape}")
        d, bad = self._physics_step(state.data, action)
        # A diverged env must not poison the batch: its outputs are zeroed, its state is restored to
        # the settled start and the episode ends, so an auto-reset wrapper starts it afresh.
        touch, regions, extended = self.sense(d)
        obs, reward, metrics, familiarity = self._transition(d, touch, regions, extended, state.info["prev_touch"],
                                                             state.info["prev_regions"], action,
                                                             state.info["familiarity"])
        d = self._restore_start(d, bad)
        obs, reward, touch, familiarity = (jnp.where(bad, 0.0, x) for x in (obs, reward, touch, familiarity))
        metrics = {k: jnp.where(bad, 0.0, v) for k, v in metrics.items()}
        regions = regions & ~bad
        metrics["nan_reset"] = bad.astype(jnp.float32)
        info = dict(state.info, prev_touch=touch, prev_regions=regions, familiarity=familiarity)
        return state.replace(data=d, obs=obs, reward=reward, done=bad.astype(jnp.float32), metrics=metrics,
                             info=info)


def region_names() -> tuple[str, ...]:
    return body.REGIONS
