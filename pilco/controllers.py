"""Policies and the squashing functions that bound their actions.

A controller maps a Gaussian state ``N(m, s)`` to the Gaussian moments of its action:
``moments(m, s) -> (M [1, U], S [U, U], V [D, U])`` with ``V = inv(s) Cov[x, u]``
(the protocol :class:`pilco.protocols.Controller`; ``compute_action`` is the same with
its inputs checked). Actions are bounded by a squashing function applied to the
unsquashed action's moments:

- :func:`squash_sin`: ``u = e * sin(v)``;
- :func:`squash_sat`: ``u = e * (9 sin v + sin 3v) / 8``, a flatter saturation.
"""
from __future__ import annotations

import logging
from typing import Callable, Optional

import gpflow
import numpy as np
import tensorflow as tf
from check_shapes import check_shapes
from gpflow import Parameter
from gpflow.config import default_float

from . import moments as gp_moments
from .seeding import generator
from .validation import (
    as_2d_float,
    check_callable,
    check_entries,
    check_gaussian,
    check_indices,
    check_matrix,
    check_max_action,
    check_non_negative_float,
    check_pair,
    check_positive_int,
    check_squash,
    check_state_row,
    checked_arguments,
)

__all__ = ["squash_sin", "squash_sat", "LinearController", "RbfController", "StartDraw"]

#: shapes of the action moments at a Gaussian state: mean, covariance and
#: ``V = inv(s) Cov[x, u]`` (``moments``, ``compute_action``)
_ACTION_MOMENTS_SHAPES = check_shapes(
    "m: [1, D]",
    "s: [D, D]",
    "return[0]: [1, U]",
    "return[1]: [U, U]",
    "return[2]: [D, U]",
)

logger = logging.getLogger(__name__)


def _sin_moments(m, s, e):
    """Moments of ``e * sin(x)`` elementwise for x ~ N(m, s).

    Shapes: m [1, I], s [I, I], e [I] -> M [1, I], S [I, I], C [I, I].
    """
    e = e[None, :]  # [1, I]; rows and columns below come from transposes, not slices
    vii = tf.linalg.diag_part(s)[None, :]
    damp = e * tf.exp(-0.5 * vii)
    M = damp * tf.sin(m)
    lq = -0.5 * (tf.transpose(vii) + vii)
    q = tf.exp(lq)
    mt = tf.transpose(m)
    S = (tf.exp(lq + s) - q) * tf.cos(mt - m) - (tf.exp(lq - s) - q) * tf.cos(mt + m)
    S = 0.5 * (tf.transpose(e) * e) * S
    C = tf.linalg.diag(damp[0] * tf.cos(m[0]))
    return M, S, C


def _max_action_vector(max_action, size: int, dtype) -> tf.Tensor:
    if not tf.is_tensor(max_action):  # numbers and arrays become one constant
        return tf.constant(np.broadcast_to(np.asarray(max_action, dtype=np.float64).reshape(-1),
                                           (size,)), dtype=dtype)
    e = tf.reshape(tf.cast(max_action, dtype), [-1])
    return tf.broadcast_to(e, [size])


def squash_sin(m, s, max_action=None):
    """Sine squashing ``max_action * sin(v)`` of a Gaussian action v ~ N(m, s).

    Shapes: m [1, U], s [U, U], max_action scalar or [U] (default 1)
    -> M [1, U], S [U, U], C [U, U] with ``C = inv(s) Cov[v, u]`` (diagonal).
    """
    m = tf.convert_to_tensor(m, dtype=default_float())
    s = tf.convert_to_tensor(s, dtype=default_float())
    U = m.shape[-1]
    e = _max_action_vector(1.0 if max_action is None else max_action, U, m.dtype)
    return _sin_moments(m, s, e)


def squash_sat(m, s, max_action=None):
    """Saturating squashing ``max_action * (9 sin v + sin 3v) / 8`` of v ~ N(m, s).

    Its first derivative vanishes at the bounds, so it saturates more gently than
    :func:`squash_sin`. Shapes as :func:`squash_sin`.
    """
    m = tf.convert_to_tensor(m, dtype=default_float())
    s = tf.convert_to_tensor(s, dtype=default_float())
    U = m.shape[-1]
    e = _max_action_vector(1.0 if max_action is None else max_action, U, m.dtype)
    # moments of [sin v, sin 3v] from the augmented Gaussian [v, 3v]
    ma = tf.concat([m, 3.0 * m], axis=1)
    sa = tf.concat([tf.concat([s, 3.0 * s], 1), tf.concat([3.0 * s, 9.0 * s], 1)], 0)
    M2, S2, C2 = _sin_moments(ma, sa, tf.concat([9.0 * e / 8.0, e / 8.0], 0))
    M = M2[:, :U] + M2[:, U:]
    S = S2[:U, :U] + S2[:U, U:] + S2[U:, :U] + S2[U:, U:]
    S = 0.5 * (S + tf.transpose(S))
    C = C2[:U, :U] + 3.0 * C2[U:, U:]
    return M, S, C


