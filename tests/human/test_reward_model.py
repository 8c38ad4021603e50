"""DeepTAMER's reward model learns a known synthetic reward; its params are a plain jit argument.

A live session's model (`live.reward_model.SessionRewardModel`) absorbs each chunk's credited events and silences
in one jitted call through the batched path's pieces (`human.batched.ring_add`, `reward_model_updates`); the
tests of what the fit does with stored rows call those pieces directly.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from mjx_protamer.config import ConfigError, from_dict
from mjx_protamer.human.batched import reward_model_updates, ring_add
from mjx_protamer.human.credit import CreditConfig
from mjx_protamer.human.reward_model import RewardMLP, RewardModelConfig, reward_fn, reward_nets, weighted_loss
from mjx_protamer.live.reward_model import SessionRewardModel

OBS, ACT = 8, 2
NO_SILENCE = (np.zeros((0, OBS), np.float32), np.zeros((0, ACT), np.float32))


def synthetic_reward(obs, act):
    return np.tanh(1.5 * obs[:, 0] - obs[:, 1] * act[:, 0] + 0.5 * act[:, 1])


def session_model(config, obs_size=OBS, act_size=ACT, seed=0, chunk_steps=1, max_events=1, rows_per_event=1,
                  credit=None):
    return SessionRewardModel(config, credit or CreditConfig(), obs_size, act_size, seed, chunk_steps, max_events,
                              rows_per_event)


@functools.lru_cache(maxsize=None)
def _replay(config, n_updates):
    """`n_updates` replay minibatches (batched.reward_model_updates), compiled once per config."""
    return jax.jit(functools.partial(
        reward_model_updates, reward_nets(config).fit, optax.adam(config.learning_rate), n_fresh=0,
        n_replay=n_updates, batch_size=config.batch_size, replay_min_rows=config.replay_min_rows,
        balance_max=config.balance_max if config.balance_signs else None))


def fit_stored(config, obs, act, weight, target, n_updates, seed=0):
    """A session's fresh reward model (its initialisation for `seed`) after `n_updates` replay minibatches on a
    feedback ring holding these rows (balanced by sign with `config.balance_signs`)."""
    model = session_model(config, obs.shape[1], act.shape[1], seed)
    s = model.state
    ring = ring_add(s.ring, *(jnp.asarray(x, jnp.float32) for x in (obs, act, weight, target)))
    fresh = (ring.obs[:1], ring.action[:1], jnp.zeros((1,)), jnp.zeros((1,)))  # no fresh step: replay alone
    params, opt_state, _, live = _replay(config, n_updates)(s.params, s.opt_state, ring, fresh, s.key)
    assert bool(np.all(live))
    model.state = s._replace(params=params, opt_state=opt_state, ring=ring, updates=s.updates + n_updates)
    return model


def test_learns_a_known_synthetic_reward_from_credited_noisy_feedback():
    """300 events through `absorb`, as a session's drains: each is about one state (its value that state's
    synthetic reward plus noise) and credits 15 consecutive steps around it (a slow random walk) with 0.9^i
    weights, from which `draw` takes 8 rows. Per drain: one minibatch step per event, then `chunk_steps //
    replay_every` replay minibatches once the ring holds `replay_min_rows`."""
    rng = np.random.default_rng(0)
    chunk_steps, K = 60, 8
    model = session_model(RewardModelConfig(replay_every=1), chunk_steps=chunk_steps, max_events=15, rows_per_event=K)

    def event():
        obs = rng.normal(size=(1, OBS)) + 0.02 * np.cumsum(rng.normal(size=(15, OBS)), axis=0)
        act = np.clip(rng.uniform(-1, 1, size=(1, ACT)) + 0.02 * np.cumsum(rng.normal(size=(15, ACT)), axis=0), -1, 1)
        value = float(synthetic_reward(obs[:1], act[:1])[0] + 0.1 * rng.normal())
        o, a = model.draw(obs.astype(np.float32), act.astype(np.float32), 0.9 ** np.arange(15))
        assert o.shape == (K, OBS) and a.shape == (K, ACT)
        return o, a, value

    expected = 0
    for n in [5] + [15] * 19 + [10]:  # 300 events; the first drain's 40 rows are too few to replay
        got = model.absorb([event() for _ in range(n)], NO_SILENCE)
        assert got == n + (chunk_steps if int(model.state.ring.size) >= 64 else 0)
        expected += got
    assert model.updates == expected == 300 + 20 * chunk_steps
    assert int(model.state.ring.size) == 300 * K and np.isfinite(model.last_loss)
    obs = rng.normal(size=(2000, OBS)).astype(np.float32)
    act = rng.uniform(-1, 1, size=(2000, ACT)).astype(np.float32)
    corr = np.corrcoef(model.predict(obs, act), synthetic_reward(obs, act))[0, 1]
    assert corr > 0.9, corr


def test_a_bounded_model_never_rates_beyond_the_labels():
    """`bounded`: the same params through tanh, so off the labelled states r_hat cannot exceed +-1 however far
    the linear model would extrapolate; checkpoints of either kind share one params tree."""
    params = RewardMLP((8,)).init(jax.random.PRNGKey(0), jnp.zeros((1, OBS)), jnp.zeros((1, ACT)))
    obs = 50.0 * jax.random.normal(jax.random.PRNGKey(1), (256, OBS))  # far outside any training state
    act = jnp.zeros((256, ACT))
    linear, bounded = reward_fn((8,))(params, obs, act), reward_fn((8,), True)(params, obs, act)
    assert float(jnp.abs(linear).max()) > 1.5
    np.testing.assert_allclose(bounded, jnp.tanh(linear), rtol=1e-6)
    model = session_model(RewardModelConfig(hidden=(8,), bounded=True))
    assert jax.tree.structure(model.params) == jax.tree.structure(params)
    assert np.abs(model.predict(np.asarray(obs), np.asarray(act))).max() <= 1.0


def test_weighted_loss_ignores_zero_weight_rows():
    apply = reward_fn((4,))
    params = jax.tree.map(jnp.zeros_like, RewardMLP((4,)).init(jax.random.PRNGKey(0), jnp.zeros((1, 2)), jnp.zeros((1, 1))))
    obs, act = jnp.zeros((3, 2)), jnp.zeros((3, 1))
    # prediction 0 everywhere: loss = (1*1 + 0*100) / 1
    assert float(weighted_loss(params, apply, obs, act, jnp.array([1.0, 0.0, 0.0]), jnp.array([1.0, 10.0, 0.0]))) == 1.0


def test_an_events_rows_are_drawn_in_proportion_to_its_credit():
    """`draw`: an event's credited steps, however many (Deep TAMER's 3.8 s at 200 Hz is 760), become
    rows_per_event rows drawn in proportion to their weight: one shape for the jitted absorb."""
    model = session_model(RewardModelConfig(hidden=(4,)), rows_per_event=64)
    o = np.arange(760, dtype=np.float32)[:, None] * np.ones((1, OBS), np.float32)
    w = np.zeros(760, np.float32)
    w[10] = 1.0  # all the weight on one step
    ob, ab = model.draw(o, np.ones((760, ACT), np.float32), w)
    assert ob.shape == (64, OBS) and ab.shape == (64, ACT) and (ob[:, 0] == 10).all()
    model = session_model(RewardModelConfig(hidden=(4,)), rows_per_event=20_000)
    w = 0.9 ** np.arange(15)
    ob, _ = model.draw(o[:15], np.ones((15, ACT), np.float32), w)
    freq = np.bincount(ob[:, 0].astype(int), minlength=15) / len(ob)
    np.testing.assert_allclose(freq, w / w.sum(), atol=0.01)


def test_params_are_a_jit_argument_and_updates_do_not_recompile():
    model = session_model(RewardModelConfig(hidden=(16, 16)), seed=1, chunk_steps=8, max_events=4, rows_per_event=4,
                          credit=CreditConfig(silence_weight=0.1))
    model.commit(jax.devices()[0])  # as the learner does: committed arrays in, committed out
    traces = []

    @jax.jit
    def use(params, obs, act):
        traces.append(1)
        return model.apply(params, obs, act).sum()

    x, a = jnp.ones((5, OBS)), jnp.ones((5, ACT))
    before = float(use(model.params, x, a))
    event = (np.ones((4, OBS), np.float32), np.ones((4, ACT), np.float32), 5.0)
    assert model.absorb([event], NO_SILENCE) == 1
    after = float(use(model.params, x, a))
    assert after != before and len(traces) == 1
    # drains of other sizes, with silences or nothing: the same compiled absorb (the event count is traced)
    assert model.absorb([event] * 3, (np.ones((5, OBS), np.float32), np.ones((5, ACT), np.float32))) == 3
    assert model.absorb([], NO_SILENCE) == 0
    assert model._absorb._cache_size() == 1
    ring = model.state.ring
    assert int(ring.size) == 4 + 12 + 5  # weight > 0 rows only
    np.testing.assert_allclose(np.asarray(ring.weight[16:21]), 0.1 * 4)  # a silent step weighs 0.1 events
    assert float(use(model.params, x, a)) != after and len(traces) == 1


def test_save_and_load_round_trip(tmp_path):
    """The model's state as a session saves it (reward_model/, experiments/checkpoints.py) restores into a
    model of another seed: the same predictions, ring and update count."""
    from mjx_protamer.experiments import checkpoints

    cfg = RewardModelConfig(hidden=(8,))
    m1 = session_model(cfg, seed=2, max_events=1, rows_per_event=3)
    m1.absorb([(np.ones((3, OBS), np.float32), np.ones((3, ACT), np.float32), 1.0)], NO_SILENCE)
    mngr = checkpoints.manager(tmp_path / "reward_model")
    try:
        checkpoints.save(mngr, 1, jax.device_get(m1.state))
    finally:
        mngr.close()
    m2 = session_model(cfg, seed=3, max_events=1, rows_per_event=3)
    x, a = np.ones((2, OBS)), np.zeros((2, ACT))
    assert not np.allclose(m1.predict(x, a), m2.predict(x, a))
    mngr = checkpoints.manager(tmp_path / "reward_model")
    try:
        m2.state = checkpoints.restore(mngr, 1, jax.eval_shape(lambda: m2.state))
    finally:
        mngr.close()
    np.testing.assert_allclose(m1.predict(x, a), m2.predict(x, a))
    assert m2.updates == 1 and int(m2.state.ring.size) == 3


def test_config_validation_names_the_field():
    with pytest.raises(ConfigError, match="buffer_size"):
        from_dict(RewardModelConfig, {"buffer_size": 10})


def test_sign_factors_give_praise_and_reproach_equal_weight():
    from mjx_protamer.human.reward_model import balanced_weight, sign_factors

    weight = np.array([1.0, 1.0, 1.0, 0.5, 0.03, 0.0], np.float32)
    target = np.array([1.0, 1.0, 1.0, -1.0, 0.0, -1.0], np.float32)
    for xp in (np, jnp):
        f_neg, f_pos = sign_factors(xp, xp.asarray(weight), xp.asarray(target), 10.0)
        assert float(f_neg) == pytest.approx(3.5 / 1.0) and float(f_pos) == pytest.approx(3.5 / 6.0)
        w = np.asarray(balanced_weight(xp, (f_neg, f_pos), xp.asarray(weight), xp.asarray(target)))
        assert w[:3].sum() == pytest.approx(w[3]) and w[4] == pytest.approx(0.03)  # silences keep their weight
        assert float(sign_factors(xp, xp.asarray(weight[:3]), xp.asarray(target[:3]), 10.0)[1]) == 1.0  # one sign
        assert float(sign_factors(xp, xp.asarray([100.0, 1.0]), xp.asarray([1.0, -1.0]), 10.0)[0]) == 10.0  # capped


def test_balanced_model_rates_rarely_scolded_states_lower():
    """A learner that complies is praised far more than scolded: 1 reproach per 40 praises, in overlapping
    clusters. After the same updates, the balanced model rates the scolded cluster lower and still rates the
    praised one high."""
    rng = np.random.default_rng(0)

    def fit(balance: bool):
        obs, target = [], []
        for i in range(400):
            sign = -1.0 if i % 41 == 40 else 1.0
            obs.append(rng.normal(size=(16, 2)) + [1.5 * sign, 0.0])
            target.append(np.full(16, sign))
        obs, target = np.concatenate(obs), np.concatenate(target)
        model = fit_stored(RewardModelConfig(hidden=(32, 32), balance_signs=balance), obs, np.zeros((len(obs), 1)),
                           np.ones(len(obs)), target, 300)
        probe = {s: np.array([[1.5 * s, 0.0]], np.float32) + 0.5 * rng.normal(size=(256, 2)).astype(np.float32)
                 for s in (-1.0, 1.0)}
        return {s: float(model.predict(x, np.zeros((256, 1))).mean()) for s, x in probe.items()}

    plain, balanced = fit(False), fit(True)
    # measured: -0.07 plain, -0.79 balanced (the gap 0.40 to 0.73 over five seeds of model and data)
    assert balanced[-1.0] < min(plain[-1.0] - 0.3, 0.0), (plain, balanced)
    assert balanced[1.0] > 0.5, balanced


def test_an_ensemble_fits_every_member_and_pessimism_lowers_r_hat_where_they_disagree():
    """Each member fits the labels (the loss is the members' sum, so one member's gradient never moves another);
    r_hat is the members' mean less `pessimism` x their spread: near the labelled states the members agree and
    r_hat is the label, far from them they disagree and r_hat drops below the mean."""
    cfg = RewardModelConfig(hidden=(32, 32), bounded=True, ensemble=4, pessimism=1.0)
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(256, OBS)).astype(np.float32)
    act = rng.uniform(-1, 1, size=(256, ACT)).astype(np.float32)
    target = np.sign(obs[:, 0]).astype(np.float32)  # +1 / -1 by the first feature
    model = fit_stored(cfg, obs, act, np.ones(256), target, 616)
    members = RewardMLP((32, 32), True, 4).apply(model.params, jnp.asarray(obs), jnp.asarray(act))
    assert members.shape == (4, 256)
    for m in np.asarray(members):  # every member learnt the labels on its own
        assert np.mean(np.sign(m) == target) > 0.95
    far = 20.0 * rng.normal(size=(256, OBS)).astype(np.float32)  # no label anywhere near
    spread = lambda o: np.asarray(RewardMLP((32, 32), True, 4).apply(model.params, jnp.asarray(o), jnp.asarray(act)).std(0))
    assert spread(far).mean() > 3 * spread(obs).mean()
    mean_far = np.asarray(RewardMLP((32, 32), True, 4).apply(model.params, jnp.asarray(far), jnp.asarray(act)).mean(0))
    np.testing.assert_allclose(model.predict(far, act), mean_far - spread(far), rtol=1e-5, atol=1e-6)
    assert np.mean(np.sign(model.predict(obs, act)) == target) > 0.95


def test_a_pessimistic_ensemble_whose_members_agree_gives_the_actor_a_finite_gradient():
    """Members that agree exactly (here: the same weights) have a spread of 0; the actor climbs r_hat through its
    action, so r_hat's gradient must stay finite there (jnp.std's was NaN, and a live session's actor went NaN
    with it: the twelfth session's ensemble screen)."""
    ens = RewardMLP((16, 16), True, 2)
    params = ens.init(jax.random.PRNGKey(0), jnp.zeros((1, OBS)), jnp.zeros((1, ACT)))
    same = jax.tree_util.tree_map(lambda x: jnp.stack([x[0], x[0]]), params)  # member 1 := member 0
    obs = jnp.asarray(np.random.default_rng(1).normal(size=(8, OBS)), jnp.float32)
    act = jnp.zeros((8, ACT), jnp.float32)
    grad = jax.grad(lambda a: reward_fn((16, 16), True, 2, 1.0)(same, obs, a).sum())(act)
    assert np.all(np.isfinite(np.asarray(grad)))
    r = reward_fn((16, 16), True, 2, 1.0)(same, obs, act)
    members = ens.apply(same, obs, act)
    np.testing.assert_allclose(np.asarray(r), np.asarray(members[0]), atol=2e-6)
    mean_grad = jax.grad(lambda a: ens.apply(same, obs, a).mean(0).sum())(act)
    np.testing.assert_allclose(np.asarray(grad), np.asarray(mean_grad), rtol=1e-4, atol=1e-6)


