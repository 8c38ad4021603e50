"""Native MuJoCo physics for a batch of self-touch worlds: `mujoco.batch.Batch`, host side (NumPy only).

The native env (`native_env.py`) calls `NativePhysics.step` from inside its jitted step through
`jax.pure_callback`; everything here is plain NumPy so that the JAX module stays free of host code.

Stateless by design: a world's whole physics state is its float64 `mjSTATE_INTEGRATION` row
(qpos, qvel, act, warm start, ctrl, time, ...), which the JAX side carries bit for bit as uint32 pairs
(JAX on CPU runs float32). A call loads the rows into the batch, steps, and returns the new rows and the
derived fields sensing reads. Because the callback keeps no state, JAX may replay or drop it freely
(`pure_callback`), and the reset pool, auto-reset and NaN isolation stay ordinary array selects in JAX.
Results are bit-identical to `mujoco.mj_step` on one `MjData` (the batch's promise), hence to the twin.

Contacts come from MuJoCo contact sensors, one per self-contact pair of the model (a hand geom against
a geom with a region), `num` slots each, sorted by penetration (`reduce="mindist"`): the batch cannot
bind `d.contact` or `efc_force` (arena arrays), but it binds `sensordata`. Each slot gives found, the
contact-frame force (its first component is the normal force, as `mj_contactForce` gives it), the
penetration and the world position. The deepest `n_contacts` active slots of a world are its contacts,
the MJX env's selection (`max_contact_points` deepest per condim group). The sensors are added to a
copy of the model; they read the physics and never change it.

Sensing runs here too, on the host, in float64: `slot_sensing.SlotSensing` gives each world, straight
from its sensor slots, bit for bit what `sensing.sense` (the code the MJX env runs in JAX and the twin in
NumPy) gives it, computing only the contact entries that count, for all worlds in one pass (the MJX env's
fixed-shape JAX sensing runs every entry of every world). A world without contact gets zero touch
features and no regions, as `sense` gives it. What returns to JAX is only what the env's
step reads, packed in one float32 row per world (`fields()`).
"""

from __future__ import annotations

import os
import threading

import mujoco
import mujoco.batch
import numpy as np

from mjx_protamer.envs import body, sensing
from mjx_protamer.envs.model import SelfTouchModel
from mjx_protamer.envs.slot_sensing import SlotSensing

WORLDS_PER_THREAD = 32
FEW_CONTACTS = 2  # worlds sensed together with a width of at most this many contacts (see _sense)
SLOTS_PER_PAIR = 2  # capsule-capsule pairs can touch at two points
# Per slot: found (1), force in the contact frame (3), dist (1), pos (3).
_SLOT_WIDTH = 8
_BAD_STATE_WARNINGS = np.array([int(mujoco.mjtWarning.mjWARN_BADQPOS), int(mujoco.mjtWarning.mjWARN_BADQVEL),
                                int(mujoco.mjtWarning.mjWARN_BADQACC)])
STATE_SPEC = mujoco.mjtState.mjSTATE_INTEGRATION


def self_contact_pairs(m: mujoco.MjModel, model: SelfTouchModel) -> np.ndarray:
    """(P, 2) geom ids of the model's explicit contact pairs that sensing can count (hand vs region)."""
    hand = model.sensing.geom_hand
    region = model.sensing.geom_region
    pairs = []
    for p in range(m.npair):
        g1, g2 = int(m.pair_geom1[p]), int(m.pair_geom2[p])
        if (hand[g1] >= 0 and region[g2] >= 0) or (hand[g2] >= 0 and region[g1] >= 0):
            pairs.append((g1, g2))
    return np.array(pairs, np.int32).reshape(-1, 2)


def sensor_model(xml: str, geom_names: list[str], pairs: np.ndarray) -> mujoco.MjModel:
    """The model with one contact sensor per self-contact pair appended (physics unchanged)."""
    sensors = "".join(
        f'<contact geom1="{geom_names[a]}" geom2="{geom_names[b]}" num="{SLOTS_PER_PAIR}" '
        f'data="found force dist pos" reduce="mindist"/>' for a, b in pairs)
    if "</mujoco>" not in xml:
        raise ValueError("the model XML has no closing </mujoco> tag")
    return mujoco.MjModel.from_xml_string(xml.replace("</mujoco>", f"<sensor>{sensors}</sensor>\n</mujoco>"))


