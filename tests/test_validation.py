"""Bad input is reported at the public API boundary with a clear message, and numerical
failures during training are recovered from."""
import logging

import numpy as np
import pytest
import tensorflow as tf

from pilco.controllers import LinearController, RbfController
from pilco.models import MGPR, PILCO, SMGPR
from pilco.rewards import CartPoleReward, CombinedRewards, ExponentialReward, LinearReward

D, U, N = 2, 1, 12
RNG = np.random.default_rng(0)
X = RNG.standard_normal((N, D + U))
Y = 0.1 * RNG.standard_normal((N, D))
M0 = np.zeros((1, D))
S0 = 0.1 * np.eye(D)


def with_value(a, index, value):
    a = np.array(a, dtype=float)
    a[index] = value
    return a


def rbf(state_dim=D, **kw):
    return RbfController(state_dim, U, 4, **kw)


def make_agent(**kw):
    args = dict(data=(X, Y), controller=rbf(), reward=ExponentialReward(D), horizon=3)
    args.update(kw)
    return PILCO(**args)


@pytest.fixture(scope="module")
def agent():
    return make_agent()


@pytest.fixture(scope="module")
def gp():
    return MGPR((X, Y))


CHOLESKY_ERROR = tf.errors.InvalidArgumentError(
    None, None, "Cholesky decomposition was not successful")
NOT_SYMMETRIC = np.array([[1.0, 0.5], [0.0, 1.0]])
NOT_PSD = np.array([[1.0, 2.0], [2.0, 1.0]])

