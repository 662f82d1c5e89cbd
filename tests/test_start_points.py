"""The policy objective's start points (``PILCO.start_points``): beside each task's start
distribution propagated as one moment-matched Gaussian, known start states (the flanks of
the start distribution, or draws from it) are rolled out through the policy and the
dynamics GPs' mean, and the task's total weighs the two returns.

The pieces are checked against what they stand for: the point predictions against the
moment-matched ones at a zero covariance (and against NumPy), the rollout against a NumPy
rollout of the GP mean, the objective's gradient against finite differences."""
from __future__ import annotations

import numpy as np
import pytest
import tensorflow as tf

from pilco import moments
from pilco.angles import point_features
from pilco.controllers import LinearController, RbfController, squash_sat, squash_sin
from pilco.experiment import ExperimentConfig
from pilco.features import angle_features
from pilco.models.starts import flank_points, start_mixture, start_samples
from test_gradients import check_against_differences
from test_multitask import D, M0, S0, TASKS_M, TASKS_S, agent, target_reward


def _gp(seed, E=3, n=12, inputs=4):
    rng = np.random.default_rng(seed)
    X = tf.constant(rng.standard_normal((n, inputs)))
    Y = tf.constant(rng.standard_normal((n, E)))
    ell = tf.constant(rng.uniform(0.5, 2.0, (E, inputs)))
    sf2 = tf.constant(rng.uniform(0.5, 2.0, E))
    sn2 = tf.constant(np.full(E, 1e-2))
    return moments.factorize(X, Y, ell, sf2, sn2)


@pytest.mark.parametrize("deterministic", [False, True], ids=["dynamics", "policy"])
def test_point_means_are_the_moment_matched_means_at_zero_covariance(deterministic):
    fact = _gp(0)
    pred = moments.prepare(fact, constant=True, deterministic=deterministic)
    x = np.random.default_rng(1).standard_normal((5, 4))
    got = moments.point_means(tf.constant(x), pred).numpy()
    assert got.shape == (5, 3)
    for i in range(5):
        M, _, _ = moments.predict(tf.constant(x[i:i + 1]), tf.zeros([4, 4], tf.float64), pred)
        np.testing.assert_allclose(got[i], M.numpy()[0], rtol=1e-12, atol=1e-14)
    # and against the kernel written out in NumPy
    X, beta = fact.centers.numpy(), fact.beta.numpy()
    ell, sf2 = fact.lengthscales.numpy(), fact.variance.numpy()
    for e in range(3):
        k = sf2[e] * np.exp(-0.5 * np.sum(((x[:, None, :] - X[None]) / ell[e]) ** 2, -1))
        np.testing.assert_allclose(got[:, e], k @ beta[e], rtol=1e-12)


@pytest.mark.parametrize("angles", [(), (1,), (0, 2)])
def test_point_features_are_the_angle_features(angles):
    x = np.random.default_rng(2).uniform(-4, 4, (6, 3))
    np.testing.assert_allclose(point_features(tf.constant(x), angles).numpy(),
                               angle_features(x, angles), rtol=0, atol=1e-15)


def _custom_squash(m, s, max_action=None):
    """A squash the point form does not know: ``2 tanh``-like via its moments at 0 variance."""
    return 2.0 * tf.tanh(m), tf.zeros_like(s), tf.ones_like(s)


@pytest.mark.parametrize("squash", [squash_sin, squash_sat, None, _custom_squash],
                         ids=["sin", "sat", "none", "custom"])
@pytest.mark.parametrize("kind", ["rbf", "linear"])
def test_point_actions_are_the_action_means_at_zero_covariance(kind, squash):
    rng = np.random.default_rng(3)
    F, U = 3, 2
    if kind == "rbf":
        ctrl = RbfController(F, U, 6, max_action=[1.5, 0.7], squash=squash, seed=4)
    else:
        ctrl = LinearController(F, U, max_action=[1.5, 0.7], squash=squash, seed=4)
        ctrl.W.assign(rng.uniform(-2, 2, (U, F)))
    x = rng.standard_normal((4, F))
    got = ctrl.point_actions(tf.constant(x)).numpy()
    assert got.shape == (4, U)
    for i in range(4):
        # the unsquashed mean at zero covariance, squashed as a known action (the RBF
        # policy's moments add a 1e-6 jitter to the unsquashed variance, which the
        # squash's moments would damp the mean by)
        M, _, _ = ctrl.moments(tf.constant(x[i:i + 1]), tf.zeros([F, F], tf.float64),
                               squash=False)
        if squash is not None:
            M = squash(M, tf.zeros([U, U], tf.float64), ctrl.max_action)[0]
        np.testing.assert_allclose(got[i], M.numpy()[0], rtol=1e-12, atol=1e-14)


