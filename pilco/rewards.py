"""Rewards whose expectation and variance under a Gaussian state are computed in closed form.

Every reward has ``moments(m [1, D], s [D, D]) -> (mean [1, 1], variance [1, 1])`` (the
protocol :class:`pilco.protocols.Reward`) and ``compute_reward``, the same with its inputs
checked; the saturating ones and their weighted sums also say where their target is
(``cost_geometry()``, :mod:`pilco.reward_geometry`).
PILCO maximises the sum of expected rewards over the horizon. A saturating
("exponential") reward ``exp(-(x - t)^T W (x - t) / 2)`` is PILCO's cost ``1 - reward``.
"""
from __future__ import annotations

from typing import Optional, Sequence

import gpflow
import numpy as np
import tensorflow as tf
from check_shapes import check_shapes, inherit_check_shapes
from gpflow.config import default_float

from .angles import trig_moments
from .moments import compiled, eye_like
from .protocols import Reward
from .reward_geometry import (CostGeometry, geometry_of, quadratic_geometry, tip_geometry,
                              weighted_geometry)
from .validation import (
    check_entries,
    check_gaussian,
    check_indices,
    check_matrix,
    check_positive_float,
    check_positive_int,
    check_reward,
    check_reward_list,
    check_weight_matrix,
    checked_arguments,
)

__all__ = ["ExponentialReward", "AxisBumpsReward", "LinearReward", "CombinedRewards",
           "CartPoleReward", "LinearMapReward", "difference_map"]


def _exp_reward_moments(m, s, W, t):
    """Mean and variance of ``exp(-(x - t)^T W (x - t) / 2)`` for x ~ N(m, s).

    Shapes: m [1, D], s [D, D], W [D, D], t [1, D] -> mean [1, 1], variance [1, 1].
    """
    eye = eye_like(s)
    d = m - t
    SW = tf.matmul(s, W)
    # W (I + s W)^-1, written through a solve with the transposed system
    iSpW = tf.transpose(tf.linalg.solve(tf.transpose(eye + SW), W))
    mean = tf.exp(-0.5 * tf.matmul(tf.matmul(d, iSpW), d, transpose_b=True)) * tf.exp(
        -0.5 * compiled.log_determinant(eye + SW)
    )
    i2SpW = tf.transpose(tf.linalg.solve(tf.transpose(eye + 2.0 * SW), W))
    r2 = tf.exp(-tf.matmul(tf.matmul(d, i2SpW), d, transpose_b=True)) * tf.exp(
        -0.5 * compiled.log_determinant(eye + 2.0 * SW)
    )
    return mean, r2 - mean * mean


def _check_state_gaussian(reward, arguments) -> None:
    arguments["m"], arguments["s"] = check_gaussian(arguments["m"], arguments["s"],
                                                    reward.state_dim, "state")


class _Reward(gpflow.base.Module):
    """Base of the rewards of this module: :meth:`compute_reward` checks its input and
    calls :meth:`moments`, the method of :class:`pilco.protocols.Reward`."""

    state_dim: int

    @checked_arguments(_check_state_gaussian)
    @check_shapes(
        "m: [1, D]",
        "s: [D, D]",
        "return[0]: [1, 1]",
        "return[1]: [1, 1]",
    )
    def compute_reward(self, m, s):
        """Expected reward and its variance (tensors), the input checked
        (:mod:`pilco.validation.inputs`: eager or inside ``tf.function``).
        Shapes: m [1, D], s [D, D] -> [1, 1], [1, 1]."""
        return self.moments(m, s)

    @check_shapes(
        "m: [1, D]",
        "s: [D, D]",
        "return[0]: [1, 1]",
        "return[1]: [1, 1]",
    )
    def moments(self, m, s):  # pragma: no cover - abstract
        """Reward moments without input checks. Shapes as :meth:`compute_reward`."""
        raise NotImplementedError


