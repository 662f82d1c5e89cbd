"""pilco.constraints: each constraint's violation probability against 2·10⁵ samples of the
same Gaussian (within 3 standard errors), its gradient against finite differences, the
union bound above the truth, the horizon's combination rules and the input checks."""
from __future__ import annotations

import numpy as np
import pytest
import tensorflow as tf

from pilco.constraints import (AngleHalfSpace, Box, HalfSpace, OnMap, constraint_config,
                               constraint_from_config, horizon_risk, normal_tail)

SAMPLES = 200_000


def gaussian(D=3, seed=0, scale=0.3):
    rng = np.random.default_rng(seed)
    m = rng.normal(size=(1, D))
    L = scale * rng.normal(size=(D, D))
    return m, L @ L.T + 0.05 * np.eye(D)


def samples(m, s, seed=1):
    return np.random.default_rng(seed).multivariate_normal(m[0], s, size=SAMPLES)


def within_three_se(p, hits):
    freq = hits.mean()
    se = np.sqrt(max(freq * (1 - freq), 1.0 / SAMPLES) / SAMPLES)
    assert abs(float(p) - freq) <= 3 * se, (float(p), freq, se)


def value(c, m, s):
    return float(c.violation(tf.constant(m), tf.constant(s)))


def test_half_space_is_exact():
    m, s = gaussian()
    x = samples(m, s)
    for a, b in (([1.0, -0.5, 0.2], 0.3), ([0.0, 2.0, 0.0], -1.0), ([1.0, 1.0, 1.0], 2.5)):
        c = HalfSpace(3, a, b)
        within_three_se(value(c, m, s), x @ np.asarray(a) > b)


@pytest.mark.parametrize("combine", ["union", "independent"])
def test_box_per_dimension_exact_and_combined(combine):
    m, s = gaussian(seed=2)
    x = samples(m, s)
    low, high = [-0.5, -np.inf, -1.0], [0.4, 0.2, np.inf]
    box = Box(3, [0, 1, 2], low, high, combine=combine)
    p_dims = box.violations(tf.constant(m), tf.constant(s)).numpy()
    outside = (x < np.asarray(low)) | (x > np.asarray(high))
    for d in range(3):  # each dimension alone: exact
        within_three_se(p_dims[d], outside[:, d])
    truth = outside.any(axis=1).mean()
    p = value(box, m, s)
    if combine == "union":  # a bound: never below the truth
        assert p >= truth - 3 * np.sqrt(truth * (1 - truth) / SAMPLES)
        assert p == pytest.approx(min(1.0, p_dims.sum()))
    else:
        assert p == pytest.approx(1 - np.prod(1 - p_dims))
    # one dimension: both rules are exact
    one = Box(3, [1], [-0.3], [0.3], combine=combine)
    within_three_se(value(one, m, s), (x[:, 1] < -0.3) | (x[:, 1] > 0.3))


def test_independent_rule_is_exact_for_uncorrelated_dimensions():
    m = np.array([[0.1, -0.2, 0.4]])
    s = np.diag([0.04, 0.09, 0.16])
    x = samples(m, s)
    box = Box(3, [0, 2], [-0.2, 0.0], [0.3, 0.6], combine="independent")
    within_three_se(value(box, m, s), ((x[:, 0] < -0.2) | (x[:, 0] > 0.3)
                                       | (x[:, 2] < 0.0) | (x[:, 2] > 0.6)))


def test_a_constraint_on_a_linear_map_is_exact():
    # the distance along the first axis between two points of the state stays below 0.5,
    # and the sum of three states stays in a box
    m, s = gaussian(D=4, seed=3)
    x = samples(m, s)
    A = np.array([[1.0, 0.0, -1.0, 0.0]])
    c = OnMap(4, A, HalfSpace(1, [1.0], 0.5))
    within_three_se(value(c, m, s), x @ A[0] > 0.5)
    A2 = np.array([[1.0, 1.0, 1.0, 0.0], [0.0, 0.0, 0.0, 2.0]])
    c2 = OnMap(4, A2, Box(2, [0], [-1.0], [1.0]), c=[0.1, 0.0])
    y = x @ A2.T + np.array([0.1, 0.0])
    within_three_se(value(c2, m, s), (y[:, 0] < -1.0) | (y[:, 0] > 1.0))