def _squash_sin_points(v, e):
    return e * tf.sin(v)


def _squash_sat_points(v, e):
    return e * (9.0 * tf.sin(v) + tf.sin(3.0 * v)) / 8.0


#: the squashing functions at known actions (no uncertainty): v [P, U], e [1, U] -> [P, U]
_POINT_SQUASH = {squash_sin: _squash_sin_points, squash_sat: _squash_sat_points}


def _check_state_gaussian(controller, arguments) -> None:
    arguments["m"], arguments["s"] = check_gaussian(arguments["m"], arguments["s"],
                                                    controller.state_dim, "state")


class _SquashedController(gpflow.base.Module):
    """What both policies share: dimensions, bounds, the squash, and the public protocol
    (:class:`pilco.protocols.Controller`) around an unsquashed prediction."""

    def __init__(self, state_dim: int, control_dim: int, max_action, squash):
        super().__init__()
        self.state_dim = check_positive_int(state_dim, "state_dim")
        self.control_dim = check_positive_int(control_dim, "control_dim")
        self.max_action = check_max_action(max_action, self.control_dim)
        self.squash = check_squash(squash)

    def prepare(self):
        """State-independent pieces for the current parameters (None: nothing to do)."""
        return None

    def _unsquashed(self, m, s, prepared):
        """Moments of the unsquashed action: M [1, U], S [U, U], V [D, U]."""
        raise NotImplementedError

    @_ACTION_MOMENTS_SHAPES
    def moments(self, m, s, squash: bool = True, prepared=None):
        """Action moments. Shapes: m [1, D], s [D, D] -> M [1, U], S [U, U], V [D, U].

        ``prepared`` is :meth:`prepare`'s result, computed here when None.
        """
        M, S, V = self._unsquashed(m, s, self.prepare() if prepared is None else prepared)
        if squash and self.squash is not None:
            M, S, C = self.squash(M, S, self.max_action)
            V = tf.matmul(V, C)
        return M, S, V

    def _unsquashed_points(self, x, prepared):
        """Unsquashed actions at P known inputs: x [P, D] -> [P, U]."""
        raise NotImplementedError

    @check_shapes("x: [P, D]", "return: [P, U]")
    def point_actions(self, x, prepared=None):
        """Actions at P known (policy) inputs, as tensors: x [P, D] -> [P, U]; the mean
        :meth:`moments` returns for a zero covariance, for many inputs at once.
        ``prepared`` is :meth:`prepare`'s result, computed here when None."""
        v = self._unsquashed_points(x, self.prepare() if prepared is None else prepared)
        if self.squash is None:
            return v
        U = self.control_dim
        e = _max_action_vector(self.max_action, U, v.dtype)
        at_points = _POINT_SQUASH.get(self.squash)
        if at_points is not None:
            return at_points(v, e[None, :])
        zero = tf.zeros([U, U], v.dtype)  # another squash: its moments row by row
        return tf.concat([self.squash(v[i:i + 1], zero, self.max_action)[0]
                          for i in range(int(v.shape[0]))], axis=0)

    @checked_arguments(_check_state_gaussian)
    @_ACTION_MOMENTS_SHAPES
    def compute_action(self, m, s, squash: bool = True):
        """Action moments (tensors) with the input checked (:mod:`pilco.validation.inputs`:
        eager or inside ``tf.function``). Shapes as :meth:`moments`."""
        return self.moments(m, s, squash)


class LinearController(_SquashedController):
    """Affine policy ``u = squash(x W^T + b)``.

    Parameters: ``W`` [U, D], ``b`` [1, U] (trainable).
    """

    def __init__(self, state_dim: int, control_dim: int, max_action=1.0, squash=squash_sin,
                 seed: Optional[int] = None):
        super().__init__(state_dim, control_dim, max_action, squash)
        rng = generator(seed)
        self.W = Parameter(rng.uniform(-0.1, 0.1, (self.control_dim, self.state_dim)))
        self.b = Parameter(np.zeros((1, self.control_dim)))

    def _unsquashed(self, m, s, prepared):
        W = tf.convert_to_tensor(self.W)
        M = tf.matmul(m, W, transpose_b=True) + self.b
        S = tf.matmul(W, tf.matmul(s, W, transpose_b=True))
        return M, S, tf.transpose(W)

    def _unsquashed_points(self, x, prepared):
        return tf.matmul(x, self.W, transpose_b=True) + self.b

    def randomize(self, scale: float = 0.1, seed: Optional[int] = None):
        """Draw fresh parameters: W, b ~ N(0, scale^2)."""
        rng = generator(seed)
        self.W.assign(scale * rng.standard_normal(self.W.shape))
        self.b.assign(scale * rng.standard_normal(self.b.shape))