# (id, call, exception, message pattern). Calls that need an object take it as argument.
CONSTRUCTION = [
    # -- MGPR / SMGPR ---------------------------------------------------------------------
    ("mgpr-nan-X", lambda: MGPR((with_value(X, (3, 1), np.nan), Y)), ValueError,
     r"data X contains NaN .*index \(3, 1\)"),
    ("mgpr-inf-Y", lambda: MGPR((X, with_value(Y, (0, 0), np.inf))), ValueError,
     "data Y contains inf"),
    ("mgpr-rows-differ", lambda: MGPR((X, Y[:-1])), ValueError,
     "same number of rows, got 12 and 11"),
    ("mgpr-1d-X", lambda: MGPR((X[:, 0], Y)), ValueError, "data X must be 2-D .*reshape"),
    ("mgpr-empty", lambda: MGPR((np.zeros((0, 3)), np.zeros((0, 2)))), ValueError,
     r"data X is empty \(shape \(0, 3\)\)"),
    ("mgpr-not-a-pair", lambda: MGPR(X), TypeError, r"data must be a pair \(X, Y\)"),
    ("mgpr-strings", lambda: MGPR((X.astype(str), Y)), TypeError,
     "data X must be an array of .*numbers, got strings"),
    ("mgpr-booleans", lambda: MGPR((X > 0, Y)), TypeError,
     "data X must be an array of .*numbers, got booleans"),
    ("mgpr-noise-floor-zero", lambda: MGPR((X, Y), noise_floor=0.0), ValueError,
     "noise_floor must be a positive"),
    ("mgpr-noise-floor-nan", lambda: MGPR((X, Y), noise_floor=np.nan), ValueError,
     "noise_floor must be a positive"),
    ("mgpr-noise-floor-string", lambda: MGPR((X, Y), noise_floor="1e-6"), TypeError,
     "noise_floor must be a positive number"),
    ("mgpr-noise-floor-bool", lambda: MGPR((X, Y), noise_floor=True), TypeError,
     "noise_floor must be a positive number"),
    ("smgpr-zero-points", lambda: SMGPR((X, Y), 0), ValueError,
     "num_induced_points must be a positive integer, got 0"),
    ("smgpr-negative-points", lambda: SMGPR((X, Y), -3), ValueError,
     "num_induced_points must be a positive integer"),
    ("smgpr-fractional-points", lambda: SMGPR((X, Y), 2.5), TypeError,
     "num_induced_points must be a positive integer"),
    ("smgpr-bool-points", lambda: SMGPR((X, Y), True), TypeError,
     "num_induced_points must be a positive integer"),
    ("smgpr-string-points", lambda: SMGPR((X, Y), "5"), TypeError,
     "num_induced_points must be a positive integer"),
    ("smgpr-nan-data", lambda: SMGPR((with_value(X, (0, 0), np.nan), Y), 5), ValueError,
     "data X contains NaN"),
    # -- controllers ---------------------------------------------------------------------
    ("rbf-zero-state-dim", lambda: RbfController(0, 1, 4), ValueError,
     "state_dim must be a positive integer, got 0"),
    ("rbf-string-control-dim", lambda: RbfController(2, "1", 4), TypeError,
     "control_dim must be a positive integer"),
    ("rbf-zero-basis", lambda: RbfController(2, 1, 0), ValueError,
     "num_basis_functions must be a positive integer, got 0"),
    ("rbf-bool-basis", lambda: RbfController(2, 1, True), TypeError,
     "num_basis_functions must be a positive integer"),
    ("rbf-negative-max-action", lambda: RbfController(2, 1, 4, max_action=-1.0), ValueError,
     "max_action must be non-negative"),
    ("rbf-nan-max-action", lambda: RbfController(2, 1, 4, max_action=np.nan), ValueError,
     "max_action contains NaN"),
    ("rbf-max-action-size", lambda: RbfController(2, 2, 4, max_action=[1.0, 2.0, 3.0]),
     ValueError, "max_action must be a scalar or have 2 entries, got 3"),
    ("rbf-bool-max-action", lambda: RbfController(2, 1, 4, max_action=True), TypeError,
     "max_action must be an array of .*numbers, got booleans"),
    ("rbf-squash-string", lambda: RbfController(2, 1, 4, squash="sin"), TypeError,
     "squash must be a function"),
    ("rbf-place-near-mean-size", lambda: RbfController(2, 1, 4).place_near([0.0] * 3, 0.1),
     ValueError, r"mean must have shape \(1, 2\), got \(1, 3\)"),
    ("rbf-place-near-negative-std", lambda: RbfController(2, 1, 4).place_near([0, 0], -1.0),
     ValueError, "std must be a finite number >= 0, got -1.0"),
    ("rbf-place-near-string-std", lambda: RbfController(2, 1, 4).place_near([0, 0], "0.1"),
     TypeError, "std must be a number >= 0"),
    ("rbf-place-near-features", lambda: RbfController(2, 1, 4).place_near([0], 0.1, features=3),
     TypeError, "features must be callable, got int"),
    ("rbf-place-near-feature-shape",
     lambda: RbfController(2, 1, 4).place_near([0.0], 0.1, features=lambda x: x), ValueError,
     r"centers must have shape \(4, 2\), got \(4, 1\)"),
    ("linear-zero-control-dim", lambda: LinearController(2, 0), ValueError,
     "control_dim must be a positive integer, got 0"),
    ("linear-squash-string", lambda: LinearController(2, 1, squash="sat"), TypeError,
     "squash must be a function"),
    ("linear-string-max-action", lambda: LinearController(2, 1, max_action="1"), TypeError,
     "max_action must be an array of numbers"),
    # -- rewards ------------------------------------------------------------------------
    ("exp-W-shape", lambda: ExponentialReward(2, W=np.eye(3)), ValueError,
     r"W must have shape \(2, 2\), got \(3, 3\)"),
    ("exp-W-not-symmetric", lambda: ExponentialReward(2, W=NOT_SYMMETRIC), ValueError,
     "W must be symmetric"),
    ("exp-W-not-psd", lambda: ExponentialReward(2, W=NOT_PSD), ValueError,
     "W must be positive semi-definite"),
    ("exp-W-nan", lambda: ExponentialReward(2, W=with_value(np.eye(2), (0, 0), np.nan)),
     ValueError, "W contains NaN"),
    ("exp-t-size", lambda: ExponentialReward(2, t=[1.0, 2.0, 3.0]), ValueError,
     r"t \(the target\) must have 2 entries, got 3"),
    ("exp-t-inf", lambda: ExponentialReward(2, t=[1.0, np.inf]), ValueError, "t contains inf"),
    ("exp-t-string", lambda: ExponentialReward(2, t="origin"), TypeError,
     "t must be an array of numbers"),
    ("exp-state-dim-bool", lambda: ExponentialReward(True), TypeError,
     "state_dim must be a positive integer"),
    ("linear-reward-W-size", lambda: LinearReward(2, W=[1.0, 2.0, 3.0]), ValueError,
     "W must have 2 entries, got 3"),
    ("linear-reward-W-nan", lambda: LinearReward(2, W=[1.0, np.nan]), ValueError,
     "W contains NaN"),
    ("combined-empty", lambda: CombinedRewards(2, []), ValueError, "rewards must not be empty"),
    ("combined-dims-differ", lambda: CombinedRewards(2, [ExponentialReward(3)]), ValueError,
     "every reward must have state_dim 2, got 3"),
    ("combined-not-a-reward", lambda: CombinedRewards(2, ["exp"]), TypeError,
     r"rewards\[0\] must be a reward"),
    ("combined-coefs-size", lambda: CombinedRewards(2, [ExponentialReward(2)], coefs=[1.0, 2.0]),
     ValueError, "coefs must have 1 entries, got 2"),
    ("combined-coefs-nan", lambda: CombinedRewards(2, [ExponentialReward(2)], coefs=[np.nan]),
     ValueError, "coefs contains NaN"),
    ("cartpole-zero-width", lambda: CartPoleReward(width=0.0), ValueError,
     "width must be a positive"),
    ("cartpole-nan-length", lambda: CartPoleReward(pendulum_length=np.nan), ValueError,
     "pendulum_length must be a positive"),
    ("cartpole-string-width", lambda: CartPoleReward(width="0.25"), TypeError,
     "width must be a positive number"),
    ("cartpole-bool-length", lambda: CartPoleReward(pendulum_length=True), TypeError,
     "pendulum_length must be a positive number"),
    # -- PILCO ----------------------------------------------------------------------------
    ("pilco-nan-data", lambda: make_agent(data=(with_value(X, (2, 2), np.nan), Y)), ValueError,
     "data X contains NaN"),
    ("pilco-rows-differ", lambda: make_agent(data=(X[:5], Y)), ValueError,
     "same number of rows, got 5 and 12"),
    ("pilco-1d-Y", lambda: make_agent(data=(X, Y[:, 0])), ValueError, "data Y must be 2-D"),
    ("pilco-empty", lambda: make_agent(data=(X[:0], Y[:0])), ValueError, "data X is empty"),
    ("pilco-no-action-columns", lambda: make_agent(data=(X[:, :D], Y)), ValueError,
     "at least one action column"),
    ("pilco-controller-state-dim", lambda: make_agent(controller=rbf(3)), ValueError,
     "controller.state_dim is 3 but the policy input has dimension 2"),
    ("pilco-controller-angles", lambda: make_agent(angle_indices=[1]), ValueError,
     r"controller.state_dim is 2 but the policy input has dimension 3 .*angle"),
    ("pilco-control-dim", lambda: make_agent(controller=RbfController(D, 2, 4)), ValueError,
     "controller.control_dim is 2 but the data has 1 action columns"),
    ("pilco-reward-state-dim", lambda: make_agent(reward=ExponentialReward(3)), ValueError,
     "reward.state_dim is 3 but the state has dimension 2"),
    ("pilco-controller-none", lambda: make_agent(controller=None), TypeError,
     "controller must have a state_dim attribute"),
    ("pilco-angle-out-of-range", lambda: make_agent(angle_indices=[2], controller=rbf(3)),
     ValueError, r"angle_indices: index 2 is outside the state \(dimension 2\)"),
    ("pilco-angle-negative", lambda: make_agent(angle_indices=[-1], controller=rbf(3)),
     ValueError, "angle_indices: index -1 is outside the state"),
    ("pilco-angle-duplicates", lambda: make_agent(angle_indices=[1, 1], controller=rbf(4)),
     ValueError, "angle_indices has duplicates"),
    ("pilco-angle-float", lambda: make_agent(angle_indices=[1.5], controller=rbf(3)), TypeError,
     "angle_indices must hold integers, got 1.5"),
    ("pilco-angle-bool", lambda: make_agent(angle_indices=[True], controller=rbf(3)), TypeError,
     "angle_indices must hold integers, got True"),
    ("pilco-angle-scalar", lambda: make_agent(angle_indices=1, controller=rbf(3)), TypeError,
     "angle_indices must be a sequence of integers"),
    ("pilco-angle-string", lambda: make_agent(angle_indices="1", controller=rbf(3)), TypeError,
     "angle_indices must be a sequence of integers"),
    ("pilco-horizon-zero", lambda: make_agent(horizon=0), ValueError,
     "horizon must be a positive integer, got 0"),
    ("pilco-horizon-negative", lambda: make_agent(horizon=-5), ValueError,
     "horizon must be a positive integer, got -5"),
    ("pilco-horizon-fraction", lambda: make_agent(horizon=2.5), TypeError,
     "horizon must be a positive integer, got 2.5"),
    ("pilco-horizon-bool", lambda: make_agent(horizon=True), TypeError,
     "horizon must be a positive integer, got True"),
    ("pilco-horizon-string", lambda: make_agent(horizon="30"), TypeError,
     "horizon must be a positive integer, got '30'"),
    ("pilco-m-init-shape", lambda: make_agent(m_init=np.zeros((1, 3))), ValueError,
     r"initial state mean must have shape \(1, 2\), got \(1, 3\)"),
    ("pilco-m-init-nan", lambda: make_agent(m_init=[0.0, np.nan]), ValueError,
     "initial state mean contains NaN"),
    ("pilco-S-init-not-symmetric", lambda: make_agent(S_init=NOT_SYMMETRIC), ValueError,
     "initial state covariance is not symmetric"),
    ("pilco-S-init-not-psd", lambda: make_agent(S_init=NOT_PSD), ValueError,
     "initial state covariance is not positive semi-definite"),
    ("pilco-S-init-shape", lambda: make_agent(S_init=np.eye(3)), ValueError,
     r"initial state covariance must have shape \(2, 2\), got \(3, 3\)"),
    ("pilco-S-init-inf", lambda: make_agent(S_init=with_value(np.eye(2), (1, 1), np.inf)),
     ValueError, "initial state covariance contains inf"),
    ("pilco-S-init-string", lambda: make_agent(S_init="identity"), TypeError,
     "initial state covariance must be an array of numbers"),
    ("pilco-induced-zero", lambda: make_agent(num_induced_points=0), ValueError,
     "num_induced_points must be a positive integer, got 0"),
    ("pilco-induced-bool", lambda: make_agent(num_induced_points=True), TypeError,
     "num_induced_points must be a positive integer"),
    ("pilco-input-noise-string", lambda: make_agent(policy_input_noise="False"), TypeError,
     "policy_input_noise must be True or False"),
]