class ExponentialReward(_Reward):
    """Saturating reward ``exp(-(x - t)^T W (x - t) / 2)`` in [0, 1].

    ``W`` [D, D] symmetric positive semi-definite (default identity), target ``t`` [1, D]
    (default zeros). Both are non-trainable parameters that can be reassigned.
    """

    def __init__(self, state_dim: int, W=None, t=None):
        super().__init__()
        self.state_dim = D = check_positive_int(state_dim, "state_dim")
        W = np.eye(D) if W is None else check_weight_matrix(W, D, "W")
        t = np.zeros((1, D)) if t is None else check_entries(t, D, "t", "t (the target)")
        t = t.reshape(1, -1)
        self.W = gpflow.Parameter(W, trainable=False)
        self.t = gpflow.Parameter(t, trainable=False)

    @inherit_check_shapes
    def moments(self, m, s):
        return _exp_reward_moments(m, s, tf.convert_to_tensor(self.W), tf.convert_to_tensor(self.t))

    def cost_geometry(self) -> CostGeometry:
        """Where the reward's target is, read from its current ``W`` and ``t``
        (:func:`pilco.reward_geometry.quadratic_geometry`)."""
        return quadratic_geometry(self.W.numpy(), self.t.numpy()[0])


class AxisBumpsReward(_Reward):
    """Weighted sum of one-dimensional saturating bumps, ``sum_k c_k exp(-(x[d_k] - t_k)^2
    / (2 w_k^2))``, each on one state dimension ``d_k`` (several may share one).

    The same value as a :class:`CombinedRewards` of one :class:`ExponentialReward` per
    bump (``W`` with the single entry ``1 / w_k^2`` at ``[d_k, d_k]``), including its
    variance ``sum_k c_k^2 Var[bump_k]`` (covariances between bumps neglected), but
    computed for all bumps at once in a few operations instead of two solves and two
    log-determinants per bump: e.g. the reacher's 8 joint-limit bumps.

    Shapes: ``dims`` [K] integers in ``range(state_dim)``, ``t`` [K] centres, ``widths``
    [K] > 0, ``coefs`` [K] (default ones). ``t``, ``widths`` and ``coefs`` are
    non-trainable parameters that can be reassigned.
    """

    def __init__(self, state_dim: int, dims, t, widths, coefs=None):
        super().__init__()
        self.state_dim = D = check_positive_int(state_dim, "state_dim")
        if not isinstance(dims, (str, bytes)):  # a string is refused by check_indices
            dims = np.asarray(dims, dtype=object).reshape(-1).tolist()  # one index or many
        self.dims = check_indices(dims, D, "dims", distinct=False)
        if not self.dims:
            raise ValueError("dims must name at least one state dimension")
        K = len(self.dims)
        widths = check_entries(widths, K, "widths")
        if np.any(widths <= 0):
            raise ValueError(f"widths must be positive, got {widths}")
        coefs = np.ones(K) if coefs is None else check_entries(coefs, K, "coefs")
        self.t = gpflow.Parameter(check_entries(t, K, "t", "t (the centres)"), trainable=False)
        self.widths = gpflow.Parameter(widths, trainable=False)
        self.coefs = gpflow.Parameter(coefs, trainable=False)

    @inherit_check_shapes
    def moments(self, m, s):
        dims = tf.constant(self.dims)
        d = tf.gather(m[0], dims) - tf.convert_to_tensor(self.t)  # [K]
        var = tf.gather(tf.linalg.diag_part(s), dims)  # [K]
        w2 = tf.square(tf.convert_to_tensor(self.widths))
        c = tf.convert_to_tensor(self.coefs)
        # E[bump] = (1 + v / w^2)^-1/2 exp(-d^2 / (2 (w^2 + v))); E[bump^2] the same with
        # twice the variance and without the 1/2 in the exponent
        mean = tf.exp(-0.5 * tf.square(d) / (w2 + var)) * tf.math.rsqrt(1.0 + var / w2)
        second = tf.exp(-tf.square(d) / (w2 + 2.0 * var)) * tf.math.rsqrt(1.0 + 2.0 * var / w2)
        total = tf.reduce_sum(c * mean)
        spread = tf.reduce_sum(tf.square(c) * (second - tf.square(mean)))
        return tf.reshape(total, [1, 1]), tf.reshape(spread, [1, 1])


