"""The batched one-dimensional bumps against the general saturating reward they replace."""
from __future__ import annotations

import numpy as np
import pytest
import tensorflow as tf

from pilco.rewards import AxisBumpsReward, CombinedRewards, ExponentialReward

D = 6
DIMS = [1, 1, 4, 0]  # two bumps may share a dimension (both limits of one joint)
T = np.array([-1.0, 1.2, 0.3, 0.0])
WIDTHS = np.array([0.1, 0.2, 0.5, 1.0])
COEFS = np.array([0.5, 0.5, -1.0, 2.0])


def one_reward_per_bump():
    parts = []
    for d, t, w in zip(DIMS, T, WIDTHS):
        W = np.zeros((D, D))
        W[d, d] = 1.0 / w ** 2
        target = np.zeros((1, D))
        target[0, d] = t
        parts.append(ExponentialReward(D, W, target))
    return CombinedRewards(D, parts, COEFS)


def random_gaussian(seed):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((D, D))
    m = rng.normal(0.0, 1.0, (1, D))
    return m, 0.05 * A @ A.T + 1e-3 * np.eye(D)


@pytest.mark.parametrize("seed", range(4))
def test_the_same_moments_as_one_exponential_reward_per_bump(seed):
    m, s = random_gaussian(seed)
    fast = AxisBumpsReward(D, DIMS, T, WIDTHS, COEFS).compute_reward(m, s)
    slow = one_reward_per_bump().compute_reward(m, s)
    for a, b in zip(fast, slow):
        assert a.shape == (1, 1)
        np.testing.assert_allclose(a.numpy(), b.numpy(), rtol=1e-10, atol=1e-14)


def test_the_same_gradients_as_one_exponential_reward_per_bump():
    m0, s0 = random_gaussian(7)
    m, s = tf.Variable(m0), tf.Variable(s0)

    def gradients(reward):
        with tf.GradientTape() as tape:
            mean, var = reward.moments(m, s)
            total = mean + 3.0 * var
        return [g.numpy() for g in tape.gradient(total, [m, s])]

    fast = gradients(AxisBumpsReward(D, DIMS, T, WIDTHS, COEFS))
    slow = gradients(one_reward_per_bump())
    for a, b in zip(fast, slow):  # s enters through its diagonal only, in both
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)
    assert np.count_nonzero(fast[1] - np.diag(np.diag(fast[1]))) == 0


def test_the_bump_is_highest_at_its_centre_and_parameters_can_be_reassigned():
    reward = AxisBumpsReward(3, [2], [0.5], [0.1])
    at = np.array([[0.0, 0.0, 0.5]])
    assert reward.compute_reward(at, np.zeros((3, 3)))[0].numpy().item() == pytest.approx(1.0)
    reward.t.assign([0.6])
    assert reward.compute_reward(at, np.zeros((3, 3)))[0].numpy().item() == pytest.approx(
        np.exp(-0.5))


@pytest.mark.parametrize("kwargs, error, message", [
    (dict(dims=[6]), ValueError, "index 6 is outside the state"),
    (dict(dims=[-1]), ValueError, "index -1 is outside the state"),
    (dict(dims=[0.5]), TypeError, "dims must hold integers"),
    (dict(dims=[True]), TypeError, "dims must hold integers"),
    (dict(dims="01"), TypeError, "dims must be a sequence of integers"),
    (dict(dims=[]), ValueError, "at least one state dimension"),
    (dict(t=[0.0, 1.0]), ValueError, "t \\(the centres\\) must have 1 entries"),
    (dict(widths=[0.0]), ValueError, "widths must be positive"),
    (dict(widths=[np.nan]), ValueError, "widths"),
    (dict(coefs=[1.0, 2.0]), ValueError, "coefs must have 1 entries"),
])
def test_bad_bumps_are_refused_by_name(kwargs, error, message):
    args = dict(dims=[0], t=[0.0], widths=[0.1], coefs=None)
    args.update(kwargs)
    with pytest.raises(error, match=message):
        AxisBumpsReward(D, args["dims"], args["t"], args["widths"], args["coefs"])