@pytest.mark.parametrize("call, error, match",
                         [pytest.param(*case[1:], id=case[0]) for case in CONSTRUCTION])
def test_construction_is_validated(call, error, match):
    with pytest.raises(error, match=match):
        call()


METHODS = [
    # -- MGPR -------------------------------------------------------------------------------
    ("gp.set_data-columns", "gp", lambda g: g.set_data((X[:, :2], Y)), ValueError,
     "data X must have 3 columns, got 2"),
    ("gp.set_data-nan", "gp", lambda g: g.set_data((X, with_value(Y, (1, 1), np.nan))),
     ValueError, "data Y contains NaN"),
    ("gp.set_data-rows", "gp", lambda g: g.set_data((X, Y[:3])), ValueError,
     "same number of rows"),
    ("gp.set_data-empty", "gp", lambda g: g.set_data((X[:0], Y[:0])), ValueError,
     "data X is empty"),
    ("gp.predict-mean-shape", "gp",
     lambda g: g.predict_on_noisy_inputs(np.zeros((1, 2)), np.eye(3)), ValueError,
     r"input mean must have shape \(1, 3\)"),
    ("gp.predict-not-psd", "gp",
     lambda g: g.predict_on_noisy_inputs(np.zeros((1, 3)), -np.eye(3)), ValueError,
     "input covariance is not positive semi-definite"),
    ("gp.predict-nan", "gp",
     lambda g: g.predict_on_noisy_inputs([[0.0, np.nan, 0.0]], np.eye(3)), ValueError,
     "input mean contains NaN"),
    ("gp.optimize-maxiter-zero", "gp", lambda g: g.optimize(maxiter=0), ValueError,
     "maxiter must be a positive integer, got 0"),
    ("gp.optimize-restarts-zero", "gp", lambda g: g.optimize(restarts=0), ValueError,
     "restarts must be a positive integer, got 0"),
    ("gp.optimize-restarts-bool", "gp", lambda g: g.optimize(restarts=True), TypeError,
     "restarts must be a positive integer"),
    ("gp.optimize-restarts-fraction", "gp", lambda g: g.optimize(restarts=1.5), TypeError,
     "restarts must be a positive integer"),
    ("gp.optimize-seed-string", "gp", lambda g: g.optimize(seed="abc"), TypeError,
     "seed must be None or a non-negative integer"),
    # -- controllers ---------------------------------------------------------------------
    ("rbf.set_data-not-a-pair", "rbf", lambda c: c.set_data(np.zeros((3, 4, 2))), TypeError,
     r"data must be a pair \(centers, targets\)"),
    ("rbf.set_data-centers-shape", "rbf",
     lambda c: c.set_data((np.zeros((3, 2)), np.zeros((4, 1)))),
     ValueError, r"centers must have shape \(4, 2\), got \(3, 2\)"),
    ("rbf.set_data-targets-shape", "rbf",
     lambda c: c.set_data((np.zeros((4, 2)), np.zeros((4, 2)))),
     ValueError, r"targets must have shape \(4, 1\), got \(4, 2\)"),
    ("rbf.set_data-targets-nan", "rbf",
     lambda c: c.set_data((np.zeros((4, 2)), with_value(np.zeros((4, 1)), (2, 0), np.nan))),
     ValueError, "targets contains NaN"),
    ("rbf.set_data-1d", "rbf", lambda c: c.set_data((np.zeros(8), np.zeros((4, 1)))),
     ValueError, "centers must be 2-D"),
    ("rbf.compute_action-mean-shape", "rbf", lambda c: c.compute_action(np.zeros((1, 3)), S0),
     ValueError, r"state mean must have shape \(1, 2\), got \(1, 3\)"),
    ("rbf.compute_action-nan", "rbf", lambda c: c.compute_action([[np.nan, 0.0]], S0),
     ValueError, "state mean contains NaN"),
    ("rbf.compute_action-not-symmetric", "rbf", lambda c: c.compute_action(M0, NOT_SYMMETRIC),
     ValueError, "state covariance is not symmetric"),
    ("rbf.compute_action-not-psd", "rbf", lambda c: c.compute_action(M0, NOT_PSD), ValueError,
     "state covariance is not positive semi-definite"),
    ("rbf.compute_action-cov-shape", "rbf", lambda c: c.compute_action(M0, np.eye(3)),
     ValueError, r"state covariance must have shape \(2, 2\)"),
    ("linear.compute_action-mean-shape", "linear",
     lambda c: c.compute_action(np.zeros((2, 2)), S0), ValueError,
     r"state mean must have shape \(1, 2\), got \(2, 2\)"),
    ("linear.compute_action-inf-cov", "linear",
     lambda c: c.compute_action(M0, with_value(S0, (0, 0), np.inf)), ValueError,
     "state covariance contains inf"),
    # -- rewards ------------------------------------------------------------------------
    ("exp.compute_reward-mean-shape", "reward",
     lambda r: r.compute_reward(np.zeros((1, 3)), S0), ValueError,
     r"state mean must have shape \(1, 2\)"),
    ("exp.compute_reward-not-psd", "reward", lambda r: r.compute_reward(M0, NOT_PSD),
     ValueError, "state covariance is not positive semi-definite"),
    ("cartpole.compute_reward-state-size", "cartpole",
     lambda r: r.compute_reward(M0, S0), ValueError, r"state mean must have shape \(1, 4\)"),
    # -- PILCO ----------------------------------------------------------------------------
    ("predict-mean-shape", "agent", lambda a: a.predict(np.zeros((1, 3)), S0), ValueError,
     r"initial state mean must have shape \(1, 2\)"),
    ("predict-not-psd", "agent", lambda a: a.predict(M0, NOT_PSD), ValueError,
     "initial state covariance is not positive semi-definite"),
    ("predict-nan", "agent", lambda a: a.predict([[np.nan, 0.0]], S0), ValueError,
     "initial state mean contains NaN"),
    ("predict-horizon-zero", "agent", lambda a: a.predict(horizon=0), ValueError,
     "horizon must be a positive integer, got 0"),
    ("predict-horizon-string", "agent", lambda a: a.predict(horizon="5"), TypeError,
     "horizon must be a positive integer"),
    ("predict-horizon-negative", "agent", lambda a: a.predict(M0, S0, -3), ValueError,
     "horizon must be a positive integer, got -3"),
    ("predict-horizon-fraction", "agent", lambda a: a.predict(M0, S0, 2.5), TypeError,
     "horizon must be a positive integer, got 2.5"),
    ("predict-horizon-list", "agent", lambda a: a.predict(M0, S0, [3]), TypeError,
     r"horizon must be a positive integer, got \[3\]"),
    ("predict_trajectory-not-symmetric", "agent",
     lambda a: a.predict_trajectory(M0, NOT_SYMMETRIC), ValueError,
     "initial state covariance is not symmetric"),
    ("predict_trajectory-horizon-bool", "agent", lambda a: a.predict_trajectory(horizon=True),
     TypeError, "horizon must be a positive integer"),
    ("predict_trajectory-horizon-negative", "agent", lambda a: a.predict_trajectory(horizon=-1),
     ValueError, "horizon must be a positive integer"),
    ("compute_action-nan", "agent", lambda a: a.compute_action([0.0, np.nan]), ValueError,
     "state contains NaN"),
    ("compute_action-inf-2d", "agent", lambda a: a.compute_action([[np.inf, 0.0]]), ValueError,
     r"state contains NaN or inf \(first at index \(0, 0\)\)"),
    ("compute_action-size", "agent", lambda a: a.compute_action([0.0, 1.0, 2.0]), ValueError,
     r"state must have 2 entries per row .* got shape \(3,\)"),
    ("compute_action-rank", "agent", lambda a: a.compute_action(np.zeros((1, 2, 2))),
     ValueError, r"state must have shape \[2\] or \[N, 2\], got \(1, 2, 2\)"),
    ("compute_action-strings", "agent", lambda a: a.compute_action(["0", "1"]), TypeError,
     "state must be an array of .*numbers, got strings"),
    ("compute_action-none", "agent", lambda a: a.compute_action(None), TypeError,
     "state must be an array of numbers"),
    ("optimize_policy-maxiter-zero", "agent", lambda a: a.optimize_policy(maxiter=0),
     ValueError, "maxiter must be a positive integer, got 0"),
    ("optimize_policy-maxiter-string", "agent", lambda a: a.optimize_policy(maxiter="10"),
     TypeError, "maxiter must be a positive integer"),
    ("optimize_policy-restarts-zero", "agent", lambda a: a.optimize_policy(restarts=0),
     ValueError, "restarts must be a positive integer, got 0"),
    ("optimize_policy-restarts-bool", "agent", lambda a: a.optimize_policy(restarts=True),
     TypeError, "restarts must be a positive integer"),
    ("optimize_policy-restarts-fraction", "agent", lambda a: a.optimize_policy(restarts=1.5),
     TypeError, "restarts must be a positive integer"),
    ("optimize_policy-seed-negative", "agent", lambda a: a.optimize_policy(seed=-1),
     ValueError, "seed must be None or a non-negative integer"),
    ("optimize_policy-method-unknown", "agent", lambda a: a.optimize_policy(method="adam"),
     ValueError, r"method must be one of \('L-BFGS-B', 'BFGS'\), got 'adam'"),
    ("optimize_policy-min-rel-improvement-negative", "agent",
     lambda a: a.optimize_policy(min_rel_improvement=-1.0), ValueError,
     "min_rel_improvement must be a finite number >= 0 or None"),
    ("optimize_policy-min-rel-improvement-nan", "agent",
     lambda a: a.optimize_policy(min_rel_improvement=np.nan), ValueError,
     "min_rel_improvement must be a finite number >= 0 or None"),
    ("optimize_policy-patience-zero", "agent", lambda a: a.optimize_policy(patience=0),
     ValueError, "patience must be a positive integer, got 0"),
    ("optimize_models-maxiter-zero", "agent", lambda a: a.optimize_models(maxiter=0),
     ValueError, "maxiter must be a positive integer, got 0"),
    ("optimize_models-restarts-negative", "agent", lambda a: a.optimize_models(restarts=-2),
     ValueError, "restarts must be a positive integer, got -2"),
    ("optimize_models-restarts-bool", "agent", lambda a: a.optimize_models(restarts=False),
     TypeError, "restarts must be a positive integer"),
    ("optimize_models-seed-float", "agent", lambda a: a.optimize_models(seed=0.5), TypeError,
     "seed must be None or a non-negative integer"),
    ("set_data-columns", "agent", lambda a: a.set_data((X[:, :2], Y)), ValueError,
     "data X must have 3 columns, got 2"),
    ("set_data-state-columns", "agent", lambda a: a.set_data((X, np.zeros((N, 3)))),
     ValueError, "data Y must have 2 columns, got 3"),
    ("set_data-nan", "agent", lambda a: a.set_data((with_value(X, (0, 2), np.nan), Y)),
     ValueError, "data X contains NaN"),
    ("set_data-1d", "agent", lambda a: a.set_data((X, Y[:, 0])), ValueError,
     "data Y must be 2-D"),
    ("horizon-setter-zero", "agent", lambda a: setattr(a, "horizon", 0), ValueError,
     "horizon must be a positive integer, got 0"),
    ("m_init-setter-nan", "agent", lambda a: setattr(a, "m_init", [np.nan, 0.0]), ValueError,
     "initial state mean contains NaN"),
    ("S_init-setter-not-psd", "agent", lambda a: setattr(a, "S_init", NOT_PSD), ValueError,
     "initial state covariance is not positive semi-definite"),
]

