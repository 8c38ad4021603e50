"""A pretrain run's reward model on disk (experiments/saved_reward_model.py): checksummed, exact, and the files
of runs saved before checksums still load."""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from flax import serialization

from mjx_protamer.errors import CheckpointDamaged, CheckpointError
from mjx_protamer.experiments import saved_reward_model
from mjx_protamer.human.reward_model import RewardModelConfig, reward_nets

OBS, ACT = 6, 2
CONFIG = RewardModelConfig(hidden=(16,))


def trained():
    """(params, Adam state, updates) after two Adam steps: every leaf differs from a fresh model's."""
    net = reward_nets(CONFIG).net
    params = net.init(jax.random.PRNGKey(1), jnp.zeros((1, OBS)), jnp.zeros((1, ACT)))
    opt = optax.adam(CONFIG.learning_rate)
    state = opt.init(params)
    for _ in range(2):
        grads = jax.tree.map(lambda p: jnp.full_like(p, 0.3), params)
        step, state = opt.update(grads, state)
        params = optax.apply_updates(params, step)
    return params, state, 2


def assert_same(loaded, saved):
    got, want = jax.tree_util.tree_leaves_with_path(loaded), jax.tree_util.tree_leaves_with_path(saved)
    assert [p for p, _ in got] == [p for p, _ in want]
    for (path, a), (_, b) in zip(got, want):
        assert np.asarray(a).dtype == np.asarray(b).dtype and np.array_equal(a, b), path


def old_format_file(run_dir, params, opt_state, updates):
    """reward_model.msgpack as pretrain wrote it before checksums (feedback_train.reward_model_bytes)."""
    path = run_dir / saved_reward_model.OLD_FILE
    path.write_bytes(serialization.msgpack_serialize({
        "params": serialization.to_state_dict(jax.device_get(params)),
        "opt_state": serialization.to_state_dict(jax.device_get(opt_state)),
        "updates": int(updates)}))
    return path


def test_round_trip_is_exact(tmp_path):
    params, opt_state, updates = trained()
    saved_reward_model.save(tmp_path, params, opt_state, updates)
    loaded = saved_reward_model.load(tmp_path, saved_reward_model.like(CONFIG, OBS, ACT))
    assert_same(loaded, saved_reward_model.tree(params, opt_state, updates))
    assert int(loaded["updates"]) == 2


@pytest.mark.parametrize("damage", ["flipped", "truncated"])
def test_a_damaged_reward_model_is_refused_in_one_line_naming_it(tmp_path, damage):
    saved_reward_model.save(tmp_path, *trained())
    files = sorted(p for p in (tmp_path / saved_reward_model.DIR / "0").rglob("*")
                   if p.is_file() and p.name != "manifest.json")
    target = max(files, key=lambda p: p.stat().st_size)  # the arrays' data
    data = bytearray(target.read_bytes())
    if damage == "flipped":
        data[len(data) // 2] ^= 0xFF
    else:
        del data[len(data) // 2:]
    target.write_bytes(bytes(data))
    with pytest.raises(CheckpointDamaged) as e:
        saved_reward_model.load(tmp_path, saved_reward_model.like(CONFIG, OBS, ACT))
    message = str(e.value)
    assert "\n" not in message and str(tmp_path / saved_reward_model.DIR / "0") in message
    assert ("SHA-256" if damage == "flipped" else "truncated") in message


def test_a_reward_model_saved_before_checksums_still_loads_exactly(tmp_path):
    params, opt_state, updates = trained()
    old_format_file(tmp_path, params, opt_state, updates)
    loaded = saved_reward_model.load(tmp_path, saved_reward_model.like(CONFIG, OBS, ACT))
    assert_same(loaded, saved_reward_model.tree(params, opt_state, updates))


def test_a_truncated_old_file_or_one_of_another_config_is_refused_naming_it(tmp_path):
    path = old_format_file(tmp_path, *trained())
    like = saved_reward_model.like(CONFIG, OBS, ACT)
    whole = path.read_bytes()
    path.write_bytes(whole[:len(whole) // 2])
    with pytest.raises(CheckpointDamaged, match=f"reward model {path} is damaged: it cannot be read") as e:
        saved_reward_model.load(tmp_path, like)
    assert "\n" not in str(e.value)
    path.write_bytes(whole)
    wider = saved_reward_model.like(RewardModelConfig(hidden=(32,)), OBS, ACT)
    with pytest.raises(CheckpointError, match=f"reward model {path} does not fit this config"):
        saved_reward_model.load(tmp_path, wider)


def test_a_run_without_a_reward_model_says_what_to_give(tmp_path):
    with pytest.raises(CheckpointError, match="holds no reward model"):
        saved_reward_model.load(tmp_path, saved_reward_model.like(CONFIG, OBS, ACT))
