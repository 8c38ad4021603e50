"""Deep COACH: trace coefficients, importance ratio, and learning a small problem from corrective feedback."""

import jax
import jax.numpy as jnp
import numpy as np

from mjx_protamer.agents.coach import CoachConfig, CoachLearner
from mjx_protamer.agents.coach.losses import coach_loss, trace_coefficients
from mjx_protamer.agents.coach.networks import GaussianPolicy


def test_trace_coefficients_hand_computed():
    np.testing.assert_allclose(trace_coefficients(4, 0.35), [0.35**3, 0.35**2, 0.35, 1.0], rtol=1e-6)


def test_positive_feedback_moves_the_mean_towards_the_taken_action_negative_away():
    policy = GaussianPolicy(1, (8,))
    params = policy.init(jax.random.PRNGKey(0), jnp.zeros((1, 1)))
    obs = jnp.zeros((1, 1, 1))
    mean0 = float(policy.apply(params, obs)[0][0, 0, 0])
    action = jnp.full((1, 1, 1), mean0 + 0.5)
    logp_old = jnp.zeros((1, 1))
    for f, sign in ((1.0, 1), (-1.0, -1)):
        g = jax.grad(lambda p: coach_loss(p, policy.apply, obs, action, logp_old, jnp.ones((1, 1)),
                                          jnp.array([f]), 0.35, 0.0)[0])(params)
        stepped = jax.tree.map(lambda p, d: p - 1e-2 * d, params, g)
        assert np.sign(float(policy.apply(stepped, obs)[0][0, 0, 0]) - mean0) == sign


def test_importance_ratio_scales_old_windows():
    policy = GaussianPolicy(1, (8,))
    params = policy.init(jax.random.PRNGKey(0), jnp.zeros((1, 1)))
    obs, action, mask, fb = jnp.zeros((1, 1, 1)), jnp.full((1, 1, 1), 0.3), jnp.ones((1, 1)), jnp.ones(1)
    mean, log_std = policy.apply(params, obs)
    from mjx_protamer.agents.coach.networks import log_prob
    lp = log_prob(mean, log_std, action)
    grad = lambda old: jax.grad(lambda p: coach_loss(p, policy.apply, obs, action, old, mask, fb, 0.35, 0.0)[0])(params)
    g_same, g_old = grad(lp), grad(lp + jnp.log(2.0))  # the old policy liked this action twice as much
    np.testing.assert_allclose(jax.tree.leaves(g_old)[0], 0.5 * jax.tree.leaves(g_same)[0], rtol=1e-5)


def target(obs):
    return np.stack([0.6 * obs[:, 0], np.full(len(obs), -0.5)], axis=1)


def test_improves_a_policy_from_corrective_feedback_alone():
    """Contextual task: s ~ U[-1, 1]^2, the teacher wants a = (0.6 s0, -0.5). It sees no reward, only
    the actions: every second step it says +1 when the previous action was closer to its wish than the
    running average, else -1 (a human delay of one step). Nothing else trains the policy."""
    learner = CoachLearner(CoachConfig(), obs_size=2, action_size=2, seed=0)
    rng = np.random.default_rng(0)
    test_obs = rng.uniform(-1, 1, (500, 2)).astype(np.float32)
    err = lambda: float(np.mean(np.linalg.norm(learner.mean_action(test_obs) - target(test_obs), axis=1)))
    before = err()
    baseline, prev_err = None, None
    for step in range(4000):
        obs = rng.uniform(-1, 1, (1, 2)).astype(np.float32)
        action, logp = learner.act(obs)
        learner.record(step, obs, action, logp)
        e = float(np.linalg.norm(np.clip(action, -1, 1) - target(obs)))
        baseline = e if baseline is None else 0.95 * baseline + 0.05 * e
        if step % 2 == 1:  # judges step - 1 ... the delay is one step
            learner.feedback(1.0 if prev_err < baseline else -1.0, step)
        prev_err = e
    after = err()
    print(f"COACH mean action error: {before:.3f} -> {after:.3f} ({learner.updates} updates)")
    assert after < 0.5 * before