_OBJECTS = {
    "rbf": lambda: rbf(),
    "linear": lambda: LinearController(D, U),
    "reward": lambda: ExponentialReward(D),
    "cartpole": lambda: CartPoleReward(),
}


@pytest.mark.parametrize("target, call, error, match",
                         [pytest.param(*case[1:], id=case[0]) for case in METHODS])
def test_method_arguments_are_validated(request, target, call, error, match):
    obj = request.getfixturevalue(target) if target in ("agent", "gp") else _OBJECTS[target]()
    with pytest.raises(error, match=match):
        call(obj)


def test_invalid_calls_leave_the_agent_unchanged(agent):
    before = (agent.horizon, agent.m_init.copy(), agent.S_init.copy(), agent.data)
    for bad in (lambda: agent.set_data((X[:, :2], Y)), lambda: setattr(agent, "horizon", 0),
                lambda: setattr(agent, "S_init", NOT_PSD)):
        with pytest.raises(ValueError):
            bad()
    assert agent.horizon == before[0]
    np.testing.assert_array_equal(agent.m_init, before[1])
    np.testing.assert_array_equal(agent.S_init, before[2])
    np.testing.assert_array_equal(agent.data[0], before[3][0])
    # valid values in the same accepted forms still work
    agent.horizon = 3.0
    assert agent.horizon == 3
    assert agent.compute_action(np.zeros(D)).shape == (1, U)


