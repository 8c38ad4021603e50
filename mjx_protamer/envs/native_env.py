"""The self-touch env on native MuJoCo physics, inside the jitted step: the CPU backend.

Same env as `SelfTouchEnv` (same observation, regions, reward, reset pool, NaN isolation, wrappers,
pure `reset`/`step` on a `State`), but the physics step is native C MuJoCo (`mujoco.batch`, float64,
the engine's own threads) reached through `jax.pure_callback`: under `VmapWrapper` a whole batch of
worlds is one callback per vectorised step (`vmap_method="broadcast_all"`), so the chunk stays one
jitted program; touch sensing runs on the host in the same call (the shared
`sensing.sense`, on the worlds in contact only), reward, observation and learning remain JAX. On a CPU this is about ten times faster than
MJX (docs/environment.md); on an accelerator every step would cross to the host, so MJX stays there.

A world's physics state is `NativeData.state`: its float64 integration-state row carried bit for bit
(as uint32 pairs), so a trajectory equals the NumPy twin's (`mj_step` on one MjData) exactly. The other
fields are what the env's step reads, float32: qpos and qvel after the step, actuator forces, and the
touch features and region masks that the host sensed (in float64, the shared `sensing.sense`, only on
the worlds in contact) from the deepest self-contacts and geom frames of the step's forward pass.
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
    touch: jax.Array  # (4 * (k + 3),) sensing.sense's touch features
    region_mask: jax.Array  # (8,) 0/1
    extended_region_mask: jax.Array  # (4,) 0/1


def unpack(physics: NativePhysics, bits, packed) -> NativeData:
    """NativeData from `NativePhysics` outputs (NumPy or JAX arrays, any leading batch shape)."""
    lead = packed.shape[:-1]
    fields, offset = {}, 0
    for name, shape in physics.fields():
        size = int(np.prod(shape))
        fields[name] = packed[..., offset:offset + size].reshape(lead + shape)
        offset += size
    return NativeData(state=bits, **fields)


class NativeSelfTouchEnv(SelfTouchEnv):
    backend = "native"

    def _setup_physics(self):
        m = self.model
        self.physics = NativePhysics(m, self.config.physics, n_contacts=self.config.physics.max_contact_points,
                                     touch_k=self.config.k, action_smoothing=self.config.action_smoothing)
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

    def sense(self, d: NativeData):
        # Sensed on the host with the physics step (native_physics.py): one call per vectorised step.
        return d.touch, d.region_mask > 0, d.extended_region_mask > 0
