"""Touch sensing of a batch of native worlds straight from their contact-sensor slots (NumPy only, host side).

`sensing.sense(np, ...)` costs about a hundred small NumPy calls per batch, whatever the batch holds; with
the ~30 worlds and few contacts each of a trained policy, that overhead was most of the native env's step
(issue 40). This computes the same numbers from the valid contact entries of all worlds at once, bit for
bit: every float is made by the same operations on the same values in the same order as in `sense`.

Why the order is the same: `sense` sums the pairwise readings (over the other entries f of the world) and
the touch features (over the entries of a hand) with `np.einsum`, which adds its terms one by one in
ascending entry order from zero (tests/env/test_slot_sensing.py pins this down for the shapes in use).
Terms of another world, another hand geom or an invalid entry are exact zeros there, and adding zero
changes nothing, so the sum over the entries of the same world and hand geom, in the same order, is the
same float. Everything else is elementwise, or per entry row (`sensing._entry_geometry`, reused as is).

The one place the two could differ is a non-finite or huge value: in `sense` a NaN of one entry reaches
the other hand's features through `0 * NaN`. Batches with such values return None and the caller uses
`sense` (a diverging world is rare, and is then flagged bad either way).
"""

from __future__ import annotations

import numpy as np

from mjx_protamer.envs import sensing

# Beyond these, an intermediate of `sense` could overflow; every physical contact is far inside them.
_MAX_LOCAL_POS = 1.0e6
_MAX_FORCE = 1.0e100