@pytest.mark.parametrize("theta, std, a_sin, a_cos, b", [
    (2.8, 0.2, 0.0, 1.0, -0.97),   # a pendulum's cos θ near its lowest value
    (2.8, 0.5, 0.0, 1.0, -0.9),
    (0.3, 0.3, 0.0, 1.0, 0.9),     # near its highest
    (0.0, 3.0, 1.0, 1.0, 0.5),     # spread over several turns
    (10.0, 1.0, -1.0, 0.3, 0.2),   # a mean turns away from 0
])
def test_a_half_space_on_an_angles_sine_and_cosine_is_exact(theta, std, a_sin, a_cos, b):
    """``a_sin sin θ + a_cos cos θ <= b``: where the Gaussian of the features (sin θ,
    cos θ) would be off by up to 0.16 (cos θ is bounded and skewed near ±1), the sum over
    the turns matches the samples; a known state is certain; it is saved and rebuilt."""
    m = np.array([[0.5, theta]])
    s = np.array([[0.3, 0.05 * std], [0.05 * std, std ** 2]])
    c = AngleHalfSpace(2, 1, a_sin, a_cos, b)
    x = samples(m, s)
    assert np.array_equal(c.breaks(x), a_sin * np.sin(x[:, 1]) + a_cos * np.cos(x[:, 1]) > b)
    within_three_se(value(c, m, s), c.breaks(x))
    again = constraint_from_config(constraint_config(c))
    assert value(again, m, s) == value(c, m, s)
    known = float(c.breaks(m)[0])
    assert value(c, m, np.zeros((2, 2))) == known


def test_an_angle_half_space_that_always_or_never_holds_is_refused():
    for b in (1.0, -1.5):
        with pytest.raises(ValueError, match="always or never holds"):
            AngleHalfSpace(2, 1, 0.0, 1.0, b)
    with pytest.raises(ValueError, match="angle"):
        AngleHalfSpace(2, 2, 0.0, 1.0, 0.5)


@pytest.mark.parametrize("make", [
    lambda: HalfSpace(3, [1.0, -0.5, 0.2], 0.3),
    lambda: AngleHalfSpace(3, 2, 0.6, -0.8, 0.3),
    lambda: Box(3, [0, 2], [-0.5, -1.0], [0.4, np.inf]),
    lambda: Box(3, [0, 1], [-0.5, -0.2], [0.4, 0.3], combine="independent"),
    lambda: OnMap(3, [[1.0, 1.0, 0.0]], HalfSpace(1, [1.0], 0.2)),
])
def test_gradients_match_finite_differences(make):
    c = make()
    m, s = gaussian(seed=4)
    m_t, s_t = tf.Variable(m), tf.Variable(s)
    with tf.GradientTape() as tape:
        p = c.violation(m_t, s_t)
    gm, gs = tape.gradient(p, [m_t, s_t])
    h = 1e-6
    for i in range(3):
        e = np.zeros_like(m)
        e[0, i] = h
        fd = (value(c, m + e, s) - value(c, m - e, s)) / (2 * h)
        assert gm.numpy()[0, i] == pytest.approx(fd, rel=1e-5, abs=1e-9)
    for i, j in ((0, 0), (1, 1), (0, 2)):
        e = np.zeros_like(s)
        e[i, j] = e[j, i] = h  # a symmetric change of s
        fd = (value(c, m, s + e) - value(c, m, s - e)) / (2 * h)
        analytic = gs.numpy()[i, j] + (gs.numpy()[j, i] if i != j else 0.0)
        assert analytic == pytest.approx(fd, rel=1e-5, abs=1e-9)


def test_far_tails_keep_their_precision_and_a_known_state_is_certain():
    # 10 standard deviations out: ~7.6e-24, where 1 - Phi would round to 0
    assert float(normal_tail(tf.constant(10.0, tf.float64))) == pytest.approx(7.6198530e-24,
                                                                              rel=1e-6)
    c = HalfSpace(2, [1.0, 0.0], 0.0)
    assert value(c, np.array([[1.0, 0.0]]), np.zeros((2, 2))) == 1.0
    assert value(c, np.array([[-1.0, 0.0]]), np.zeros((2, 2))) == 0.0


def test_horizon_risk_rules():
    p = np.array([0.1, 0.2, 0.05])
    assert float(horizon_risk(p)) == pytest.approx(1 - 0.9 * 0.8 * 0.95)
    assert float(horizon_risk(p, "union")) == pytest.approx(0.35)
    assert float(horizon_risk(np.full(30, 0.1), "union")) == 1.0  # a bound, capped at 1
    assert float(horizon_risk(p, "union")) >= float(horizon_risk(p))