def test_predict_horizon_none_whole_floats_and_numpy_integers_work(agent):
    """``predict(m, S, horizon)`` as in the paper's scripts: None is the agent's horizon,
    2.0 and np.int64(2) are 2, and a longer horizon gives another prediction."""
    agent.horizon = 3
    outputs = {h: [np.asarray(v) for v in agent.predict(M0, S0, h)]
               for h in (None, 3, 2, 2.0, np.int64(2))}
    for a, b in ((None, 3), (2.0, 2), (np.int64(2), 2)):
        for va, vb in zip(outputs[a], outputs[b]):
            np.testing.assert_array_equal(va, vb)
    assert not np.array_equal(outputs[3][0], outputs[2][0])
    assert all(np.all(np.isfinite(v)) for v in outputs[3])


# -- degenerate data work -------------------------------------------------------------------
@pytest.mark.parametrize("sparse", [False, True], ids=["full", "sparse"])
def test_degenerate_data_train_and_predict(sparse):
    """A transition recorded twice, one recorded N times (sparse: every inducing input the
    same) and a state dimension that never changes: training and prediction give finite
    values (the noise floor keeps the kernel matrices invertible), and the GP learns the
    constant dimension."""
    Xd = np.vstack([X, X[:1]] if not sparse else [X[:4], np.tile(X[:1], (N, 1))])
    Yd = np.vstack([Y, Y[:1]] if not sparse else [Y[:4], np.tile(Y[:1], (N, 1))])
    Yd[:, 1] = 0.0  # zero variance
    agent = make_agent(data=(Xd, Yd), num_induced_points=4 if sparse else None)
    losses = agent.optimize_models(maxiter=20)
    m, s, total = (np.asarray(v) for v in agent.predict(M0, S0, 3))
    mean, var = agent.one_step_prediction(Xd[:3])
    for v in (losses, m, s, total, mean, var):
        assert np.all(np.isfinite(v))
    assert np.all(np.linalg.eigvalsh(s) > -1e-9) and np.all(var > 0)
    np.testing.assert_allclose(mean[:, 1], 0.0, atol=1e-3)  # the constant dimension
    assert abs(mean[0, 0] - Yd[0, 0]) < 0.02  # the repeated transition


