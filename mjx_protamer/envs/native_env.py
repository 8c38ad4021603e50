"""The self-touch env on native MuJoCo physics, inside the jitted step: the CPU backend.

Same env as `SelfTouchEnv` (same observation, regions, reward, reset pool, NaN isolation, wrappers,
pure `reset`/`step` on a `State`), but the physics step is native C MuJoCo (`mujoco.batch`, float64,
the engine's own threads) reached through `jax.pure_callback`: under `VmapWrapper` a whole batch of
worlds is one callback per vectorised step (`vmap_method="broadcast_all"`), so the chunk stays one
jitted program and sensing, reward and learning remain JAX. On a CPU this is about ten times faster than
MJX (docs/environment.md); on an accelerator every step would cross to the host, so MJX stays there.

A world's physics state is `NativeData.state`: its float64 integration-state row carried bit for bit
(as uint32 pairs), so a trajectory equals the NumPy twin's (`mj_step` on one MjData) exactly. The other
fields are what the step's forward pass computed, float32, as the MJX env reads them from `mjx.Data`:
qpos and qvel after the step, actuator forces, geom frames and the deepest self-contacts before it.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from mjx_protamer.envs.native_physics import NativePhysics
from mjx_protamer.envs.self_touch import SelfTouchEnv


@struct.dataclass
class NativeData:
    state: jax.Array  # (2 * nstate,) uint32: the float64 mjSTATE_INTEGRATION row
    time: jax.Array  # () the episode time (the oscillator's phase)
    qpos: jax.Array
    qvel: jax.Array
    actuator_force: jax.Array
    geom_xpos: jax.Array  # (ngeom, 3)
    geom_xmat: jax.Array  # (ngeom, 3, 3)
    contact_geom: jax.Array  # (n_contacts, 2) int32, deepest self-contacts first
    contact_pos: jax.Array  # (n_contacts, 3)
    contact_dist: jax.Array  # (n_contacts,) penetration; >= 0 for an empty slot
    contact_force: jax.Array  # (n_contacts,) normal force


def unpack(physics: NativePhysics, bits, packed, geom) -> NativeData:
    """NativeData from `NativePhysics` outputs (NumPy or JAX arrays, any leading batch shape)."""
    lead = packed.shape[:-1]
    fields, offset = {}, 0
    for name, shape in physics.fields():
        size = int(np.prod(shape))
        fields[name] = packed[..., offset:offset + size].reshape(lead + shape)
        offset += size
    return NativeData(state=bits, contact_geom=geom, **fields)


class NativeSelfTouchEnv(SelfTouchEnv):
    backend = "native"

    def _setup_physics(self):
        m = self.model
        self.physics = NativePhysics(m, self.config.physics, n_contacts=self.config.physics.max_contact_points,
                                     action_smoothing=self.config.action_smoothing)
        rows = self.physics.state_rows(m.init_qpos, m.init_qvel, m.rest_ctrl, m.init_warmstart)
        init = [jnp.asarray(x[0]) for x in self.physics.forward(rows)]
        pool_rows = self.physics.state_rows(m.start_qpos, m.start_qvel, m.start_ctrl, m.start_warmstart)
        pool = unpack(self.physics, *(jnp.asarray(x) for x in self.physics.forward(pool_rows)))
        self._result_shapes = tuple(jax.ShapeDtypeStruct(x.shape, x.dtype) for x in init)
        return unpack(self.physics, *init), pool

    def _physics_step(self, d: NativeData, action):
        shapes = self._result_shapes + (jax.ShapeDtypeStruct((), jnp.bool_),)
        # One call per vectorised step: under vmap the callback receives the whole batch.
        *out, bad = jax.pure_callback(self.physics.step, shapes, d.state, action.astype(jnp.float32),
                                      vmap_method="broadcast_all")
        return unpack(self.physics, *out), bad

    def _restore_start(self, d: NativeData, bad):
        # The state row defines the next step completely; the derived fields follow it for consistency.
        return jax.tree.map(lambda i, x: jnp.where(bad, i, x), self.init_data, d)

    def contacts(self, d: NativeData):
        return d.contact_geom, d.contact_pos, d.contact_dist, d.contact_force