def _numpy_point_return(p, start, horizon):
    """The return of one known start under the policy and the GP mean, in NumPy (the
    toy agent: angle 1, context (2, 3), a policy reading every feature)."""
    fact = p.mgpr.factorize()
    X, beta = fact.centers.numpy(), fact.beta.numpy()
    ell, sf2 = fact.lengthscales.numpy(), fact.variance.numpy()
    x, total = np.array(start, dtype=float), 0.0
    zero = np.zeros((D, D))
    for _ in range(horizon):
        z = angle_features(x[None], p.angle_indices)  # [1, F]
        u = p.controller.point_actions(tf.constant(z)).numpy()  # checked above
        inp = np.concatenate([z[:, [0, 3, 4]], u], axis=1)[0]  # [p, sin θ, cos θ, u]
        delta = [sf2[e] * np.exp(-0.5 * np.sum(((inp - X) / ell[e]) ** 2, -1)) @ beta[e]
                 for e in range(2)]
        x = x + np.array([delta[0], delta[1], 0.0, 0.0])  # the context stays
        total += float(p.reward.moments(tf.constant(x[None]), tf.constant(zero))[0][0, 0])
    return total


def _points(m, S, spread=1.5, samples=3, seed=0):
    return np.concatenate([flank_points(m, S, spread), start_samples(m, S, samples, seed)])


def test_points_objective_weighs_the_gaussian_and_its_points():
    p = agent("rbf", (1,), reward=target_reward(), m_init=TASKS_M, S_init=TASKS_S)
    plain = p.expected_returns()
    points = np.stack([_points(TASKS_M[i], TASKS_S[i], seed=i) for i in range(len(TASKS_M))])
    p.start_points = points
    np.testing.assert_array_equal(p.start_points, points)
    weighed = p.expected_returns()
    for i in range(len(TASKS_M)):
        point_mean = np.mean([_numpy_point_return(p, x, p.horizon) for x in points[i]])
        assert weighed[i] == pytest.approx(
            0.5 * plain[i] + 0.5 * point_mean, rel=1e-10)
    assert not np.allclose(weighed, plain)
    p.start_points = None
    assert p.start_points is None
    np.testing.assert_array_equal(p.expected_returns(), plain)


def test_flank_points_are_the_mixture_means_and_samples_the_start_distribution():
    for i in range(len(TASKS_M)):
        np.testing.assert_array_equal(flank_points(TASKS_M[i], TASKS_S[i], 1.5),
                                      start_mixture(TASKS_M[i], TASKS_S[i], 1.5)[0][1:])
    draws = start_samples(M0[0], S0, 20000, seed=5)
    assert draws.shape == (20000, D)
    np.testing.assert_allclose(draws.mean(axis=0), M0[0], atol=0.01)
    np.testing.assert_allclose(np.cov(draws.T), S0, atol=0.005)
    np.testing.assert_array_equal(start_samples(M0[0], S0, 4, seed=5), draws[:4])


def test_a_new_number_of_points_retraces_and_a_mixture_overrides_them():
    p = agent("rbf", (1,), reward=target_reward())
    p.start_points = _points(M0[0], S0, samples=2)
    first = p.expected_return()
    more = _points(M0[0], S0, samples=5)
    p.start_points = more  # 13 points where the trace had 10
    q = agent("rbf", (1,), reward=target_reward())
    q.controller = p.controller
    q.start_points = more
    assert p.expected_return() == pytest.approx(q.expected_return(), rel=1e-12)
    assert p.expected_return() != first
    p.optimize_policy(maxiter=1)  # the optimiser's compiled objective has 13 points too
    assert p.expected_return() == pytest.approx(-float(p._rollout.policy_loss()), rel=1e-12)
    p.start_spread = 1.0  # the mixture's objective, whatever the points
    q.controller = p.controller
    q.start_points = None
    q.start_spread = 1.0
    assert p.expected_return() == pytest.approx(q.expected_return(), rel=1e-12)


def test_points_objective_gradient_matches_differences():
    p = agent("rbf", (1,), reward=target_reward())
    p.start_points = _points(M0[0], S0, spread=2.0)
    p.expected_return()  # refresh the model's factorisation
    variables = p.controller.trainable_variables
    with tf.GradientTape() as tape:
        loss = p._rollout.policy_loss()
    check_against_differences(p, variables, tape.gradient(loss, variables))


def test_policy_search_with_start_points_improves_their_objective():
    p = agent("rbf", (1,), reward=target_reward())
    p.start_points = _points(M0[0], S0)
    before = p.expected_return()
    best = p.optimize_policy(maxiter=3)
    assert best > before
    assert p.expected_return() == pytest.approx(best, rel=1e-9)
    assert p.start_points is not None


@pytest.mark.parametrize("points, scale", [(True, None), (False, 2.0), (True, 1.5)],
                         ids=["points", "wide", "both"])
def test_xla_points_objective_agrees_with_the_graph(points, scale):
    p = agent("rbf", (1,), reward=target_reward())
    p.start_points = _points(M0[0], S0) if points else None
    p.start_scale = scale
    graph = p.expected_return()
    xla = tf.function(p._rollout.xla_points_policy_loss, jit_compile=True, autograph=False)
    assert -float(xla().numpy()) == pytest.approx(graph, rel=1e-10)


