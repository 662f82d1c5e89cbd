"""The public protocol of controllers and rewards (pilco.protocols), the shared feature map,
one-step predictions and the direction of imports."""
import subprocess
import sys

import gpflow
import numpy as np
import pytest
import tensorflow as tf

from pilco.angles import augment_state
from pilco.controllers import RbfController
from pilco.deploy import Policy
from pilco.features import angle_features
from pilco.models import PILCO
from pilco.protocols import Controller, Reward
from pilco.rewards import CombinedRewards, ExponentialReward

D, U = 2, 1


class AffineController(gpflow.base.Module):
    """An unbounded affine policy u = x W^T + b, written against the protocol only."""

    def __init__(self, state_dim, control_dim):
        super().__init__()
        self.state_dim, self.control_dim = state_dim, control_dim
        self.W = gpflow.Parameter(np.zeros((control_dim, state_dim)))
        self.b = gpflow.Parameter(np.zeros((1, control_dim)))
        self.prepared = 0

    def prepare(self):
        self.prepared += 1
        return tf.convert_to_tensor(self.W)

    def moments(self, m, s, squash=True, prepared=None):
        W = self.prepare() if prepared is None else prepared
        return (tf.matmul(m, W, transpose_b=True) + self.b,
                tf.matmul(W, tf.matmul(s, W, transpose_b=True)), tf.transpose(W))


class QuadraticReward(gpflow.base.Module):
    """r(x) = -(x - t)^T Q (x - t), with its exact mean and variance under N(m, s)."""

    def __init__(self, target, Q):
        super().__init__()
        self.t = tf.constant(np.reshape(target, (1, -1)), dtype=tf.float64)
        self.Q = tf.constant(Q, dtype=tf.float64)
        self.state_dim = self.Q.shape[0]

    def moments(self, m, s):
        d = m - self.t
        Qs = tf.matmul(self.Q, s)
        mean = -(tf.linalg.trace(Qs) + tf.matmul(tf.matmul(d, self.Q), d, transpose_b=True))
        var = (2.0 * tf.linalg.trace(tf.matmul(Qs, Qs))
               + 4.0 * tf.matmul(tf.matmul(d, tf.matmul(Qs, self.Q)), d, transpose_b=True))
        return tf.reshape(mean, (1, 1)), tf.reshape(var, (1, 1))


def transitions(n=30, seed=0, angle=False):
    """A damped point mass pushed by the action: x' = x + 0.1 [x_2, u - x_2]."""
    rng = np.random.default_rng(seed)
    X = rng.uniform(-2.0, 2.0, (n, D + U))
    Y = 0.1 * np.stack([X[:, 1], X[:, 2] - X[:, 1]], axis=1)
    return X, Y


def test_custom_controller_and_reward_train():
    controller = AffineController(D, U)
    reward = QuadraticReward([1.0, 0.0], np.diag([1.0, 0.1]))
    assert isinstance(controller, Controller) and isinstance(reward, Reward)
    agent = PILCO(transitions(), controller, reward, horizon=8, m_init=np.zeros((1, D)),
                  S_init=0.01 * np.eye(D))
    agent.optimize_models(maxiter=100)
    before = agent.expected_return()
    best = agent.optimize_policy(maxiter=20)
    after = agent.expected_return()
    assert after == pytest.approx(best, rel=1e-9)
    assert after > before + 0.1
    assert controller.prepared > 0  # the rollout went through the protocol
    # the trained policy pushes towards the target x_1 = 1 from the origin
    assert agent.compute_action(np.zeros(D))[0, 0] > 0.0


def test_custom_reward_inside_combined_rewards():
    quadratic = QuadraticReward([0.0, 0.0], np.eye(D))
    combined = CombinedRewards(D, [ExponentialReward(D), quadratic], coefs=[1.0, 0.5])
    m, s = np.array([[0.3, -0.2]]), 0.1 * np.eye(D)
    mean, var = combined.compute_reward(m, s)
    e_mean, e_var = ExponentialReward(D).compute_reward(m, s)
    q_mean, q_var = quadratic.moments(tf.constant(m), tf.constant(s))
    mean, var, e_mean, e_var, q_mean, q_var = (float(np.asarray(v)[0, 0]) for v in (
        mean, var, e_mean, e_var, q_mean, q_var))
    assert mean == pytest.approx(e_mean + 0.5 * q_mean, rel=1e-12)
    assert var == pytest.approx(e_var + 0.25 * q_var, rel=1e-12)


class NoMoments(gpflow.base.Module):
    def __init__(self):
        super().__init__()
        self.state_dim, self.control_dim = D, U

    def _action(self, m, s, squash=True, ctx=None):  # the old private name: not the protocol
        return m, s, s


class OldReward:
    state_dim = D

    def _reward(self, m, s):
        return m, s