class LinearReward(_Reward):
    """Linear reward ``x^T W`` with ``W`` [D, 1]; variance ``W^T s W``."""

    def __init__(self, state_dim: int, W):
        super().__init__()
        self.state_dim = D = check_positive_int(state_dim, "state_dim")
        W = check_entries(W, D, "W").reshape(-1, 1)
        self.W = gpflow.Parameter(W, trainable=False)

    @inherit_check_shapes
    def moments(self, m, s):
        W = tf.convert_to_tensor(self.W)
        return tf.matmul(m, W), tf.matmul(tf.transpose(W), tf.matmul(s, W))


class CombinedRewards(_Reward):
    """Weighted sum ``sum_i c_i r_i(x)`` of rewards.

    The variance is ``sum_i c_i^2 Var[r_i]``: the covariance between the rewards is
    neglected (exact when at most one term is random).
    """

    def __init__(self, state_dim: int, rewards: Sequence[Reward], coefs=None):
        super().__init__()
        self.state_dim = check_positive_int(state_dim, "state_dim")
        self.base_rewards = check_reward_list(rewards, self.state_dim)
        n = len(self.base_rewards)
        coefs = np.ones(n) if coefs is None else check_entries(coefs, n, "coefs")
        self.coefs = gpflow.Parameter(coefs, trainable=False)

    @inherit_check_shapes
    def moments(self, m, s):
        mean = 0.0
        var = 0.0
        c = tf.convert_to_tensor(self.coefs)
        for i, r in enumerate(self.base_rewards):
            mi, vi = r.moments(m, s)
            mean += c[i] * mi
            var += c[i] ** 2 * vi
        return mean, var

    def cost_geometry(self) -> Optional[CostGeometry]:
        """The widest positively weighted part's geometry
        (:func:`pilco.reward_geometry.weighted_geometry`); None when such a part has none."""
        return weighted_geometry(self.coefs.numpy(),
                                 [geometry_of(r) for r in self.base_rewards])


class CartPoleReward(_Reward):
    """Saturating reward on the cart-pole's pendulum tip (the MATLAB release's ``loss_cp``).

    State ``[x, x_dot, theta_dot, theta]`` with θ = 0 hanging down. The tip of a pendulum
    of length ``l`` on a cart at x is at ``(x + l sin θ, -l cos θ)``; the reward is
    ``exp(-d^2 / (2 width^2))`` with d the tip's distance to the upright target
    ``(0, l)``. As MATLAB's ``loss_cp``, the state is augmented with (sin θ, cos θ), a
    Gaussian is fitted to the augmented state by moment matching, and the saturating
    reward's moments under that Gaussian are exact (so the result is exact up to that
    fit: within ~0.1 % of the true mean for small covariances).
    """

    def __init__(self, pendulum_length: float = 0.5, width: float = 0.25):
        super().__init__()
        self.state_dim = 4
        self.pendulum_length = check_positive_float(pendulum_length, "pendulum_length")
        self.width = check_positive_float(width, "width")
        l = self.pendulum_length
        Q = np.zeros((6, 6))
        Q[np.ix_([0, 4], [0, 4])] = np.outer([1.0, l], [1.0, l])  # (x + l sin θ)^2
        Q[5, 5] = l ** 2  # l^2 (cos θ + 1)^2
        self._W = tf.constant(Q / self.width ** 2, dtype=default_float())
        self._t = tf.constant([[0.0, 0.0, 0.0, np.pi, np.sin(np.pi), np.cos(np.pi)]],
                              dtype=default_float())

    @inherit_check_shapes
    def moments(self, m, s):
        Mt, St, Ct = trig_moments(m, s, [3])
        cross = tf.matmul(s, Ct)
        M6 = tf.concat([m, Mt], axis=1)
        S6 = tf.concat([tf.concat([s, cross], 1), tf.concat([tf.transpose(cross), St], 1)], 0)
        return _exp_reward_moments(M6, S6, self._W, self._t)

    def cost_geometry(self) -> CostGeometry:
        """The tip's distance to upright (:func:`pilco.reward_geometry.tip_geometry`)."""
        return tip_geometry(self.pendulum_length, self.width)