def test_bad_constraints_are_refused_with_their_reason():
    with pytest.raises(ValueError, match="all zero"):
        HalfSpace(2, [0.0, 0.0], 1.0)
    with pytest.raises(ValueError, match="a must have 2 entries"):
        HalfSpace(2, [1.0], 1.0)
    with pytest.raises(ValueError, match="low must be below high"):
        Box(2, [0], [1.0], [0.5])
    with pytest.raises(ValueError, match="one entry per dimension of dims"):
        Box(2, [0, 1], [0.0], [1.0, 2.0])
    with pytest.raises(ValueError, match="combine must be one of"):
        Box(2, [0], [0.0], [1.0], combine="max")
    with pytest.raises(ValueError, match="must read 1 dimensions"):
        OnMap(3, [[1.0, 0.0, 0.0]], HalfSpace(2, [1.0, 0.0], 0.0))
    with pytest.raises(ValueError, match="combine must be one of"):
        horizon_risk(np.array([0.1]), "sum")


# ------------------------------------------------------- the penalty in the policy objective
def small_agent(reward):
    """A 2-state agent whose first state follows the action: u drives x0 up or down."""
    from pilco.controllers import LinearController
    from pilco.models import PILCO

    rng = np.random.default_rng(0)
    X = rng.uniform(-1.0, 1.0, (30, 3))
    Y = np.stack([0.3 * X[:, 2], -0.1 * X[:, 1]], axis=1)
    controller = LinearController(2, 1, max_action=1.0)
    controller.W.assign([[0.0, 0.0]])
    controller.b.assign([[0.5]])
    return PILCO((X, Y), controller, reward, horizon=5, m_init=np.zeros((1, 2)),
                 S_init=0.01 * np.eye(2))


def test_the_penalty_subtracts_weight_times_each_steps_violation():
    from pilco.constraints import ViolationPenalty, step_violations
    from pilco.rewards import CombinedRewards, ExponentialReward

    task = ExponentialReward(2, t=[[1.0, 0.0]])
    wall = HalfSpace(2, [1.0, 0.0], 0.4)  # x0 must stay at or below 0.4
    penalty = ViolationPenalty(wall, weight=3.0)
    agent = small_agent(CombinedRewards(2, [task, penalty]))
    M, S = agent.predict_trajectory()
    p = step_violations(wall, M, S)
    assert p[0] < 1e-4 and p[-1] > 0.5  # the policy pushes x0 over the wall
    plain = small_agent(task).expected_return()
    assert agent.expected_return() == pytest.approx(plain - 3.0 * p[1:].sum(), rel=1e-10)
    # Safe PILCO's mu changes the objective without a new reward
    penalty.weight.assign(0.0)
    assert agent.expected_return() == pytest.approx(plain, rel=1e-12)
    # the independent form: -mu log(1 - risk) of the independent rule
    log_form = ViolationPenalty(wall, weight=2.0, form="independent")
    agent = small_agent(CombinedRewards(2, [task, log_form]))
    risk = float(horizon_risk(p[1:]))
    assert agent.expected_return() == pytest.approx(plain + 2.0 * np.log(1 - risk), rel=1e-9)


def test_a_policy_search_with_the_penalty_lowers_the_risk():
    from pilco.constraints import ViolationPenalty, step_violations
    from pilco.rewards import CombinedRewards, ExponentialReward

    task = ExponentialReward(2, t=[[1.0, 0.0]])  # the target lies beyond the wall
    wall = HalfSpace(2, [1.0, 0.0], 0.4)
    risks = {}
    for mu in (0.0, 5.0):
        agent = small_agent(CombinedRewards(2, [task, ViolationPenalty(wall, weight=mu)]))
        agent.optimize_policy(maxiter=30, restarts=1)
        M, S = agent.predict_trajectory()
        risks[mu] = float(horizon_risk(step_violations(wall, M, S)[1:]))
    assert risks[0.0] > 0.5 and risks[5.0] < 0.5 * risks[0.0]


def test_the_penalty_and_its_constraint_are_saved_with_the_agent(tmp_path):
    from pilco.constraints import ViolationPenalty
    from pilco.models import PILCO
    from pilco.rewards import CombinedRewards, ExponentialReward

    box = OnMap(2, [[1.0, 1.0]], Box(1, [0], [-np.inf], [0.6], combine="independent"))
    penalty = ViolationPenalty(box, weight=1.0)
    penalty.weight.assign(4.5)  # raised by a safe loop: comes back from the file
    agent = small_agent(CombinedRewards(2, [ExponentialReward(2, t=[[1.0, 0.0]]), penalty]))
    loaded = PILCO.load(agent.save(tmp_path / "agent.npz"))
    back = loaded.reward.base_rewards[1]
    assert type(back) is ViolationPenalty and float(back.weight.numpy()) == 4.5
    assert type(back.constraint.constraint) is Box and back.constraint.constraint.high[0] == 0.6
    assert np.isneginf(back.constraint.constraint.low[0])
    assert loaded.expected_return() == agent.expected_return()