def test_pessimism_without_an_ensemble_is_refused():
    with pytest.raises(ConfigError, match="ensemble"):
        from_dict(RewardModelConfig, {"pessimism": 0.5})


@pytest.mark.parametrize("field,value", [("lr_final_fraction", 0.0), ("lr_final_fraction", 1.5),
                                         ("lr_decay_from", 1.0)])
def test_a_reward_model_step_size_decay_out_of_range_is_refused(field, value):
    with pytest.raises(ConfigError, match=field):
        from_dict(RewardModelConfig, {field: value})


def test_asinh_inputs_tell_a_light_touch_of_one_hand_under_a_hard_press_of_the_other():
    """`asinh_obs`: the lateral rule's two-handed states (a 5-50 N press by the right hand, 0.2-1 N by the left:
    score 0) against the right hand alone (+1). On raw newtons the light touch is a small shift beside the
    press's spread; on asinh(obs) it is a step of the same order, and the same 100 minibatches separate the two
    far better (measured, seeds 0-2 of model and data: corr 0.09, 0.80, 0.19 raw; 0.84, 0.85, 0.78 asinh: one
    seed says little, their mean more). The transform is inside the params' function: the session's model, the
    in-jit fit and checkpoints share it."""
    corr = {False: [], True: []}
    for seed in range(3):
        rng = np.random.default_rng(seed)

        def states(n):
            obs = np.zeros((n, OBS), np.float32)
            obs[:, 0] = rng.uniform(5, 50, n)
            left = rng.random(n) < 0.5
            obs[:, 1] = np.where(left, rng.uniform(0.2, 1.0, n), 0.0)
            return obs, np.zeros((n, ACT), np.float32), np.where(left, 0.0, 1.0).astype(np.float32)

        train, test = states(2048), states(1000)
        for asinh in (False, True):
            model = fit_stored(RewardModelConfig(hidden=(32, 32), bounded=True, asinh_obs=asinh), *train[:2],
                               np.ones(2048, np.float32), train[2], 100, seed=seed)
            corr[asinh].append(np.corrcoef(model.predict(*test[:2]), test[2])[0, 1])
            net = RewardMLP((32, 32), True, asinh_obs=asinh)
            np.testing.assert_allclose(model.predict(*test[:2]), net.apply(model.params, *test[:2]), rtol=1e-5,
                                       atol=1e-6)
    raw, asinh = np.mean(corr[False]), np.mean(corr[True])
    assert asinh > 0.75 and asinh > raw + 0.15, corr