def difference_map(state_dim: int, first: Sequence[int], second: Sequence[int]) -> np.ndarray:
    """The matrix A [K, D] with ``A x = x[first] - x[second]`` (K = len(first)), e.g. the
    gripper position minus the target held in context dimensions:
    ``difference_map(13, [0, 1, 2], [10, 11, 12]) = [I3, 0, -I3]``. The two index lists
    must have the same length and may not share an index at the same position."""
    D = check_positive_int(state_dim, "state_dim")
    first = check_indices(first, D, "first")
    second = check_indices(second, D, "second")
    if len(first) != len(second) or not first:
        raise ValueError(f"first and second must name as many dimensions (at least one), "
                         f"got {len(first)} and {len(second)}")
    if any(a == b for a, b in zip(first, second)):
        raise ValueError(f"first and second pair a dimension with itself: {first} - {second}")
    A = np.zeros((len(first), D))
    A[np.arange(len(first)), first] = 1.0
    A[np.arange(len(first)), second] = -1.0
    return A


class LinearMapReward(_Reward):
    """A reward of a linear map of the state: ``base_reward(A x + b)``.

    E.g. a saturating reward on the distance between a gripper and a target that is part
    of the state (a multi-task policy's context): ``A = [I3, 0, -I3]`` picks the gripper
    position minus the target (:func:`difference_map`), ``base_reward`` is an
    :class:`ExponentialReward` on 3 dimensions with target 0.

    For ``x ~ N(m, s)`` the map ``z = A x + b`` is Gaussian, ``N(A m + b, A s A^T)``
    exactly, so the moments are the base reward's closed form at that Gaussian (exact
    when the base reward's are; ``A s A^T`` may be singular, e.g. a gripper at a known
    distance from the target). The gradient with respect to ``m`` and ``s`` flows
    through the map by automatic differentiation, as for every reward here.

    Shapes: ``A`` [K, D] with D = ``state_dim``, ``b`` [K] (default zeros),
    ``base_reward.state_dim == K``; :meth:`moments` m [1, D], s [D, D] -> mean [1, 1],
    variance [1, 1]. ``A`` and ``b`` are non-trainable parameters that can be
    reassigned.
    """

    def __init__(self, state_dim: int, base_reward: Reward, A, b=None):
        super().__init__()
        self.state_dim = D = check_positive_int(state_dim, "state_dim")
        self.base_reward = check_reward(base_reward, name="base_reward")
        K = self.base_reward.state_dim
        A = check_matrix(A, (K, D), f"A (the map from the {D}-dimensional state to the "
                                    f"base reward's {K} dimensions)")
        b = np.zeros(K) if b is None else check_entries(b, K, "b")
        self.A = gpflow.Parameter(A, trainable=False)
        self.b = gpflow.Parameter(b.reshape(1, K), trainable=False)

    @inherit_check_shapes
    def moments(self, m, s):
        A = tf.convert_to_tensor(self.A)
        mz = tf.matmul(m, A, transpose_b=True) + tf.convert_to_tensor(self.b)  # [1, K]
        sz = tf.matmul(A, tf.matmul(s, A, transpose_b=True))  # [K, K]
        # symmetric to rounding, as the solves and log-determinants downstream expect
        return self.base_reward.moments(mz, 0.5 * (sz + tf.transpose(sz)))
