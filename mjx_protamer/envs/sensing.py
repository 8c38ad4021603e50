"""Touch features and body regions from a list of contacts, written once for NumPy and JAX.

`xp` is `numpy` (the twin and the native backend's host side, float64) or `jax.numpy` (the MJX env,
float32); the two operations the two spell differently go through `nearest_k` (top-k) and
`on_valid_entries` (NumPy computes the per-contact geometry only for the contacts that count; JAX,
which needs fixed shapes, for every slot). Inputs are contact arrays as both simulators give them: geom
pairs, world positions, penetration and normal force, for one world or a batch of worlds.

Per hand geom (left palm, left fingers, right palm, right fingers) the feature is
[contact position relative to the geom (3), forces of the k sensors nearest the contact (k)],
averaged over that geom's self-contacts, zeros without contact: 4 * (k + 3) values, which are the
spec's s_left(k) followed by s_right(k).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from mjx_protamer.envs import body
from mjx_protamer.envs.touch import TouchTables, project_to_surface

N_REGIONS = len(body.REGIONS)
HAND_HAND_ENTRIES = 2
N_EXTENDED = len(body.EXTENDED_REGIONS)


def nearest_k(xp, d, k: int):
    """Indices of the k smallest entries along the last axis, nearest first (ties: lower index)."""
    if xp is np:
        return np.argsort(d, axis=-1, kind="stable")[..., :k]
    import jax

    return jax.lax.top_k(-d, k)[1]


def on_valid_entries(xp, valid, fn, *entries):
    """`fn` over contact entries (arrays with `valid`'s leading shape); NumPy computes only the valid
    entries and fills the others with zeros (a batch of worlds has few active contacts), JAX all of them.
    Callers give invalid entries zero weight, so the two agree bit for bit on what counts."""
    if xp is not np:
        return fn(*entries)
    where = np.nonzero(valid)
    outs = fn(*(x[where] for x in entries))
    full = []
    for out in outs:
        z = np.zeros(valid.shape + out.shape[1:], out.dtype)
        z[where] = out
        full.append(z)
    return full


@dataclasses.dataclass(frozen=True)
class SensingTables:
    """Static per-model tables (numpy; the JAX env converts them once)."""

    touch: TouchTables
    geom_hand: np.ndarray  # (ngeom,) 0..3 for hand geoms, -1 otherwise
    geom_region: np.ndarray  # (ngeom,) 0..7 main regions, 8..11 extended, -1 for the floor
    hand_excluded_region: np.ndarray  # (4,) region a hand geom may not count (its own lower arm)

    def as_xp(self, xp) -> dict[str, Any]:
        t = self.touch
        return {
            "candidates": xp.asarray(t.candidates), "candidate_pos": xp.asarray(np.moveaxis(t.sensors[t.candidates], -1, 1)),
            "grid_origin": xp.asarray(t.grid_origin), "grid_cell": xp.asarray(t.grid_cell),
            "grid_dims": xp.asarray(t.grid_dims), "grid_offset": xp.asarray(t.grid_offset),
            "spread_radius": xp.asarray(t.spread_radius), "radius": xp.asarray(t.radius),
            "half_length": xp.asarray(t.half_length), "geom_hand": xp.asarray(self.geom_hand),
            "geom_region": xp.asarray(self.geom_region),
            "hand_excluded_region": xp.asarray(self.hand_excluded_region),
        }


def build_sensing_tables(geom_names: list[str], touch: TouchTables) -> SensingTables:
    regions = list(body.REGIONS) + list(body.EXTENDED_REGIONS)
    geom_hand = np.array([body.HAND_GEOMS.index(g) if g in body.HAND_GEOMS else -1 for g in geom_names],
                         dtype=np.int32)
    geom_region = np.array(
        [regions.index(body.GEOM_REGION[g]) if g in body.GEOM_REGION else -1 for g in geom_names],
        dtype=np.int32)
    excluded = np.array([regions.index(body.OWN_EXCLUDED_REGION[h.split("_")[0]]) for h in body.HAND_GEOMS],
                        dtype=np.int32)
    return SensingTables(touch=touch, geom_hand=geom_hand, geom_region=geom_region,
                         hand_excluded_region=excluded)


def sense(xp, tables: dict[str, Any], k: int, geom, pos, dist, normal_force, geom_xpos, geom_xmat):
    """Touch features (..., 4 * (k + 3)), main region mask (..., 8) and extended region mask (..., 4).

    geom (..., n, 2) int, pos (..., n, 3), dist (..., n), normal_force (..., n): the contacts (inactive
    ones allowed: dist >= 0 ignores them). geom_xpos (..., ngeom, 3), geom_xmat (..., ngeom, 3, 3): geom
    frames. Any leading shape: one world (the MJX env, vmapped; the twin) or a batch of worlds at once
    (the native backend's host side, `NativePhysics._sense_reference`; `slot_sensing` is its fast twin).
    """
    # Each contact is seen from its hand geom. A hand-to-hand contact touches both hands: the second
    # hand's view is added for the HAND_HAND_ENTRIES deepest such contacts (more at once is rare).
    geom_hand = tables["geom_hand"]
    g1, g2 = geom[..., 0], geom[..., 1]
    first_is_hand = geom_hand[g1] >= 0
    both_hands = first_is_hand & (geom_hand[g2] >= 0) & (dist < 0)
    extra = nearest_k(xp, xp.where(both_hands, dist, 1e9), min(HAND_HAND_ENTRIES, geom.shape[-2]))

    def also(x, extra_x):
        return xp.concatenate([x, extra_x], axis=-1)

    def take(x, idx):  # entries of x (..., n) at idx (..., e)
        return xp.take_along_axis(x, idx, axis=-1)

    own = also(xp.where(first_is_hand, g1, g2), take(g2, extra))
    other = also(xp.where(first_is_hand, g2, g1), take(g1, extra))
    p_world = xp.concatenate([pos, xp.take_along_axis(pos, extra[..., None], axis=-2)], axis=-2)
    force = also(normal_force, take(normal_force, extra))
    active = also(dist < 0, take(both_hands, extra))

    hand = geom_hand[own]
    region = tables["geom_region"][other]
    is_hand = hand >= 0
    hand_i = xp.where(is_hand, hand, 0)
    valid = active & is_hand & (region >= 0) & (region != tables["hand_excluded_region"][hand_i])

    frame_pos = xp.take_along_axis(geom_xpos, own[..., None], axis=-2)
    frame_mat = xp.take_along_axis(geom_xmat, own[..., None, None], axis=-3)
    p_local, q, near_x, near_y, near_z, w_sum = on_valid_entries(
        xp, valid, lambda *e: _entry_geometry(xp, tables, k, *e), hand_i, p_world, frame_pos, frame_mat)
    near_pos = (near_x, near_y, near_z)

    # Each contact's normal force is spread over the sensors within the radius with a linear
    # fall-off, normalised so the sensors' forces sum to the contact's force. A sensor's reading is
    # the sum over all contacts on its geom. Contacts are few, so the sum is computed densely
    # between contacts (E x k x E) rather than scattered into the ~1,200-sensor field.
    radius = tables["spread_radius"][hand_i]  # (..., E)
    scale = xp.where(valid & (w_sum > 0), force / xp.where(w_sum > 0, w_sum, 1.0), 0.0)  # (..., E)
    gap = xp.sqrt(sum((near_pos[a][..., :, :, None] - q[..., None, None, :, a]) ** 2
                      for a in range(3)))  # (..., E, k, E')
    w_pair = xp.maximum(1.0 - gap / radius[..., None, None, :], 0.0)  # (NumPy's clip is slower)
    same_geom = (hand_i[..., :, None] == hand_i[..., None, :]).astype(w_pair.dtype)  # (..., E, E')
    readings = xp.einsum("...ejf,...ef,...f->...ej", w_pair, same_geom, scale)  # (..., E, k)

    features = xp.concatenate([p_local, readings], axis=-1) * valid[..., None]
    onehot = (hand_i[..., None] == xp.arange(4)) & valid[..., None]  # (..., E, 4)
    count = xp.sum(onehot, axis=-2)
    summed = xp.einsum("...nh,...nf->...hf", onehot.astype(features.dtype), features)
    touch = (summed / xp.maximum(count, 1)[..., None]).reshape(summed.shape[:-2] + (-1,))

    region_hits = (region[..., None] == xp.arange(N_REGIONS + N_EXTENDED)) & valid[..., None]
    touched = xp.any(region_hits, axis=-2)
    return touch, touched[..., :N_REGIONS], touched[..., N_REGIONS:]


def entry_voxel(xp, tables, hand_i, p_world, frame_pos, frame_mat):
    """Per contact entry: its position in the hand geom's frame, its projection on the surface, and the voxel of
    the hand geom's grid that lists its candidate sensors."""
    # Contact position in the hand geom's frame (row vectors: R^T (p - x) == (p - x) @ R).
    p_local = xp.einsum("...i,...ij->...j", p_world - frame_pos, frame_mat)
    q = project_to_surface(xp, p_local, tables["half_length"][hand_i], tables["radius"][hand_i])
    # Candidate sensors from the voxel grid of the hand geom: one row of positions each (padding is a
    # far-away dummy sensor that never gets weight).
    cell = tables["grid_cell"][hand_i][..., None]
    dims = tables["grid_dims"][hand_i]
    ijk = xp.floor((q - tables["grid_origin"][hand_i]) / cell).astype(dims.dtype)
    ijk = xp.minimum(xp.maximum(ijk, 0), dims - 1)
    voxel = (tables["grid_offset"][hand_i] + (ijk[..., 0] * dims[..., 1] + ijk[..., 1]) * dims[..., 2]
             + ijk[..., 2])
    return p_local, q, voxel


def _entry_geometry(xp, tables, k: int, hand_i, p_world, frame_pos, frame_mat):
    """Per contact entry (any leading shape): its position in the hand geom's frame, its projection on
    the surface, the positions of its k nearest sensors (x, y, z, each (..., k)) and the sum of its
    fall-off weights over the sensors."""
    p_local, q, voxel = entry_voxel(xp, tables, hand_i, p_world, frame_pos, frame_mat)
    # Positions are component-major, (..., 3, C): XLA's CPU loops vectorise over C, not over xyz.
    cand_pos = tables["candidate_pos"][voxel]
    d = xp.sqrt(sum((cand_pos[..., a, :] - q[..., a, None]) ** 2 for a in range(3)))  # (..., C)
    nearest = nearest_k(xp, d, k)  # (..., k), nearest first
    near = [xp.take_along_axis(cand_pos[..., a, :], nearest, axis=-1) for a in range(3)]
    w_sum = xp.sum(xp.maximum(1.0 - d / tables["spread_radius"][hand_i][..., None], 0.0), axis=-1)
    return (p_local, q, *near, w_sum)
