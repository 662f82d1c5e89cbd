"""The policy objective's start mixture (``PILCO.start_spread``): each start distribution
split into 2D + 1 narrower Gaussians of the same mean and covariance, propagated one by
one, the task's expected return their mean; and how a run switches it on."""
from __future__ import annotations

import numpy as np
import pytest

from pilco.experiment import ExperimentConfig
from pilco.models.starts import start_mixture
from test_gradients import check_against_differences
from test_multitask import D, M0, S0, TASKS_M, TASKS_S, agent, loss_and_grad, target_reward


@pytest.mark.parametrize("spread", [0.5, 1.5, 2.1])
def test_mixture_has_the_mean_and_covariance_of_the_start(spread):
    rng = np.random.default_rng(3)
    A = rng.standard_normal((D, D))
    S = 0.05 * A @ A.T + 0.01 * np.eye(D)
    m = rng.standard_normal(D)
    means, cov = start_mixture(m, S, spread)
    assert means.shape == (2 * D + 1, D) and cov.shape == (D, D)
    np.testing.assert_allclose(means.mean(axis=0), m, rtol=0, atol=1e-14)
    mixture_cov = cov + np.cov(means.T, bias=True)  # equal weights
    np.testing.assert_allclose(mixture_cov, S, rtol=0, atol=1e-14)
    # the flank components lie `spread` standard deviations out (Mahalanobis distance)
    iS = np.linalg.inv(S)
    d = [np.sqrt((x - m) @ iS @ (x - m)) for x in means[1:]]
    np.testing.assert_allclose(d, spread, rtol=1e-10)
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_mixture_of_a_degenerate_start_keeps_its_fixed_dimensions():
    S = np.diag([0.04, 0.0, 0.01, 0.0])  # two dimensions known exactly
    means, cov = start_mixture(np.zeros(D), S, 1.5)
    assert np.all(means[:, 1] == 0) and np.all(means[:, 3] == 0)
    assert cov[1, 1] == 0 and cov[3, 3] == 0


@pytest.mark.parametrize("bad", [-1.0, np.sqrt(D + 0.5), 10.0])
def test_spread_out_of_range_is_refused_before_tensorflow(bad):
    p = agent()
    with pytest.raises(ValueError, match="spread"):
        p.start_spread = bad
    with pytest.raises(TypeError, match="spread"):
        p.start_spread = "wide"
    assert p.start_spread is None


@pytest.mark.parametrize("kind,angles", [("rbf", (1,)), ("linear", ())],
                         ids=["rbf-angle", "linear"])
def test_objective_is_the_mean_over_the_components(kind, angles):
    """Each task's return under the mixture is the mean of the plain returns from its 2D+1
    components, each a start distribution of its own; switched off, the plain objective
    comes back exactly."""
    p = agent(kind, angles, reward=target_reward(), m_init=TASKS_M, S_init=TASKS_S)
    plain = p.expected_returns()
    loss_plain, grad_plain = loss_and_grad(p)
    p.start_spread = 1.5
    mixed = p.expected_returns()
    loss, grad = loss_and_grad(p)
    expected, grads = [], []
    parts = [start_mixture(TASKS_M[i], TASKS_S[i], 1.5) for i in range(len(TASKS_M))]
    # one agent serves every task's components in turn: its starts are replaced by the
    # next task's (the same number of starts, so its compiled objective is traced once)
    q = agent(kind, angles, reward=target_reward(), m_init=parts[0][0], S_init=parts[0][1])
    q.controller = p.controller
    for means, cov in parts:
        q.set_initial(means, cov)
        expected.append(q.expected_returns().mean())
        q.expected_return()
        grads.append(loss_and_grad(q)[1] / len(means))
    np.testing.assert_allclose(mixed, expected, rtol=0, atol=1e-10)
    np.testing.assert_allclose(grad, np.sum(grads, axis=0), rtol=0, atol=1e-10)
    assert not np.allclose(mixed, plain)  # the flanks are seen
    assert p.expected_return() == pytest.approx(-loss, abs=1e-12)
    p.start_spread = None
    np.testing.assert_array_equal(p.expected_returns(), plain)
    loss_again, grad_again = loss_and_grad(p)
    assert loss_again == loss_plain
    # the same gradient; eager gradients may sum their parts in another order (last bit)
    np.testing.assert_allclose(grad_again, grad_plain, rtol=0, atol=1e-13)


def test_mixture_follows_new_starts_and_its_gradient_matches_differences():
    p = agent("rbf", (1,), reward=target_reward())
    p.start_spread = 1.0
    before = p.expected_return()
    p.m_init = M0 + 0.1
    means, cov = start_mixture(M0[0] + 0.1, S0, 1.0)
    q = agent("rbf", (1,), reward=target_reward(), m_init=means, S_init=cov)
    q.controller = p.controller
    assert p.expected_return() == pytest.approx(q.expected_returns().mean(), abs=1e-10)
    assert p.expected_return() != before
    p.expected_return()
    import tensorflow as tf
    variables = p.controller.trainable_variables
    with tf.GradientTape() as tape:
        loss = p._rollout.policy_loss()
    check_against_differences(p, variables, tape.gradient(loss, variables))


def test_policy_search_on_the_mixture_improves_it():
    p = agent("rbf", (1,), reward=target_reward())
    p.start_spread = 1.5
    before = p.expected_return()
    best = p.optimize_policy(maxiter=3)
    assert best > before
    assert p.expected_return() == pytest.approx(best, rel=1e-9)


def test_config_switches_the_mixture_on_once_solved():
    cfg = ExperimentConfig(task="t", env_id="e", policy_start_mixture=1.5)
    assert cfg.start_mixture_at(False) is None and cfg.start_mixture_at(True) == 1.5
    always = ExperimentConfig(task="t", env_id="e", policy_start_mixture=1.5,
                              policy_start_mixture_when="always")
    assert always.start_mixture_at(False) == 1.5
    assert ExperimentConfig(task="t", env_id="e", policy_start_mixture=0).start_mixture_at(
        True) is None
    with pytest.raises(ValueError, match="policy_start_mixture_when"):
        ExperimentConfig(task="t", env_id="e", policy_start_mixture_when="never")
    with pytest.raises(ValueError, match="policy_start_mixture"):
        ExperimentConfig(task="t", env_id="e", policy_start_mixture=-1.0)