class _PolicyOutput(gpflow.base.Module):
    """One output of the RBF policy, shaped like a GPR: ``.kernel`` and ``.likelihood``."""

    def __init__(self, state_dim: int):
        super().__init__()
        self.kernel = gpflow.kernels.SquaredExponential(lengthscales=np.ones(state_dim))
        self.kernel.variance.assign(1.0)
        gpflow.set_trainable(self.kernel.variance, False)
        self.likelihood = gpflow.likelihoods.Gaussian(variance=1e-4)
        gpflow.set_trainable(self.likelihood.variance, False)


class StartDraw:
    """A policy draw near a start distribution, as the MATLAB release initialises its RBF
    policies: :meth:`RbfController.place_near` of ``mean`` [d] and ``std`` (centres at
    states ``mean + std·z``, angles at ``angle_indices`` replaced by their sine and cosine,
    targets ``target_std·N(0, 1)``), then the lengthscales [state_dim] set.

    Used as an :attr:`RbfController.randomizer` (``draw(controller, seed)``), it is a
    plain description, so an agent saved with it (``PILCO.save``) draws its restarts the
    same way after ``PILCO.load``: a resumed run, or its diagnosis, searches as the run
    did.
    """

    def __init__(self, mean, std: float, lengthscales, angle_indices=(),
                 target_std: float = 0.1):
        self.mean = check_state_row(mean, int(np.size(mean)), "mean")[0]
        self.std = check_non_negative_float(std, "std")
        self.target_std = check_non_negative_float(target_std, "target_std")
        self.angle_indices = list(check_indices(angle_indices, self.mean.size, "angle_indices"))
        # one per policy input: the state's dimensions, an angle's as its sine and cosine
        self.lengthscales = check_entries(lengthscales, self.mean.size + len(self.angle_indices),
                                          "lengthscales")
        if not np.all(self.lengthscales > 0):
            raise ValueError(f"lengthscales must be positive, got {self.lengthscales}")

    def __call__(self, controller: "RbfController", seed: Optional[int]) -> None:
        from .features import angle_features

        if controller.state_dim != self.lengthscales.size:
            raise ValueError(f"this draw has {self.lengthscales.size} policy inputs, the "
                             f"controller {controller.state_dim}")
        features = (lambda x: angle_features(x, self.angle_indices)) \
            if self.angle_indices else None
        controller.place_near(self.mean, self.std, seed=seed, features=features,
                              target_std=self.target_std)
        for g in controller.models:
            g.kernel.lengthscales.assign(self.lengthscales)

    def to_dict(self) -> dict:
        """The draw as JSON-ready settings (:meth:`from_dict` rebuilds it)."""
        return dict(mean=self.mean.tolist(), std=self.std, lengthscales=self.lengthscales.tolist(),
                    angle_indices=list(self.angle_indices), target_std=self.target_std)

    @classmethod
    def from_dict(cls, settings: dict) -> "StartDraw":
        return cls(**settings)

    def __eq__(self, other) -> bool:
        return isinstance(other, StartDraw) and self.to_dict() == other.to_dict()

    def __repr__(self) -> str:
        return f"StartDraw({', '.join(f'{k}={v!r}' for k, v in self.to_dict().items())})"


