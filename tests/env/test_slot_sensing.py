"""The native backend's host sensing (`SlotSensing`) gives exactly the floats `sensing.sense(np, ...)` gives.

What each test pins down:
- NumPy's einsum adds the terms of `sense`'s two sums one by one, ascending, from zero: the fact
  `SlotSensing` relies on to sum each world's hand geom alone;
- on random poses and on forged contact-heavy slots (many deep contacts per world, several on one hand
  geom within the spread radius, forces over 16 orders of magnitude, so the order of every sum shows),
  its touch features and region masks equal `NativePhysics._sense_reference` bit for bit, including
  worlds over the contact capacity and hand-to-hand contacts;
- a batch with a non-finite contact goes through `sense` itself.
"""

from __future__ import annotations

import types

import numpy as np
import pytest

from mjx_protamer.envs.native_physics import _SLOT_WIDTH


def _sum_in_order(terms, axis):
    total = np.zeros(np.delete(terms.shape, axis))
    for t in np.moveaxis(terms, axis, 0):
        total = total + t
    return total


@pytest.mark.parametrize("worlds", [1, 3, 32])
def test_einsum_sums_in_ascending_order_from_zero(worlds):
    rng = np.random.default_rng(worlds)
    for entries in range(1, 13):
        w = rng.random((worlds, entries, 10, entries)) * 10.0 ** rng.integers(-8, 9, (worlds, entries, 10, entries))
        same = (rng.random((worlds, entries, entries)) < 0.7).astype(float)
        scale = rng.random((worlds, entries)) * 10.0 ** rng.integers(-8, 9, (worlds, entries))
        np.testing.assert_array_equal(np.einsum("...ejf,...ef,...f->...ej", w, same, scale),
                                      _sum_in_order(w * same[..., None, :] * scale[..., None, None, :], -1))
        onehot = (rng.integers(0, 4, (worlds, entries))[..., None] == np.arange(4)).astype(float)
        features = rng.standard_normal((worlds, entries, 13)) * 10.0 ** rng.integers(-8, 9, (worlds, entries, 13))
        np.testing.assert_array_equal(np.einsum("...nh,...nf->...hf", onehot, features),
                                      _sum_in_order(onehot[..., :, :, None] * features[..., :, None, :], -3))


@pytest.fixture(scope="module")
def physics():
    from mjx_protamer.envs.config import EnvConfig
    from mjx_protamer.envs.native_env import NativeSelfTouchEnv

    return NativeSelfTouchEnv(EnvConfig(reset_noise_steps=0)).physics


def _posed_batch(physics, n, seed):
    """Sensor slots and geom frames of n random poses after `mj_forward`, as the batch binds them."""
    m = physics.mj_model
    rng = np.random.default_rng(seed)
    qpos = rng.uniform(m.jnt_range[:, 0], m.jnt_range[:, 1], (n, m.nq))
    rows = physics.state_rows(qpos, np.zeros((n, m.nv)), np.zeros((n, m.nu)), np.zeros((n, m.nv)))
    physics.forward(rows)
    b = physics._batch(n)
    return types.SimpleNamespace(nsim=n, sensordata=b.sensordata.copy(), geom_xpos=b.geom_xpos.copy(),
                                 geom_xmat=b.geom_xmat.copy())


def _forge_contacts(physics, b, seed):
    """Activate about half of each world's slots, deep, with forces from 1e-8 to 1e8, and put the contacts of
    each slot's hand geom close together near its surface: several entries per hand geom overlap."""
    rng = np.random.default_rng(seed)
    tables = physics._tables
    n, ng = b.nsim, physics.mj_model.ngeom
    slots = b.sensordata.reshape(n, physics.n_slots, _SLOT_WIDTH)
    g1, g2 = physics.slot_geom[:, 0], physics.slot_geom[:, 1]
    own = np.where(tables["geom_hand"][g1] >= 0, g1, g2)
    on = rng.random((n, physics.n_slots)) < 0.5
    slots[:, :, 4] = np.where(on, -rng.uniform(0, 0.01, on.shape), 0.0)
    slots[:, :, 1] = rng.random(on.shape) * 10.0 ** rng.integers(-8, 9, on.shape)
    hand_pos = b.geom_xpos.reshape(n, ng, 3)[:, own]
    surface = tables["radius"][tables["geom_hand"][own]][None, :, None]
    slots[:, :, 5:8] = hand_pos + surface * np.array([1.0, 0.0, 0.0]) + rng.normal(scale=0.001, size=hand_pos.shape)
    return own, on


@pytest.mark.parametrize("forged", [False, True])
def test_slot_sensing_equals_sense_bit_for_bit(physics, forged):
    for seed in range(3):
        b = _posed_batch(physics, 64, seed)
        if forged:
            own, on = _forge_contacts(physics, b, seed)
            same_hand = max(np.bincount(own[world_on], minlength=physics.mj_model.ngeom).max() for world_on in on)
            assert same_hand >= 4, "no hand geom with several contacts: the order of the sums is not exercised"
        else:
            assert np.count_nonzero(b.sensordata.reshape(64, -1, _SLOT_WIDTH)[:, :, 4] < 0) > 20
        fast = physics._sense(b)
        reference = physics._sense_reference(b)
        for got, want in zip(fast, reference):
            assert got.dtype == want.dtype == np.float64
            np.testing.assert_array_equal(got.view(np.uint64), want.view(np.uint64))
        assert (np.abs(fast[0]).sum(axis=1) > 0).sum() >= 10


def test_a_non_finite_contact_goes_through_sense(physics):
    b = _posed_batch(physics, 16, 0)
    _forge_contacts(physics, b, 0)
    slots = b.sensordata.reshape(16, physics.n_slots, _SLOT_WIDTH)
    slots[3, :, 5] = np.nan
    ng = physics.mj_model.ngeom
    assert physics._slot_sensing(slots, b.geom_xpos.reshape(16, ng, 3), b.geom_xmat.reshape(16, ng, 3, 3)) is None
    for got, want in zip(physics._sense(b), physics._sense_reference(b)):
        np.testing.assert_array_equal(got, want)
    assert np.isnan(physics._sense(b)[0][3]).any()
