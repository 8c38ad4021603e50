"""The touch-sensor model of the hands: sensor points on the palm and finger surfaces.

As in the reference, sensor points cover each hand geom's surface at a fixed spacing (hand 7 mm,
fingers 2 mm). A contact's normal force is spread to the sensors within `spread_radius` of the contact
point with a linear fall-off, rescaled so the sensors' forces sum to the contact's normal force; the
observation then reads the k sensors nearest the contact point.

Searching all ~1,200 finger sensors for every contact slot would dominate the MJX step, so each geom
gets a voxel grid (in its local frame) listing, per voxel, every sensor that can be among the k
nearest or within the spread radius of a point in that voxel. The per-contact work is then a few dozen
distances. `TouchTables.check_candidates` proves the tables exact on sampled surface points.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mjx_protamer.envs import body

# The dummy sensor index's position: far from every real point, so it never gets weight.
FAR = 1.0e3


def _fibonacci_sphere(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = math.pi * (1 + 5**0.5) * i
    return np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1)


def sphere_points(radius: float, spacing: float) -> np.ndarray:
    n = max(8, round(4 * math.pi * radius**2 / spacing**2))
    return radius * _fibonacci_sphere(n)


def capsule_points(radius: float, half_length: float, spacing: float) -> np.ndarray:
    """Points on a capsule whose axis is local z (MuJoCo's capsule frame)."""
    n_theta = max(6, round(2 * math.pi * radius / spacing))
    n_z = max(1, round(2 * half_length / spacing))
    theta = 2 * math.pi * (np.arange(n_theta) + 0.5) / n_theta
    z = np.linspace(-half_length, half_length, n_z + 1)
    tt, zz = np.meshgrid(theta, z)
    side = np.stack([radius * np.cos(tt).ravel(), radius * np.sin(tt).ravel(), zz.ravel()], axis=1)
    hemi = _fibonacci_sphere(2 * max(4, round(2 * math.pi * radius**2 / spacing**2)))
    top = hemi[hemi[:, 2] > 0]
    caps = [radius * top + [0, 0, half_length], radius * top * [1, 1, -1] + [0, 0, -half_length]]
    return np.concatenate([side] + caps, axis=0)


@dataclasses.dataclass(frozen=True)
class TouchTables:
    """Static arrays for the touch model of the 4 hand geoms (body.HAND_GEOMS order)."""

    sensors: np.ndarray  # (N + 1, 3) local positions, all geoms concatenated, last row the dummy
    sensor_geom: np.ndarray  # (N + 1,) which hand geom (0..3) a sensor belongs to; -1 for the dummy
    candidates: np.ndarray  # (V, C) sensor indices per voxel, padded with the dummy index N
    grid_origin: np.ndarray  # (4, 3) voxel grid origin per hand geom (local frame)
    grid_cell: np.ndarray  # (4,) voxel size per hand geom
    grid_dims: np.ndarray  # (4, 3) voxels per axis
    grid_offset: np.ndarray  # (4,) first voxel row of each geom in `candidates`
    spread_radius: np.ndarray  # (4,) linear fall-off radius per hand geom
    spacing: np.ndarray  # (4,) sensor spacing per hand geom
    radius: np.ndarray  # (4,) geom radius
    half_length: np.ndarray  # (4,) capsule half-length along local z (0 for a sphere)
    k: int

    @property
    def n_sensors(self) -> int:
        return self.sensors.shape[0] - 1

    def check_candidates(self, rng: np.random.Generator, n_points: int = 2000) -> None:
        """Assert that for random points near each surface the candidates hold the exact k nearest
        sensors (of the point projected on the surface) and every sensor within the spread radius."""
        for h in range(4):
            own = np.where(self.sensor_geom == h)[0]
            pts = self.sensors[rng.choice(own, n_points)] + rng.normal(scale=self.spacing[h], size=(n_points, 3))
            pts = project_to_surface(np, pts, self.half_length[h], self.radius[h])
            for p in pts:
                cand = self.candidates[voxel_index(self, h, p)]
                cand = cand[cand < self.n_sensors]
                d_all = np.linalg.norm(self.sensors[own] - p, axis=1)
                nearest = set(own[np.argsort(d_all)[: self.k]])
                within = set(own[d_all < self.spread_radius[h]])
                missing = (nearest | within) - set(cand.tolist())
                if d_all.min() >= self.spread_radius[h]:
                    raise AssertionError(f"hand geom {h}: no sensor within the spread radius of {p}")
                if missing:
                    raise AssertionError(f"hand geom {h}: candidates miss sensors {sorted(missing)[:5]} at {p}")


def project_to_surface(xp, p: "np.ndarray", half_length, radius) -> "np.ndarray":
    """Closest point on a capsule (axis local z; a sphere when half_length is 0) to local points p.

    Contact points sit up to half a penetration off the surfaces; sensors are looked up at the
    projection so that the candidate tables only need to cover the surface itself.
    """
    half_length = xp.asarray(half_length)[..., None]
    radius = xp.asarray(radius)[..., None]
    z = xp.clip(p[..., 2:3], -half_length, half_length)
    axis_point = xp.concatenate([xp.zeros_like(p[..., :2]), z], axis=-1)
    v = p - axis_point
    norm = xp.sqrt(xp.sum(v * v, axis=-1, keepdims=True))
    # A point on the axis has no direction: any surface point is as near; take local +x.
    safe = xp.where(norm > 1e-9, v / xp.maximum(norm, 1e-9), xp.asarray([1.0, 0.0, 0.0]))
    return axis_point + radius * safe


def voxel_index(tables: TouchTables, hand: int, p_local: np.ndarray) -> int:
    ijk = np.floor((p_local - tables.grid_origin[hand]) / tables.grid_cell[hand]).astype(int)
    ijk = np.clip(ijk, 0, tables.grid_dims[hand] - 1)
    nx, ny, nz = tables.grid_dims[hand]
    return int(tables.grid_offset[hand] + (ijk[0] * ny + ijk[1]) * nz + ijk[2])


def _hand_geom_points(spacing_hand: float, spacing_fingers: float) -> list[np.ndarray]:
    palm = sphere_points(body.PALM_R, spacing_hand)
    fingers = capsule_points(body.FINGER_R, body.FINGER_HALF, spacing_fingers)
    return [palm, fingers, palm.copy(), fingers.copy()]


def build_touch_tables(k: int = 10, spacing_hand: float = 0.007, spacing_fingers: float = 0.002,
                       spread_factor: float = 1.5) -> TouchTables:
    """Sensor points and voxel candidate tables for the 4 hand geoms.

    spread_factor: the spread radius in sensor spacings (1.5: each contact reaches about 7 sensors).
    """
    points = _hand_geom_points(spacing_hand, spacing_fingers)
    radius = np.array([body.PALM_R, body.FINGER_R, body.PALM_R, body.FINGER_R])
    half_length = np.array([0.0, body.FINGER_HALF, 0.0, body.FINGER_HALF])
    spacing = np.array([spacing_hand, spacing_fingers, spacing_hand, spacing_fingers])
    spread = spread_factor * spacing
    sensors = np.concatenate(points + [np.full((1, 3), FAR)], axis=0)
    sensor_geom = np.concatenate([np.full(len(p), h) for h, p in enumerate(points)] + [[-1]])
    n = len(sensors) - 1
    offsets = np.cumsum([0] + [len(p) for p in points])

    rows, origins, cells, dims, grid_offsets = [], [], [], [], []
    for h, pts in enumerate(points):
        cell = spacing[h]
        margin = 2 * spacing[h]
        lo = pts.min(0) - margin
        hi = pts.max(0) + margin
        dim = np.maximum(1, np.ceil((hi - lo) / cell).astype(int))
        centres = np.stack(np.meshgrid(*[lo[a] + cell * (np.arange(dim[a]) + 0.5) for a in range(3)],
                                       indexing="ij"), axis=-1).reshape(-1, 3)
        # Any point in a voxel is within half a diagonal of its centre; the k nearest of such a point
        # are within r_k(point) <= r_k(centre) + half_diag, so a ball of r_k(centre) + 2 half_diag
        # (and of the spread radius + half_diag) around the centre holds every sensor needed.
        # Only voxels that meet the surface are ever queried (points are projected onto it first).
        half_diag = 0.5 * math.sqrt(3) * cell
        d = np.linalg.norm(centres[:, None, :] - pts[None, :, :], axis=-1)
        r_k = np.sort(d, axis=1)[:, k - 1]
        ball = np.maximum(r_k + 2 * half_diag, spread[h] + half_diag)
        on_surface = np.linalg.norm(
            centres - project_to_surface(np, centres, half_length[h], radius[h]), axis=1) <= half_diag
        for v in range(len(centres)):
            rows.append(offsets[h] + np.where(d[v] <= ball[v])[0] if on_surface[v] else np.zeros(0, int))
        grid_offsets.append(sum(int(np.prod(x)) for x in dims))
        origins.append(lo)
        cells.append(cell)
        dims.append(dim)
    width = max(len(r) for r in rows)
    candidates = np.full((len(rows), width), n, dtype=np.int32)
    for v, r in enumerate(rows):
        candidates[v, : len(r)] = r
    return TouchTables(
        sensors=sensors.astype(np.float64),
        sensor_geom=sensor_geom.astype(np.int32),
        candidates=candidates,
        grid_origin=np.array(origins),
        grid_cell=np.array(cells),
        grid_dims=np.array(dims, dtype=np.int32),
        grid_offset=np.array(grid_offsets, dtype=np.int32),
        spread_radius=spread,
        spacing=spacing,
        radius=radius,
        half_length=half_length,
        k=k,
    )