# ------------------------------------------------------------ the safe policy search
def test_the_safe_search_raises_mu_until_the_policy_is_below_the_threshold():
    from pilco.constraints import ViolationPenalty
    from pilco.models.safe import predicted_risk, safe_policy_search
    from pilco.rewards import CombinedRewards, ExponentialReward

    wall = HalfSpace(2, [1.0, 0.0], 0.4)
    penalty = ViolationPenalty(wall, weight=0.01)  # too small to keep the policy back
    agent = small_agent(CombinedRewards(2, [ExponentialReward(2, t=[[1.0, 0.0]]), penalty]))
    result = safe_policy_search(agent, 0.05, attempts=12, raise_by=3.0, maxiter=30)
    assert result.safe and not result.fallback and result.risk <= 0.05
    assert result.risk == pytest.approx(predicted_risk(agent, wall))
    weights = [t["weight"] for t in result.tries]
    assert len(weights) > 1 and all(b == pytest.approx(3.0 * a)
                                    for a, b in zip(weights, weights[1:]))
    assert all(t["risk"] > 0.05 for t in result.tries[:-1])
    record = result.as_record()
    assert record["safe"] is True and len(record["tries"]) == len(weights)


def test_an_unsafe_search_keeps_the_safe_policy_it_started_from_or_says_so():
    from pilco.constraints import ViolationPenalty
    from pilco.models.safe import predicted_risk, safe_policy_search
    from pilco.rewards import CombinedRewards, ExponentialReward

    wall = HalfSpace(2, [1.0, 0.0], 0.4)
    agent = small_agent(CombinedRewards(2, [ExponentialReward(2, t=[[1.0, 0.0]]),
                                            ViolationPenalty(wall, weight=0.0)]))
    agent.controller.b.assign([[0.0]])  # the policy that ran: stays at 0, safe
    before = agent.controller.b.numpy().copy()
    assert predicted_risk(agent, wall) < 0.01
    # mu 0 stays 0 when raised: every search runs over the wall
    result = safe_policy_search(agent, 0.05, attempts=2, maxiter=30)
    assert result.safe and result.fallback and len(result.tries) == 2
    assert all(t["risk"] > 0.05 for t in result.tries)
    np.testing.assert_array_equal(agent.controller.b.numpy(), before)
    # the same from a policy that was over the wall already: nothing safe to keep
    agent.controller.b.assign([[1.0]])
    result = safe_policy_search(agent, 0.05, attempts=1, maxiter=30)
    assert not result.safe and not result.fallback


def test_the_safe_search_checks_its_arguments():
    from pilco.models.safe import safe_policy_search
    from pilco.rewards import ExponentialReward

    agent = small_agent(ExponentialReward(2))
    with pytest.raises(ValueError, match="one ViolationPenalty"):
        safe_policy_search(agent, 0.1)
    with pytest.raises(ValueError, match="below 1"):
        safe_policy_search(agent, 1.5)
    with pytest.raises(ValueError, match="raise_by must be above 1"):
        safe_policy_search(agent, 0.1, raise_by=0.9)
    with pytest.raises(ValueError, match="repair_weight"):
        safe_policy_search(agent, 0.1, repair_weight=-1.0)


@pytest.mark.parametrize("combine", ["bound", "independent"])
def test_a_region_to_stay_out_of(combine):
    from pilco.constraints import Region

    m, s = gaussian(seed=5, scale=0.5)
    x = samples(m, s)
    region = Region(3, [0, 2], [-0.5, -1.0], [1.0, 0.5], combine=combine)
    inside = ((x[:, 0] >= -0.5) & (x[:, 0] <= 1.0) & (x[:, 2] >= -1.0) & (x[:, 2] <= 0.5))
    truth, p = inside.mean(), value(region, m, s)
    if combine == "bound":
        assert p >= truth - 3 * np.sqrt(truth * (1 - truth) / SAMPLES)
    one = Region(3, [1], [-0.2], [0.3], combine=combine)  # one dimension: exact
    within_three_se(value(one, m, s), (x[:, 1] >= -0.2) & (x[:, 1] <= 0.3))
    # uncorrelated dimensions: the product is exact
    m2, s2 = np.array([[0.2, 0.0, -0.3]]), np.diag([0.09, 0.04, 0.25])
    x2 = samples(m2, s2)
    indep = Region(3, [0, 2], [-0.5, -1.0], [1.0, 0.5], combine="independent")
    within_three_se(value(indep, m2, s2), (x2[:, 0] >= -0.5) & (x2[:, 0] <= 1.0)
                    & (x2[:, 2] >= -1.0) & (x2[:, 2] <= 0.5))
    with pytest.raises(ValueError, match="combine must be 'bound' or 'independent'"):
        Region(3, [0], [0.0], [1.0], combine="union")