# -- numerical failures are recovered -------------------------------------------------------
def _duplicated_data():
    rng = np.random.default_rng(1)
    Xd = rng.standard_normal((8, 2))
    Xd = np.vstack([Xd, Xd, Xd])  # every input three times
    Yd = np.hstack([np.sin(Xd[:, :1]), Xd[:, 1:] ** 2])  # noise-free targets
    return Xd, Yd


def _break(gp):
    """Hyperparameters whose kernel matrix is singular in float64: the loss is NaN."""
    for m in gp.models:
        m.kernel.lengthscales.assign([1e4, 1e4])
        m.kernel.variance.assign(1e6)
        m.likelihood.variance.assign(2 * gp.noise_floor)


def test_gp_training_recovers_from_a_failure_mid_run(caplog, monkeypatch):
    """A run that ends at singular hyperparameters keeps the best values seen."""
    import gpflow

    gp = MGPR(_duplicated_data(), noise_floor=1e-12)
    start = gp._model_losses()
    real_minimize = gpflow.optimizers.Scipy.minimize

    def minimize_then_blow_up(self, closure, variables, **kw):
        real_minimize(self, closure, variables, **dict(kw, options=dict(maxiter=5)))
        _break(gp)  # the optimiser wandered into a numerically singular region
        assert not np.all(np.isfinite(gp._model_losses()))
        return real_minimize(self, closure, variables, **kw)

    monkeypatch.setattr(gpflow.optimizers.Scipy, "minimize", minimize_then_blow_up)
    with caplog.at_level(logging.WARNING, logger="pilco"):
        losses = gp.optimize(maxiter=20)
    assert any("ended at a non-finite loss" in r.getMessage()
               for r in caplog.records if r.levelno == logging.WARNING)
    ell, sf2, sn2 = (t.numpy() for t in gp.hyperparameters())
    assert np.all(np.isfinite(ell)) and np.all(np.isfinite(sf2)) and np.all(np.isfinite(sn2))
    assert np.all(np.isfinite(losses)) and np.all(losses <= start + 1e-9)
    assert np.all(ell < 1e3)  # not the singular values