class RbfController(_SquashedController):
    """Radial-basis-function policy, built as a deterministic GP (PILCO's ``congp``).

    Each action dimension is the posterior mean of a GP with a squared-exponential
    kernel whose "training inputs" are the basis-function centers [n, D] and whose
    "targets" [n, U] set the weights. The signal variance (1) and noise variance
    (1e-4) are fixed; centers, targets and lengthscales are trainable. Under a
    Gaussian state the policy's moments carry no model uncertainty.

    ``models[i]`` exposes ``.kernel.lengthscales``, ``.kernel.variance`` and
    ``.likelihood.variance`` of output i, like :class:`pilco.models.MGPR`.
    """

    def __init__(self, state_dim: int, control_dim: int, num_basis_functions: int,
                 max_action=1.0, squash: Optional[Callable] = squash_sin,
                 seed: Optional[int] = None):
        super().__init__(state_dim, control_dim, max_action, squash)
        self.num_basis_functions = check_positive_int(num_basis_functions, "num_basis_functions")
        rng = generator(seed)
        self.centers = Parameter(rng.standard_normal((self.num_basis_functions, self.state_dim)))
        self.targets = Parameter(
            0.1 * rng.standard_normal((self.num_basis_functions, self.control_dim))
        )
        self.models = [_PolicyOutput(self.state_dim) for _ in range(self.control_dim)]
        #: how :meth:`randomize` draws a fresh policy (a policy search's restarts): None
        #: for its own draw, or ``f(controller, seed)``, e.g. a task's initial policy; a
        #: :class:`StartDraw` is saved with the agent, other callables are not
        self.randomizer: Optional[Callable[["RbfController", Optional[int]], None]] = None

    def set_data(self, data):
        """Set centers [n, D] and targets [n, U] (``n`` must stay the same)."""
        X, Y = check_pair(data, "data", "(centers, targets)")
        X = check_matrix(as_2d_float(X, "centers"), (self.num_basis_functions, self.state_dim),
                         "centers")
        Y = check_matrix(as_2d_float(Y, "targets"),
                         (self.num_basis_functions, self.control_dim), "targets")
        self.centers.assign(X)
        self.targets.assign(Y)

    def hyperparameters(self):
        """Stacked hyperparameters: lengthscales [U, D], variance [U], noise [U]."""
        ell = tf.stack([tf.convert_to_tensor(g.kernel.lengthscales) for g in self.models])
        sf2 = tf.stack([tf.convert_to_tensor(g.kernel.variance) for g in self.models])
        sn2 = tf.stack([tf.convert_to_tensor(g.likelihood.variance) for g in self.models])
        return ell, sf2, sn2

    def factorize(self) -> gp_moments.Factorization:
        """Deterministic-GP pieces (beta, no K^-1) for the current parameters."""
        ell, sf2, sn2 = self.hyperparameters()
        return gp_moments.factorize(
            tf.convert_to_tensor(self.centers), tf.convert_to_tensor(self.targets),
            ell, sf2, sn2, with_inverse=False,
        )

    def prepare(self) -> gp_moments.Predictor:
        """State-independent prediction pieces for the current parameters, computed once
        per objective evaluation and shared by every step of a rollout."""
        return gp_moments.prepare(self.factorize())

    def _unsquashed(self, m, s, prepared: gp_moments.Predictor):
        return gp_moments.predict(m, s, prepared)

    def _unsquashed_points(self, x, prepared: gp_moments.Predictor):
        return gp_moments.point_means(x, prepared)

    def place_near(self, mean, std: float, seed: Optional[int] = None,
                   features: Optional[Callable[[np.ndarray], np.ndarray]] = None,
                   target_std: float = 0.1) -> None:
        """Start the policy around a state distribution, as the MATLAB release initialises
        its policies: centres ``features(mean + std·z)``, ``z ~ N(0, I)`` of shape [n, d],
        targets ``target_std·N(0, 1)`` [n, U] (drawn after the centres from the same
        generator); lengthscales stay as they are.

        ``mean`` [d] is a state (d = ``state_dim``), or, with ``features`` (a map from
        [n, d] states to [n, state_dim] policy inputs, e.g. an angle to its sine and
        cosine), a state of the features' domain.
        """
        check_callable(features, "features")
        dim = self.state_dim if features is None else int(np.size(mean))
        mean = check_state_row(mean, dim, "mean")[0]
        std = check_non_negative_float(std, "std")
        target_std = check_non_negative_float(target_std, "target_std")
        rng = generator(seed)
        states = mean[None, :] + std * rng.standard_normal((self.num_basis_functions, mean.size))
        centers = states if features is None else features(states)
        targets = target_std * rng.standard_normal((self.num_basis_functions, self.control_dim))
        self.set_data((centers, targets))

    def randomize(self, scale: float = 1.0, seed: Optional[int] = None):
        """Draw fresh centers ~ N(0, scale^2), targets ~ N(0, 0.1^2), lengthscales ~ 1;
        with a :attr:`randomizer` set, ``randomizer(self, seed)`` draws instead."""
        if self.randomizer is not None:
            self.randomizer(self, seed)
            return
        rng = generator(seed)
        self.centers.assign(scale * rng.standard_normal(self.centers.shape))
        self.targets.assign(0.1 * rng.standard_normal(self.targets.shape))
        for g in self.models:
            g.kernel.lengthscales.assign(1.0 + 0.1 * rng.standard_normal(self.state_dim))