@pytest.mark.parametrize("controller, reward, match", [
    (NoMoments(), ExponentialReward(D),
     r"pilco.protocols.Controller.*NoMoments lacks prepare, moments"),
    (AffineController(D, U), OldReward(), r"reward must be a reward .*pilco.protocols.Reward"),
    (AffineController(D, U), "reward", r"reward must be a reward"),
    (object(), ExponentialReward(D), "controller must have a state_dim attribute"),
])
def test_objects_outside_the_protocol_fail_at_construction(controller, reward, match):
    with pytest.raises(TypeError, match=match):
        PILCO(transitions(), controller, reward)


def test_replacing_components_is_checked():
    agent = PILCO(transitions(), AffineController(D, U), ExponentialReward(D))
    with pytest.raises(TypeError, match="pilco.protocols.Reward"):
        agent.reward = OldReward()
    with pytest.raises(ValueError, match="controller.state_dim is 3"):
        agent.controller = AffineController(3, U)



def test_replaced_components_are_used_after_compiling():
    """Setting the reward or the controller after the compiled rollout was traced (by a
    prediction, an optimisation or an action) must change what it computes: the agent then
    agrees with one built with the new components."""
    data = transitions()
    rbf = RbfController(D, U, 4, seed=0)
    near, far = ExponentialReward(D), ExponentialReward(D, t=np.ones((1, D)))
    agent = PILCO(data, rbf, near, horizon=4)
    agent.optimize_policy(maxiter=2)
    agent.compute_action(np.zeros(D))
    before = agent.expected_return()
    agent.reward = far
    fresh = PILCO(data, rbf, far, horizon=4)
    assert agent.expected_return() == pytest.approx(fresh.expected_return(), rel=1e-12)
    assert abs(agent.expected_return() - before) > 1e-3
    np.testing.assert_allclose(agent.predict_trajectory_with_rewards()[2],
                               fresh.predict_trajectory_with_rewards()[2], rtol=1e-12)
    start = fresh.expected_return()
    best = agent.optimize_policy(maxiter=3)  # the objective is the new reward's
    assert best == pytest.approx(agent.expected_return(), rel=1e-9)
    assert best >= start

    other = RbfController(D, U, 4, seed=1)
    agent.controller = other
    fresh = PILCO(data, other, far, horizon=4)
    x = np.full((1, D), 0.3)
    np.testing.assert_allclose(agent.compute_action(x), fresh.compute_action(x), rtol=1e-12)
    assert agent.expected_return() == pytest.approx(fresh.expected_return(), rel=1e-12)

def test_one_step_prediction_is_the_gp_prediction_plus_noise():
    X, Y = transitions()
    X[:, 0] = np.angle(np.exp(1j * X[:, 0]))
    agent = PILCO((X, Y), RbfController(D + 1, U, 4, seed=0), ExponentialReward(D),
                  angle_indices=[0])
    agent.optimize_models(maxiter=20)
    query = np.random.default_rng(1).uniform(-1.0, 1.0, (7, D + U))
    mean, var = agent.one_step_prediction(query)
    f_mean, f_var = agent.mgpr.predict_f(agent.gp_inputs(query))
    noise = np.asarray(agent.mgpr.noise_variance)
    assert mean.shape == var.shape == (7, D)
    np.testing.assert_array_equal(mean, np.asarray(f_mean))
    np.testing.assert_array_equal(var, np.asarray(f_var) + noise)
    assert np.all(var > noise)
    with pytest.raises(ValueError, match="X must have 3 columns"):
        agent.one_step_prediction(query[:, :2])


def test_one_feature_map_for_gp_policy_and_moments():
    rng = np.random.default_rng(2)
    states = rng.uniform(-3.0, 3.0, (5, 4))
    angles = [3, 1]
    features = angle_features(states, angles)
    expected = np.column_stack([states[:, 0], states[:, 2], np.sin(states[:, 3]),
                                np.cos(states[:, 3]), np.sin(states[:, 1]), np.cos(states[:, 1])])
    np.testing.assert_allclose(features, expected, rtol=0, atol=0)
    actions = rng.standard_normal((5, 1))
    agent = PILCO((np.hstack([states, actions]), rng.standard_normal((5, 4))),
                  RbfController(6, 1, 3), ExponentialReward(4), angle_indices=angles)
    np.testing.assert_array_equal(agent.gp_inputs(np.hstack([states, actions])),
                                  np.hstack([features, actions]))
    policy = Policy("linear", "none", 4, angles, 1.0, W=np.ones((1, 6)), b=np.zeros(1))
    np.testing.assert_array_equal(policy.features(states), features)
    for row in range(5):  # the mean of the Gaussian features at a known state
        Mf, _, _ = augment_state(states[row:row + 1], np.zeros((4, 4)), angles)
        np.testing.assert_allclose(np.asarray(Mf)[0], features[row], rtol=1e-15, atol=1e-15)


def test_imports_point_one_way():
    """The library (models and the modules below them) imports none of the layers that
    use it: the experiment loop, the tasks, the sweep, the diagnosis."""
    above = ("pilco.experiment", "pilco.tasks", "pilco.sweep", "pilco.diagnose")
    code = ("import sys, pilco.models; "
            f"print(sorted(m for m in sys.modules if m.startswith({above!r})))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip().splitlines()[-1]
    assert out == "[]"