@pytest.mark.parametrize("bad,error,match", [
    (np.zeros((3, D + 1)), ValueError, r"shape \(P, 4\)"),
    (np.zeros((2, 3, D)), ValueError, "shape"),
    (np.full((3, D), np.nan), ValueError, "finite"),
    ("wide", TypeError, "array of numbers"),
])
def test_bad_start_points_are_refused_before_tensorflow(bad, error, match):
    p = agent()
    with pytest.raises(error, match=match):
        p.start_points = bad
    assert p.start_points is None
    multi = agent(m_init=TASKS_M, S_init=TASKS_S)
    with pytest.raises(ValueError, match=r"\(3, P, 4\) \(one set per task\)"):
        multi.start_points = np.zeros((5, D))


def test_config_switches_the_start_points_on_once_solved():
    cfg = ExperimentConfig(task="t", env_id="e", policy_flank_points=2.0,
                           policy_start_samples=16)
    assert cfg.start_points_at(False) is None and cfg.start_points_at(True) == (2.0, 16, None)
    always = ExperimentConfig(task="t", env_id="e", policy_start_samples=8,
                              policy_start_points_when="always")
    assert always.start_points_at(False) == (None, 8, None)
    assert ExperimentConfig(task="t", env_id="e", policy_flank_points=0).start_points_at(
        True) is None
    with pytest.raises(ValueError, match="policy_start_points_when"):
        ExperimentConfig(task="t", env_id="e", policy_start_points_when="fragile")
    with pytest.raises(ValueError, match="policy_flank_points"):
        ExperimentConfig(task="t", env_id="e", policy_flank_points=-1.0)
    assert ExperimentConfig(task="t", env_id="e", policy_start_scale=2.0).start_points_at(
        True) == (None, 0, 2.0)
    with pytest.raises(ValueError, match="policy_start_scale"):
        ExperimentConfig(task="t", env_id="e", policy_start_scale=-1.0)
    with pytest.raises(ValueError, match="policy_start_samples"):
        ExperimentConfig(task="t", env_id="e", policy_start_samples=-2)


def test_wide_start_is_averaged_with_the_start_distribution():
    """``start_scale = k``: each task's total is the mean of the expected returns from
    N(m, S) and N(m, k² S); with start points as well, the mean of the three."""
    p = agent("rbf", (1,), reward=target_reward(), m_init=TASKS_M, S_init=TASKS_S)
    plain = p.expected_returns()
    q = agent("rbf", (1,), reward=target_reward(), m_init=TASKS_M, S_init=4.0 * TASKS_S)
    q.controller = p.controller
    wide = q.expected_returns()
    p.start_scale = 2.0
    assert p.start_scale == 2.0
    np.testing.assert_allclose(p.expected_returns(), 0.5 * (plain + wide), rtol=1e-12)
    points = np.stack([_points(TASKS_M[i], TASKS_S[i], seed=i) for i in range(len(TASKS_M))])
    p.start_points = points
    p.start_scale = None
    with_points = p.expected_returns()  # the mean of plain and points
    p.start_scale = 2.0
    np.testing.assert_allclose(p.expected_returns(), (2 * with_points + wide) / 3, rtol=1e-12)
    p.start_points = None
    p.start_scale = 0
    assert p.start_scale is None
    np.testing.assert_array_equal(p.expected_returns(), plain)
    # the search, on the first task alone: the optimiser's compiled objective builds the
    # gradient of each Gaussian it propagates (two per task), which three tasks triple
    p.set_initial(TASKS_M[:1], TASKS_S[0])
    p.start_scale = 2.0
    before = p.expected_return()
    best = p.optimize_policy(maxiter=2)  # searched on the mean of the two
    assert best > before and p.expected_return() == pytest.approx(best, rel=1e-9)
    with pytest.raises(ValueError, match="start scale"):
        p.start_scale = -1.0
    with pytest.raises(TypeError, match="start scale"):
        p.start_scale = "wide"


def test_a_controller_without_point_actions_is_asked_row_by_row():
    """A controller that follows the protocol without ``point_actions`` (its ``moments``
    only) gives the same objective with start points."""
    p = agent("linear", (1,), reward=target_reward())
    p.start_points = _points(M0[0], S0)
    expected = p.expected_return()

    class MomentsOnly:
        def __init__(self, inner):
            self._inner = inner
            self.state_dim, self.control_dim = inner.state_dim, inner.control_dim
            self.trainable_variables = inner.trainable_variables

        def prepare(self):
            return None

        def moments(self, m, s, squash=True, prepared=None):
            return self._inner.moments(m, s, squash)

    p._rollout.controller = MomentsOnly(p.controller)
    assert not hasattr(p._rollout.controller, "point_actions")
    assert p.expected_return() == pytest.approx(expected, rel=1e-12)