def test_gp_training_recovers_from_a_cholesky_error(caplog, monkeypatch):
    """The optimiser raising (a Cholesky failure) is logged and the best values kept."""
    import gpflow

    gp = MGPR(_duplicated_data(), noise_floor=1e-12)
    start = gp._model_losses()

    def failing_minimize(self, closure, variables, **kw):
        _break(gp)
        raise CHOLESKY_ERROR

    monkeypatch.setattr(gpflow.optimizers.Scipy, "minimize", failing_minimize)
    with caplog.at_level(logging.WARNING, logger="pilco"):
        losses = gp.optimize(maxiter=20, restarts=2, seed=0)
    assert sum("failed" in r.getMessage() for r in caplog.records) == 2
    np.testing.assert_allclose(losses, start)
    assert all(np.all(np.isfinite(t.numpy())) for t in gp.hyperparameters())


def test_gp_training_recovers_from_a_singular_start(caplog):
    """Hyperparameters that are already singular are replaced by data-driven values."""
    gp = MGPR(_duplicated_data(), noise_floor=1e-12)
    _break(gp)
    assert not np.all(np.isfinite(gp._model_losses()))
    with caplog.at_level(logging.WARNING, logger="pilco"):
        losses = gp.optimize(maxiter=20)
    assert any("starting" in r.getMessage() for r in caplog.records
               if r.levelno == logging.WARNING)
    assert np.all(np.isfinite(losses))
    assert all(np.all(np.isfinite(t.numpy())) for t in gp.hyperparameters())


@pytest.mark.parametrize("failure", ["raise", "nan"])
def test_policy_optimisation_keeps_the_best_policy_after_a_failure(caplog, monkeypatch, failure):
    agent = make_agent()
    start = agent.expected_return()
    before = [v.numpy().copy() for v in agent.controller.trainable_variables]

    def broken_minimize(closure, variables, **kw):
        agent.controller.centers.assign(np.full(agent.controller.centers.shape, np.nan))
        if failure == "raise":
            raise CHOLESKY_ERROR

    monkeypatch.setattr(agent._policy_optimizer, "minimize", broken_minimize)
    with caplog.at_level(logging.WARNING, logger="pilco"):
        best = agent.optimize_policy(maxiter=5, restarts=2, seed=0)
    if failure == "raise":
        assert sum("failed" in r.getMessage() for r in caplog.records) == 2
    assert np.isfinite(best) and best >= start - 1e-12
    assert np.isclose(agent.expected_return(), best)
    if best == start:
        for v, b in zip(agent.controller.trainable_variables, before):
            np.testing.assert_array_equal(v.numpy(), b)
    assert np.all(np.isfinite(agent.compute_action(np.zeros(D))))


def test_interrupted_policy_optimisation_keeps_the_best_policy_evaluated():
    """An interrupt in the middle of a run (Ctrl-C, SIGTERM in the runner) leaves the best
    policy evaluated so far in place, not the trial point being evaluated."""
    agent = make_agent()
    start = agent.expected_return()
    returns = []
    first = []
    original = agent._policy_optimizer.eval_func

    def interrupting_eval_func(*args, **kwargs):
        inner = original(*args, **kwargs)

        def wrapped(x):
            if not first:
                first.append(np.array(x, copy=True))
            if len(returns) == 4:
                # Back to the starting point, which the run has improved on, then Ctrl-C while
                # its parameters are set. (A point the run never saw might score higher than
                # everything before it, and would then rightly be kept.)
                inner(first[0])
                raise KeyboardInterrupt
            loss, grad = inner(x)
            returns.append(-float(loss))
            return loss, grad

        return wrapped

    agent._policy_optimizer.eval_func = interrupting_eval_func
    with pytest.raises(KeyboardInterrupt):
        agent.optimize_policy(maxiter=50)
    assert np.isclose(returns[0], start, rtol=1e-9)
    assert max(returns) > start + 1e-6  # so the trial point is not the best one
    assert np.isclose(agent.expected_return(), max(returns), rtol=1e-9)
    assert agent.expected_return() >= start - 1e-12