class NativePhysics:
    """Steps batches of worlds given as state rows; one `mujoco.batch.Batch` per batch size, reused."""

    def __init__(self, model: SelfTouchModel, physics_config, n_contacts: int, touch_k: int, nthread: int = 0,
                 action_smoothing: float = 0.0):
        m0 = model.mj_model
        names = [mujoco.mj_id2name(m0, mujoco.mjtObj.mjOBJ_GEOM, i) for i in range(m0.ngeom)]
        self.pairs = self_contact_pairs(m0, model)
        self.mj_model = sensor_model(body.infant_xml(physics_config), names, self.pairs)
        m = self.mj_model
        self.nstate = mujoco.mj_stateSize(m, STATE_SPEC)
        self.n_slots = len(self.pairs) * SLOTS_PER_PAIR
        self.n_contacts = min(n_contacts, self.n_slots) if n_contacts > 0 else self.n_slots
        self.slot_geom = np.repeat(self.pairs, SLOTS_PER_PAIR, axis=0).astype(np.int32)  # (S, 2)
        self._tables = model.sensing.as_xp(np)
        self.touch_k = touch_k
        self._slot_sensing = SlotSensing(self._tables, self.slot_geom, self.n_contacts, touch_k)
        self.touch_size = 4 * (touch_k + 3)
        self.nthread = nthread or (os.cpu_count() or 1)
        self._action_lo = model.ctrl_lo
        self._action_hi = model.ctrl_hi
        self._smoothing = action_smoothing  # model.next_ctrl's low-pass from action to servo target
        self._batches: dict[int, mujoco.batch.Batch] = {}
        self._lock = threading.Lock()
        self._ctrl_slice = self._component(mujoco.mjtState.mjSTATE_CTRL)
        self._qpos_slice = self._component(mujoco.mjtState.mjSTATE_QPOS)
        self._qvel_slice = self._component(mujoco.mjtState.mjSTATE_QVEL)
        self._warmstart_slice = self._component(mujoco.mjtState.mjSTATE_WARMSTART)
        self._time_slice = self._component(mujoco.mjtState.mjSTATE_TIME)

    def _component(self, spec) -> slice:
        """Where one state component sits inside an mjSTATE_INTEGRATION row."""
        m, offset, part = self.mj_model, 0, 1
        while part <= int(STATE_SPEC):
            if int(STATE_SPEC) & part:
                size = mujoco.mj_stateSize(m, part)
                if part == int(spec):
                    return slice(offset, offset + size)
                offset += size
            part <<= 1
        raise ValueError(f"state component {spec} is not part of the integration state")

    # --- state rows --------------------------------------------------------------------------------
    def state_rows(self, qpos, qvel, ctrl, warmstart) -> np.ndarray:
        """(n, nstate) float64 rows from per-world arrays (time and act zero, as after mj_resetData)."""
        qpos, qvel, ctrl, warmstart = (np.atleast_2d(np.asarray(x, np.float64)) for x in (qpos, qvel, ctrl, warmstart))
        rows = np.zeros((qpos.shape[0], self.nstate))
        d = mujoco.MjData(self.mj_model)
        for i in range(qpos.shape[0]):
            mujoco.mj_resetData(self.mj_model, d)
            d.qpos[:], d.qvel[:], d.ctrl[:], d.qacc_warmstart[:] = qpos[i], qvel[i], ctrl[i], warmstart[i]
            mujoco.mj_getState(self.mj_model, d, rows[i], STATE_SPEC)
        return rows

    def rows_to_bits(self, rows: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(rows, np.float64).view(np.uint32)

    def bits_to_rows(self, bits: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(bits, np.uint32).view(np.float64)

    # --- the calls -----------------------------------------------------------------------------------
    def _batch(self, n: int) -> mujoco.batch.Batch:
        b = self._batches.get(n)
        if b is None:
            # A thread pays off from about 32 worlds: below that, waking it costs more than it saves
            # (measured: 16 worlds step faster on one thread than on two).
            b = mujoco.batch.Batch(self.mj_model, n, max(1, min(self.nthread, n // WORLDS_PER_THREAD)))
            for name in ("geom_xpos", "geom_xmat", "actuator_force", "sensordata"):
                b.bind(name)
            self._batches[n] = b
        return b

    def step(self, bits: np.ndarray, action: np.ndarray):
        """One physics step of each world: `bits` (..., 2 nstate) uint32 rows, `action` (..., nu) in [-1, 1].

        The action becomes position targets here, in float64, exactly as the twin computes them.
        Returns (state bits, packed float32 fields (see `fields`), bad) for the stepped worlds; `bad`
        marks worlds whose state diverged (MuJoCo's bad-state warnings rose, non-finite state, or a
        simulation error).
        """
        lead = bits.shape[:-1]
        rows = self.bits_to_rows(bits.reshape(-1, bits.shape[-1]))
        a = np.clip(np.asarray(action, np.float64).reshape(rows.shape[0], -1), -1.0, 1.0)
        with self._lock:
            b = self._batch(rows.shape[0])
            b.state[:] = rows
            target = self._action_lo + 0.5 * (a + 1.0) * (self._action_hi - self._action_lo)
            b.state[:, self._ctrl_slice] = self._smoothing * rows[:, self._ctrl_slice] + (1.0 - self._smoothing) * target
            before = b.warning[:, _BAD_STATE_WARNINGS, 1].sum(axis=1)
            failed = np.zeros(rows.shape[0], bool)
            try:
                b.step()
            except mujoco.batch.SimulationError as e:
                failed[np.asarray(e.ids)] = True
            bad = failed | (b.warning[:, _BAD_STATE_WARNINGS, 1].sum(axis=1) != before)
            out = self._outputs(b)
        bad |= ~np.isfinite(out[1]).all(axis=1)
        return tuple(x.reshape(lead + x.shape[1:]) for x in out + (bad,))

    def forward(self, rows: np.ndarray):
        """`mj_forward` of each row (positions, contacts, forces at that state); outputs as `step`'s."""
        rows = np.atleast_2d(rows)
        with self._lock:
            b = self._batch(rows.shape[0])
            b.state[:] = rows
            b.forward()
            return self._outputs(b)

    def forward_contacts(self, rows: np.ndarray):
        """`mj_forward` of each row; its self-contacts as sensing reads them (see `_contacts`)."""
        rows = np.atleast_2d(rows)
        with self._lock:
            b = self._batch(rows.shape[0])
            b.state[:] = rows
            b.forward()
            return self._contacts(b, np.arange(rows.shape[0]), self.n_contacts)

    def fields(self) -> tuple[tuple[str, tuple[int, ...]], ...]:
        """Name and per-world shape of each float32 field packed by `step`, in order (masks as 0/1)."""
        m = self.mj_model
        return (("time", ()), ("qpos", (m.nq,)), ("qvel", (m.nv,)), ("actuator_force", (m.nu,)),
                ("touch", (self.touch_size,)), ("region_mask", (sensing.N_REGIONS,)),
                ("extended_region_mask", (sensing.N_EXTENDED,)))

    def _contacts(self, b: mujoco.batch.Batch, worlds: np.ndarray, width: int):
        """Geom pairs (W, width, 2), positions (W, width, 3), penetrations and normal forces (W, width) of
        the `width` deepest sensor slots of each of `worlds`, deepest first.

        An empty slot is all zeros: penetration 0, which sensing counts as no contact (dist < 0 is a
        contact), and which sorts after every real contact.
        """
        slots = b.sensordata.reshape(b.nsim, self.n_slots, _SLOT_WIDTH)[worlds]
        order = np.argsort(slots[:, :, 4], axis=1, kind="stable")[:, :width]
        pick = np.take_along_axis(slots, order[:, :, None], axis=1)
        return self.slot_geom[order], pick[:, :, 5:8], pick[:, :, 4], pick[:, :, 1]

    def _sense(self, b: mujoco.batch.Batch):
        """Touch features (n, touch_size) and region masks (n, 8 + 4) of every world: `SlotSensing` from the
        sensor slots, bit for bit `_sense_reference` at a fraction of its cost (`sensing.sense`'s per-call
        overhead dominated the env's step once a trained policy touches itself); the reference itself
        where that cannot promise the same floats (non-finite values)."""
        n, ng = b.nsim, self.mj_model.ngeom
        fast = self._slot_sensing(b.sensordata.reshape(n, self.n_slots, _SLOT_WIDTH), b.geom_xpos.reshape(n, ng, 3),
                                  b.geom_xmat.reshape(n, ng, 3, 3))
        return self._sense_reference(b) if fast is None else fast

    def _sense_reference(self, b: mujoco.batch.Batch):
        """`_sense` through `sensing.sense` itself, sensing only the worlds in contact, each group cut to the
        largest number of active contacts in it (entries past a world's active ones are inactive and change
        nothing in `sense`): worlds with at most `FEW_CONTACTS`, then the rest, since `sense`'s pairwise step
        grows with the square of the width."""
        n, ng = b.nsim, self.mj_model.ngeom
        touch = np.zeros((n, self.touch_size))
        regions = np.zeros((n, sensing.N_REGIONS + sensing.N_EXTENDED))
        count = np.count_nonzero(b.sensordata.reshape(n, self.n_slots, _SLOT_WIDTH)[:, :, 4] < 0, axis=1)
        for worlds in (np.flatnonzero((count > 0) & (count <= FEW_CONTACTS)), np.flatnonzero(count > FEW_CONTACTS)):
            if worlds.size == 0:
                continue
            geom, pos, depth, force = self._contacts(b, worlds, min(int(count[worlds].max()), self.n_contacts))
            t, main, extended = sensing.sense(np, self._tables, self.touch_k, geom, pos, depth, force,
                                              b.geom_xpos.reshape(n, ng, 3)[worlds],
                                              b.geom_xmat.reshape(n, ng, 3, 3)[worlds])
            touch[worlds] = t
            regions[worlds] = np.concatenate([main, extended], axis=1)
        return touch, regions

    def _outputs(self, b: mujoco.batch.Batch):
        """(state bits, the float fields packed in one float32 row per world).

        Copies: the batch overwrites its outputs on the next call. One packed array instead of seven
        keeps the per-call overhead of the callback small (it matters for a single env).
        """
        state = b.state.copy()
        touch, regions = self._sense(b)
        packed = np.concatenate([
            state[:, self._time_slice], state[:, self._qpos_slice], state[:, self._qvel_slice], b.actuator_force,
            touch, regions], axis=1).astype(np.float32)
        return state.view(np.uint32), packed