class SlotSensing:
    """Touch features and region masks of worlds from their contact-sensor slots, as `sensing.sense(np, ...)`
    gives them for each world's `n_contacts` deepest active slots (`NativePhysics._contacts`)."""

    def __init__(self, tables: dict, slot_geom: np.ndarray, n_contacts: int, k: int):
        self.tables, self.n_contacts, self.k = tables, n_contacts, k
        self.n_slots = len(slot_geom)
        # Each slot's entries are fixed by its geom pair: the entry seen from its hand geom, and, for a
        # hand-to-hand pair, the second hand's view (`sense`'s extra entries). Entry id: slot, or
        # n_slots + slot for the second view.
        geom_hand, geom_region = tables["geom_hand"], tables["geom_region"]
        g1, g2 = slot_geom[:, 0], slot_geom[:, 1]
        first_is_hand = geom_hand[g1] >= 0
        self.both_hands = first_is_hand & (geom_hand[g2] >= 0)
        own = np.concatenate([np.where(first_is_hand, g1, g2), g2])
        other = np.concatenate([np.where(first_is_hand, g2, g1), g1])
        hand = geom_hand[own]
        region = geom_region[other]
        hand_i = np.where(hand >= 0, hand, 0)
        self.entry_own, self.entry_hand, self.entry_region = own, hand_i, region
        # Each candidate's sensor position once, to gather the k nearest in one step.
        candidates, candidate_pos = tables["candidates"], tables["candidate_pos"]
        self.sensor_pos = np.zeros((int(candidates.max()) + 1, 3))
        self.sensor_pos[candidates.ravel()] = np.moveaxis(candidate_pos, 1, -1).reshape(-1, 3)
        self.entry_counts = ((hand >= 0) & (region >= 0) & (region != tables["hand_excluded_region"][hand_i])
                             & np.concatenate([np.ones(self.n_slots, bool), self.both_hands]))

    def __call__(self, slots: np.ndarray, geom_xpos: np.ndarray, geom_xmat: np.ndarray):
        """(touch (n, 4 (k + 3)), regions (n, 8 + 4) as 0/1) from slots (n, n_slots, 8) and the geom frames
        (n, ngeom, 3) and (n, ngeom, 3, 3); None where only `sense` itself gives the exact result."""
        n, k, tables = slots.shape[0], self.k, self.tables
        touch = np.zeros((n, 4 * (k + 3)))
        regions = np.zeros((n, sensing.N_REGIONS + sensing.N_EXTENDED))
        dist = slots[:, :, 4]
        count = np.minimum(np.count_nonzero(dist < 0, axis=1), self.n_contacts)
        if not count.any():
            return touch, regions
        # A world's contacts: its `count` deepest slots, deepest first (ties: lower slot); the second hand's
        # views follow for the (at most) HAND_HAND_ENTRIES deepest hand-to-hand ones among them.
        order = np.argsort(dist, axis=1, kind="stable")
        taken = np.arange(self.n_slots) < count[:, None]
        second = taken & self.both_hands[order]
        second &= np.cumsum(second, axis=1) <= sensing.HAND_HAND_ENTRIES
        entry = np.concatenate([order, order + self.n_slots], axis=1)
        counts = np.concatenate([taken, second], axis=1) & self.entry_counts[entry]
        # Valid entries, world by world, each in `sense`'s order (contacts, then the second views).
        world, at = np.nonzero(counts)
        if world.size == 0:
            return touch, regions
        entry = entry[world, at]
        slot = entry % self.n_slots
        own = self.entry_own[entry]
        hand_i = self.entry_hand[entry]
        p_world = slots[world, slot, 5:8]
        force = slots[world, slot, 1]
        p_local, q, near, w_sum = self._entry_geometry(hand_i, p_world, geom_xpos[world, own], geom_xmat[world, own])
        if not (np.abs(p_local).max() < _MAX_LOCAL_POS and np.abs(force).max() < _MAX_FORCE):
            return None
        scale = np.where(w_sum > 0, force / np.where(w_sum > 0, w_sum, 1.0), 0.0)

        # The entries of one world on one hand geom (a group) in order: members[g, r] is the r-th of group g.
        group = world * 4 + hand_i
        by_group = np.argsort(group, kind="stable")
        in_order = group[by_group]
        rank = np.arange(len(group)) - np.searchsorted(in_order, in_order)
        members = np.full((n * 4, int(rank.max()) + 1), -1)
        members[in_order, rank] = by_group

        # Readings: each contact's force spread over the k sensors near each contact of its group.
        mine = members[group]  # (V, G)
        f = np.maximum(mine, 0)
        squares = (near[:, :, None, :] - q[f][:, None, :, :]) ** 2
        gap = np.sqrt(squares[..., 0] + squares[..., 1] + squares[..., 2])  # (V, k, G)
        radius = tables["spread_radius"][hand_i]
        w_pair = np.maximum(1.0 - gap / radius[:, None, None], 0.0)
        terms = w_pair * np.where(mine >= 0, scale[f], 0.0)[:, None, :]
        readings = 0.0
        for r in range(terms.shape[-1]):
            readings = readings + terms[:, :, r]

        # Features averaged over each group's entries, summed in order from zero as `sense`'s einsum does.
        features = np.concatenate([p_local, readings], axis=-1)
        used = np.flatnonzero(members[:, 0] >= 0)
        summed = 0.0
        for r in range(members.shape[1]):
            m = members[used, r]
            summed = summed + np.where(m[:, None] >= 0, features[np.maximum(m, 0)], 0.0)
        group_size = np.count_nonzero(members[used] >= 0, axis=1)
        touch.reshape(n * 4, k + 3)[used] = summed / group_size[:, None]
        regions[world, self.entry_region[entry]] = 1.0
        return touch, regions

    def _entry_geometry(self, hand_i, p_world, frame_pos, frame_mat):
        """`sensing._entry_geometry` for NumPy with fewer calls, same floats: the sensor positions (V, k, 3)
        come from one gather instead of three `take_along_axis`, and the sums of three squares are written
        out (`sense`'s `sum(...)` starts from the integer 0, and 0 + x is x)."""
        tables, k = self.tables, self.k
        p_local, q, voxel = sensing.entry_voxel(np, tables, hand_i, p_world, frame_pos, frame_mat)
        squares = (tables["candidate_pos"][voxel] - q[:, :, None]) ** 2  # (V, 3, C)
        d = np.sqrt(squares[:, 0] + squares[:, 1] + squares[:, 2])
        nearest = sensing.nearest_k(np, d, k)
        near = self.sensor_pos[tables["candidates"][voxel[:, None], nearest]]
        w_sum = np.sum(np.maximum(1.0 - d / tables["spread_radius"][hand_i][..., None], 0.0), axis=-1)
        return p_local, q, near, w_sum