def test_policy_optimisation_stops_when_the_return_stalls(caplog):
    """With ``min_rel_improvement`` a run ends once ``patience`` iterations gained less than it:
    an unreachable bar stops after exactly patience + 1 iterations, keeping the best policy."""
    agent = make_agent()
    start = agent.expected_return()
    iterations = []
    with caplog.at_level(logging.INFO, logger="pilco"):
        best = agent.optimize_policy(maxiter=50, callback=iterations.append,
                                     min_rel_improvement=1e9, patience=3)
    assert iterations == [0, 1, 2, 3]
    assert any("stopped early, after [4] iterations" in r.getMessage() for r in caplog.records)
    assert best >= start - 1e-12
    assert np.isclose(agent.expected_return(), best, rtol=1e-9)


def test_policy_optimisation_runs_on_without_a_stall():
    """A bar of zero never stops a run that keeps improving: it reaches maxiter."""
    agent = make_agent()
    iterations = []
    agent.optimize_policy(maxiter=4, callback=iterations.append, min_rel_improvement=0.0,
                          patience=2)
    assert iterations == [0, 1, 2, 3]


@pytest.mark.parametrize("method", ["BFGS", "bfgs", "L-BFGS-B"])
def test_policy_optimisers_improve_the_expected_return(method):
    agent = make_agent()
    start = agent.expected_return()
    best = agent.optimize_policy(maxiter=15, method=method)
    assert best > start + 1e-3
    assert np.isclose(agent.expected_return(), best, rtol=1e-9)


def test_gp_training_stops_when_the_loss_stalls():
    gp_model = MGPR((X, Y))
    start = gp_model._model_losses().sum()
    iterations = []
    gp_model.optimize(maxiter=100, callback=iterations.append, min_rel_improvement=1e9, patience=2)
    assert iterations == [0, 1, 2]
    assert gp_model._model_losses().sum() < start
    with pytest.raises(ValueError, match="min_rel_improvement must be a finite number >= 0"):
        gp_model.optimize(min_rel_improvement=-0.5)
    with pytest.raises(TypeError, match="min_rel_improvement must be a finite number >= 0"):
        gp_model.optimize(min_rel_improvement="1")


def test_experiment_config_rejects_an_unknown_early_stop_rule():
    from pilco.experiment import ExperimentConfig

    config = ExperimentConfig(task="t", env_id="id", policy_early_stop="solved")
    assert config.policy_early_stop == "solved"
    with pytest.raises(ValueError, match="policy_early_stop must be 'always' or 'solved'"):
        ExperimentConfig(task="t", env_id="id", policy_early_stop="never")


@pytest.mark.parametrize("scale", [1.0, 1000.0])
def test_stall_rule_is_relative_to_the_loss(scale):
    """The same relative bar stops runs on losses of any scale at the same point: a loss
    falling 0.2 % per iteration passes a 0.5 % bar over 3 iterations, 0.1 % does not."""
    from pilco.snapshots import Stalled, TrackingScipy

    def iterations_until_stop(rate):
        opt = TrackingScipy()
        on_step = opt.step_callback(min_rel_improvement=0.005, patience=3)
        loss = 10.0 * scale
        for it in range(50):
            opt.run_best_loss = loss
            try:
                on_step(it, None, None)
            except Stalled as stop:
                return stop.iterations
            loss -= rate * abs(loss)
        return None

    assert iterations_until_stop(0.002) is None
    assert iterations_until_stop(0.001) == 4


def test_a_config_saved_under_the_names_of_before_reads_back():
    """Runs saved before the loop's settings were declared once stored ``steps`` and
    ``policy_method``; they resume under today's names, settings since removed dropped."""
    import dataclasses

    from pilco.experiment import ExperimentConfig

    config = ExperimentConfig.from_saved(dict(task="t", env_id="e", steps=7, episodes=3,
                                              policy_method="BFGS", a_removed_setting=1))
    assert (config.horizon, config.policy_optimizer, config.episodes) == (7, "BFGS", 3)
    assert ExperimentConfig.from_saved(dataclasses.asdict(config)) == config
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.horizon = 8


def test_run_settings_are_the_loops_settings_extended():
    """Each loop setting is declared once: the tasks' settings inherit it with its flag,
    and a task's config carries it under the same name."""
    import dataclasses

    from pilco.experiment import LoopSettings
    from pilco.tasks import get_task
    from pilco.tasks.settings import RunSettings

    loop = {f.name for f in dataclasses.fields(LoopSettings)}
    assert loop <= {f.name for f in dataclasses.fields(RunSettings)}
    task = get_task("cartpole")
    settings = task.parse(["--horizon", "17", "--policy-optimizer", "bfgs"])
    config = task.config(settings)
    assert all(getattr(config, name) == getattr(settings, name) for name in loop)
    assert (config.horizon, config.policy_optimizer) == (17, "BFGS")
