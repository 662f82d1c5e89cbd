"""State constraints with a closed-form probability of violation under a Gaussian state.

The moment-matched prediction gives, at every step of the horizon, a Gaussian state
x ~ N(m, s); a constraint on the state then has a probability of being violated that is
known in closed form and differentiable in (m, s), so that a policy search can weigh it
(Safe PILCO: Polymenakos, Abate and Roberts, AAMAS 2019). Each constraint has
``violation(m [1, D], s [D, D]) -> p []``:

- :class:`HalfSpace`: violated where ``a·x > b``. ``a·x`` is Gaussian with mean ``a·m`` and
  variance ``aᵀ s a``, so ``p = Φ((a·m - b) / sqrt(aᵀ s a))``, exact.
- :class:`Box`: violated where some dimension ``x_d`` of ``dims`` leaves ``[low_d, high_d]``
  (either bound may be infinite). Per dimension exact:
  ``p_d = Φ((low_d - m_d) / σ_d) + Φ((m_d - high_d) / σ_d)``. Leaving the box is the union
  of the dimensions' events, so ``combine="union"`` gives the bound ``min(1, Σ p_d)``,
  never below the true probability (the conservative default), and
  ``combine="independent"`` gives ``1 - Π (1 - p_d)``, exact when the dimensions are
  uncorrelated and below the union bound always. With one dimension both are exact.
- :class:`Region`: violated where every x_d of ``dims`` lies in its interval at once (a
  region to stay out of, e.g. two cars in a crossing together): exact for one dimension;
  across several the bound ``min_d P(inside_d)`` (never below the truth, the default) or the
  product ``Π P(inside_d)``, exact when the dimensions are uncorrelated.
- :class:`OnMap`: any of them on ``A x + c`` (a Gaussian of mean ``A m + c`` and covariance
  ``A s Aᵀ``, exact), e.g. the reacher's gripper minus a point, or a sum of states.
- :class:`AngleHalfSpace`: ``a_s sin θ + a_c cos θ ≤ b`` on an angle θ of the state (e.g. a
  pendulum tip's height ``-l cos θ`` below a ceiling): the left side is ``R sin(θ + φ)``,
  so the violation is θ in one interval per turn, and its probability a sum of normal
  differences over the turns, exact. (A box on θ itself is a :class:`Box`: θ is a
  dimension of the Gaussian state. A constraint mixing an angle's sine or cosine with
  other dimensions, e.g. a cart-pole tip's horizontal position ``x + l sin θ``, is not
  Gaussian and not offered.)

:func:`horizon_risk` combines the steps' probabilities ``p_t`` into the probability of a
violation anywhere on the horizon: ``"independent"``, ``1 - Π (1 - p_t)`` (Safe PILCO's
rule; the steps of one trajectory are not independent, so this is not a bound) or
``"union"``, ``min(1, Σ p_t)`` (an upper bound on the true probability whatever the steps'
dependence).

Probabilities below ~1e-300 underflow to 0; the normal's tail is computed with ``erfc``,
so small probabilities keep their relative precision.
"""
from __future__ import annotations

import math
from typing import Any, Dict, Sequence

import gpflow
import numpy as np
import tensorflow as tf
from check_shapes import check_shapes
from gpflow.config import default_float

from .validation import (check_entries, check_indices, check_matrix, check_non_negative_float,
                         check_positive_int)

__all__ = ["HalfSpace", "AngleHalfSpace", "Box", "Region", "OnMap", "ViolationPenalty",
           "horizon_risk", "step_violations", "violated_states", "normal_tail", "constraint_config",
           "constraint_from_config", "COMBINE"]

#: the ways of combining per-dimension or per-step probabilities
COMBINE = ("union", "independent")


def normal_tail(z):
    """``P(Z > z)`` for a standard normal Z: ``erfc(z / √2) / 2`` (accurate far into the
    tail, where ``1 - Φ(z)`` would round to 0)."""
    return 0.5 * tf.math.erfc(z / math.sqrt(2.0))


def _combine(p, combine: str):
    """``p`` [K] of K events -> the probability of any of them (``COMBINE``)."""
    if combine == "union":
        return tf.minimum(tf.reduce_sum(p), tf.constant(1.0, p.dtype))
    return 1.0 - tf.reduce_prod(1.0 - p)


def _check_combine(combine: str) -> str:
    if combine not in COMBINE:
        raise ValueError(f"combine must be one of {', '.join(map(repr, COMBINE))}, got "
                         f"{combine!r}")
    return combine


class HalfSpace:
    """``a·x ≤ b`` must hold; ``violation`` is ``P(a·x > b)``, exact.

    ``a`` [D] (not all zero), ``b`` a number; ``state_dim`` D.
    """

    def __init__(self, state_dim: int, a, b: float):
        self.state_dim = D = check_positive_int(state_dim, "state_dim")
        a = check_entries(a, D, "a")
        if not np.any(a != 0):
            raise ValueError("a must not be all zero: a half-space a·x <= b needs a direction")
        self.a = tf.constant(a.reshape(D, 1), dtype=default_float())
        self.b = float(check_entries([b], 1, "b")[0])

    def get_config(self) -> Dict[str, Any]:
        """The arguments that rebuild it (:func:`constraint_from_config`)."""
        return {"state_dim": self.state_dim, "a": self.a.numpy()[:, 0].tolist(), "b": self.b}

    def breaks(self, X) -> np.ndarray:
        """Whether each known state of ``X`` [N, D] breaks it (``a·x > b``): bool [N]."""
        return np.asarray(X, dtype=np.float64) @ self.a.numpy()[:, 0] > self.b

    @check_shapes("m: [1, D]", "s: [D, D]", "return: []")
    def violation(self, m, s):
        """``P(a·x > b)`` for x ~ N(m, s)."""
        mean = tf.matmul(m, self.a)[0, 0]
        var = tf.matmul(self.a, tf.matmul(s, self.a), transpose_a=True)[0, 0]
        # a state known exactly (var 0): the violation is certain or impossible
        std = tf.sqrt(tf.maximum(var, tf.constant(1e-300, var.dtype)))
        return normal_tail((self.b - mean) / std)


class AngleHalfSpace:
    """``a_sin · sin θ + a_cos · cos θ ≤ b`` must hold for the angle ``θ = x[angle]``;
    ``violation`` is its probability of failing, exact (module docstring).

    With ``R = hypot(a_sin, a_cos)`` and ``φ = atan2(a_cos, a_sin)`` the left side is
    ``R sin(θ + φ)``, above ``b`` exactly when θ lies in ``(α, β) + 2πk`` for some integer
    k, ``α = asin(b / R) - φ``, ``β = π - asin(b / R) - φ``; for θ ~ N(μ, σ²) the
    probability is ``Σ_k Φ((β + 2πk - μ) / σ) - Φ((α + 2πk - μ) / σ)``, summed over the
    ``2·turns + 1`` turns nearest μ (the rest of the mass, beyond ``turns`` turns either
    way, counted at the interval's share of a turn). ``|b| < R`` is required: otherwise the
    constraint always or never holds.
    """

    def __init__(self, state_dim: int, angle: int, a_sin: float, a_cos: float, b: float,
                 turns: int = 8):
        self.state_dim = D = check_positive_int(state_dim, "state_dim")
        self.angle = check_indices([angle], D, "angle")[0]
        self.a_sin, self.a_cos, self.b = (float(v) for v in
                                          check_entries([a_sin, a_cos, b], 3, "a_sin, a_cos, b"))
        self.turns = check_positive_int(turns, "turns")
        R = math.hypot(self.a_sin, self.a_cos)
        if not abs(self.b) < R:
            raise ValueError(f"|b| must be below hypot(a_sin, a_cos) = {R:.6g}, got b = "
                             f"{self.b}: otherwise a_sin sin θ + a_cos cos θ <= b always or "
                             f"never holds")
        phi = math.atan2(self.a_cos, self.a_sin)
        self._low = math.asin(self.b / R) - phi  # α
        self._width = math.pi - 2.0 * math.asin(self.b / R)  # β - α, in (0, 2π)

    def get_config(self) -> Dict[str, Any]:
        """The arguments that rebuild it (:func:`constraint_from_config`)."""
        return {"state_dim": self.state_dim, "angle": self.angle, "a_sin": self.a_sin,
                "a_cos": self.a_cos, "b": self.b, "turns": self.turns}

    def breaks(self, X) -> np.ndarray:
        """Whether each known state of ``X`` [N, D] breaks it: bool [N]."""
        theta = np.asarray(X, dtype=np.float64)[:, self.angle]
        return self.a_sin * np.sin(theta) + self.a_cos * np.cos(theta) > self.b

    @check_shapes("m: [1, D]", "s: [D, D]", "return: []")
    def violation(self, m, s):
        """``P(a_sin sin θ + a_cos cos θ > b)`` for x ~ N(m, s)."""
        mu, var = m[0, self.angle], s[self.angle, self.angle]
        std = tf.sqrt(tf.maximum(var, tf.constant(1e-300, var.dtype)))
        two_pi = 2.0 * math.pi
        # the turn whose interval is nearest the mean (a constant for the gradient)
        centre = tf.stop_gradient(tf.round((mu - self._low - 0.5 * self._width) / two_pi))
        k = centre + tf.range(-self.turns, self.turns + 1, dtype=mu.dtype)  # [2K+1]
        lo = (self._low + two_pi * k - mu) / std
        hi = lo + self._width / std
        # Φ(hi) - Φ(lo), from the tail on the side away from the mean (precise far out)
        upper = normal_tail(lo) - normal_tail(hi)
        lower = normal_tail(-hi) - normal_tail(-lo)
        inside = tf.reduce_sum(tf.where(lo > 0, upper, lower))
        # outside the summed whole turns, from the first interval's start to one turn
        # after the last's
        beyond = normal_tail(-lo[0]) + normal_tail(lo[-1] + two_pi / std)
        return inside + beyond * (self._width / two_pi)


class Box:
    """``low_d ≤ x_d ≤ high_d`` must hold for every d of ``dims``; ``violation`` is the
    probability that some x_d leaves its interval, combined over the dimensions by
    ``combine`` (module docstring: ``"union"`` a bound, ``"independent"``).

    ``low``, ``high``: one number per dimension of ``dims`` (``-inf``/``inf`` for no bound;
    ``low < high``).
    """

    def __init__(self, state_dim: int, dims: Sequence[int], low, high,
                 combine: str = "union"):
        self.state_dim = D = check_positive_int(state_dim, "state_dim")
        self.dims = check_indices(dims, D, "dims")
        k = len(self.dims)
        if k == 0:
            raise ValueError("dims must name at least one state dimension")
        low = np.asarray(low, dtype=np.float64).reshape(-1)
        high = np.asarray(high, dtype=np.float64).reshape(-1)
        for name, v in (("low", low), ("high", high)):
            if v.size != k:
                raise ValueError(f"{name} must have one entry per dimension of dims ({k}), "
                                 f"got {v.size}")
            if np.any(np.isnan(v)):
                raise ValueError(f"{name} must not hold NaN")
        if not np.all(low < high):
            raise ValueError(f"low must be below high in every dimension, got low {low} and "
                             f"high {high}")
        self.combine = _check_combine(combine)
        self.low, self.high = low, high
        self._has_low, self._has_high = np.isfinite(low), np.isfinite(high)
        self._low = np.where(self._has_low, low, 0.0)
        self._high = np.where(self._has_high, high, 0.0)
        self._pick = tf.constant(np.eye(D)[:, list(self.dims)], dtype=default_float())

    def get_config(self) -> Dict[str, Any]:
        """The arguments that rebuild it (:func:`constraint_from_config`; infinite bounds
        as the strings ``"-inf"``/``"inf"``)."""
        return {"state_dim": self.state_dim, "dims": list(self.dims),
                "low": [_number(v) for v in self.low], "high": [_number(v) for v in self.high],
                "combine": self.combine}

    def breaks(self, X) -> np.ndarray:
        """Whether each known state of ``X`` [N, D] is outside the box: bool [N]."""
        Xd = np.asarray(X, dtype=np.float64)[:, list(self.dims)]
        return np.any((Xd < self.low) | (Xd > self.high), axis=1)

    @check_shapes("m: [1, D]", "s: [D, D]", "return: []")
    def violation(self, m, s):
        """The probability that x ~ N(m, s) leaves the box (by ``combine``)."""
        return _combine(self.violations(m, s), self.combine)

    @check_shapes("m: [1, D]", "s: [D, D]", "return: [K]")
    def violations(self, m, s):
        """``p_d`` [K] of each dimension of ``dims`` alone, exact."""
        md = tf.matmul(m, self._pick)[0]
        var = tf.linalg.diag_part(tf.matmul(self._pick, tf.matmul(s, self._pick),
                                            transpose_a=True))
        std = tf.sqrt(tf.maximum(var, tf.constant(1e-300, var.dtype)))
        zero = tf.zeros_like(md)
        # an infinite bound is never crossed: its term is 0 (computed at a finite stand-in)
        below = tf.where(self._has_low, normal_tail((md - self._low) / std), zero)
        above = tf.where(self._has_high, normal_tail((self._high - md) / std), zero)
        return tf.minimum(below + above, tf.ones_like(md))


class Region:
    """A region the state must stay out of: ``low_d ≤ x_d ≤ high_d`` for every d of
    ``dims`` at once (e.g. two cars inside a crossing together). ``violation`` is the
    probability of being inside: exact for one dimension; across several, by ``combine``:
    ``"bound"`` (the default) ``min_d P(inside_d)``, never below the truth (being inside all
    intervals implies being inside each), or ``"independent"`` ``Π P(inside_d)``, exact when
    the dimensions are uncorrelated. Bounds as :class:`Box` (finite here: a region with an
    open side is a :class:`HalfSpace` or a :class:`Box`)."""

    COMBINE = ("bound", "independent")

    def __init__(self, state_dim: int, dims: Sequence[int], low, high,
                 combine: str = "bound"):
        if combine not in self.COMBINE:
            raise ValueError(f"combine must be 'bound' or 'independent', got {combine!r}")
        low = check_entries(low, len(list(dims)), "low")
        high = check_entries(high, len(list(dims)), "high")
        self._box = Box(state_dim, dims, low, high)
        self.state_dim, self.dims = self._box.state_dim, self._box.dims
        self.low, self.high, self.combine = low, high, combine

    def breaks(self, X) -> np.ndarray:
        """Whether each known state of ``X`` [N, D] is inside the region: bool [N]."""
        return ~self._box.breaks(X)

    @check_shapes("m: [1, D]", "s: [D, D]", "return: []")
    def violation(self, m, s):
        """The probability that x ~ N(m, s) is inside the region (by ``combine``)."""
        inside = 1.0 - self._box.violations(m, s)
        if self.combine == "independent":
            return tf.reduce_prod(inside)
        return tf.reduce_min(inside)

    def get_config(self) -> Dict[str, Any]:
        """The arguments that rebuild it (:func:`constraint_from_config`)."""
        return {"state_dim": self.state_dim, "dims": list(self.dims), "low": self.low.tolist(),
                "high": self.high.tolist(), "combine": self.combine}


class OnMap:
    """A constraint on ``y = A x + c`` (``A`` [K, D], ``c`` [K]): ``violation(m, s)`` is
    ``constraint.violation(A m + c, A s Aᵀ)``, exact for an exact ``constraint``."""

    def __init__(self, state_dim: int, A, constraint, c=None):
        self.state_dim = D = check_positive_int(state_dim, "state_dim")
        A = np.asarray(A, dtype=np.float64)
        if A.ndim != 2:
            raise ValueError(f"A must be a matrix [K, {D}], got shape {A.shape}")
        A = check_matrix(A, (A.shape[0], D), "A")
        K = A.shape[0]
        if getattr(constraint, "state_dim", None) != K:
            raise ValueError(f"the constraint must read {K} dimensions (A's rows), it reads "
                             f"{getattr(constraint, 'state_dim', None)}")
        c = np.zeros(K) if c is None else check_entries(c, K, "c")
        self.A = tf.constant(A, dtype=default_float())
        self.c = tf.constant(c.reshape(1, K), dtype=default_float())
        self.constraint = constraint

    def get_config(self) -> Dict[str, Any]:
        """The arguments that rebuild it, the inner constraint's included."""
        return {"state_dim": self.state_dim, "A": self.A.numpy().tolist(),
                "constraint": constraint_config(self.constraint),
                "c": self.c.numpy()[0].tolist()}

    def breaks(self, X) -> np.ndarray:
        """Whether each known state of ``X`` [N, D] breaks the constraint on ``A x + c``."""
        Y = np.asarray(X, dtype=np.float64) @ self.A.numpy().T + self.c.numpy()
        return self.constraint.breaks(Y)

    @check_shapes("m: [1, D]", "s: [D, D]", "return: []")
    def violation(self, m, s):
        """The constraint's violation probability under the mapped Gaussian."""
        my = tf.matmul(m, self.A, transpose_b=True) + self.c
        sy = tf.matmul(self.A, tf.matmul(s, self.A, transpose_b=True))
        return self.constraint.violation(my, 0.5 * (sy + tf.transpose(sy)))


@check_shapes("p: [T]", "return: []")
def horizon_risk(p, combine: str = "independent"):
    """The probability of a violation at some step from the steps' ``p`` [T]: Safe PILCO's
    ``1 - Π (1 - p_t)`` (``"independent"``) or the bound ``min(1, Σ p_t)`` (``"union"``)."""
    return _combine(tf.convert_to_tensor(p, dtype=default_float()),
                    _check_combine(combine))


@check_shapes("M: [T, D]", "S: [T, D, D]", "return: [T]")
def step_violations(constraint, M, S) -> np.ndarray:
    """Each step's violation probability of a predicted trajectory (``M`` [T, D], ``S``
    [T, D, D], e.g. :meth:`pilco.models.PILCO.predict_trajectory`), as a NumPy array."""
    M = np.asarray(M, dtype=np.float64)
    S = np.asarray(S, dtype=np.float64)
    return np.array([float(constraint.violation(tf.constant(M[t:t + 1]), tf.constant(S[t])))
                     for t in range(len(M))])


def violated_states(constraint, states) -> np.ndarray:
    """Which of the known states ``states`` [T, D] violate ``constraint``: a boolean array
    [T] (the constraint's ``breaks``, else its violation at a zero covariance, certain or
    impossible)."""
    X = np.atleast_2d(np.asarray(states, dtype=np.float64))
    breaks = getattr(constraint, "breaks", None)
    if breaks is not None:
        return np.asarray(breaks(X), dtype=bool)
    return step_violations(constraint, X, np.zeros((len(X),) + X.shape[1:2] * 2)) > 0.5


class ViolationPenalty(gpflow.base.Module):
    """A reward that is minus ``weight`` times a constraint's violation, so that a policy
    search on ``CombinedRewards(D, [task_reward, ViolationPenalty(c, mu)])`` maximises the
    expected return minus ``mu`` times the horizon's risk, in the one compiled objective.

    Summed over the steps, ``form="union"`` (the default) subtracts ``mu Σ p_t``, the union
    bound on the horizon's risk (uncapped); ``form="independent"`` subtracts
    ``mu Σ -log(1 - p_t) = -mu log(1 - risk)`` with the risk by the independent rule
    (p_t capped at 1 - 1e-12), which grows without bound as the risk nears 1. ``weight`` is
    a non-trainable ``gpflow.Parameter``: assigning it (Safe PILCO's ``mu`` going up or down)
    keeps the compiled objective. The variance of this reward is 0 (it is a function of the
    state's distribution, not of the state)."""

    FORMS = ("union", "independent")

    def __init__(self, constraint, weight: float = 1.0, form: str = "union"):
        super().__init__()
        if not callable(getattr(constraint, "violation", None)):
            raise TypeError(f"constraint must have violation(m, s), got "
                            f"{type(constraint).__name__}")
        if form not in self.FORMS:
            raise ValueError(f"form must be 'union' or 'independent', got {form!r}")
        self.state_dim = check_positive_int(getattr(constraint, "state_dim", None),
                                            "constraint.state_dim")
        self.constraint = constraint
        self.form = form
        self.weight = gpflow.Parameter(check_non_negative_float(weight, "weight"),
                                       trainable=False)

    @check_shapes("m: [1, D]", "s: [D, D]", "return[0]: [1, 1]", "return[1]: [1, 1]")
    def moments(self, m, s):
        """``(-weight · p, 0)`` (union) or ``(weight · log(1 - p), 0)`` (independent)."""
        p = self.constraint.violation(m, s)
        if self.form == "independent":
            cost = -tf.math.log1p(-tf.minimum(p, tf.constant(1.0 - 1e-12, p.dtype)))
        else:
            cost = p
        mean = tf.reshape(-tf.convert_to_tensor(self.weight) * cost, (1, 1))
        return mean, tf.zeros_like(mean)

    def get_config(self) -> Dict[str, Any]:
        """The arguments that rebuild it (``weight`` comes back from the agent file)."""
        return {"constraint": constraint_config(self.constraint), "weight": 1.0,
                "form": self.form}

    @classmethod
    def from_config(cls, config: Dict[str, Any]) -> "ViolationPenalty":
        return cls(constraint_from_config(config["constraint"]), config.get("weight", 1.0),
                   config.get("form", "union"))


#: the constraint classes :func:`constraint_from_config` rebuilds, by name
_CLASSES = {"HalfSpace": HalfSpace, "AngleHalfSpace": AngleHalfSpace, "Box": Box,
            "Region": Region, "OnMap": OnMap}


def _number(v: float):
    return float(v) if np.isfinite(v) else ("inf" if v > 0 else "-inf")


def constraint_config(constraint) -> Dict[str, Any]:
    """``{"class": name, "config": ...}`` of a constraint of this module (JSON-ready)."""
    name = type(constraint).__name__
    if _CLASSES.get(name) is not type(constraint):
        raise TypeError(f"only the constraints of pilco.constraints can be stored, got {name}")
    return {"class": name, "config": constraint.get_config()}


def constraint_from_config(spec: Dict[str, Any]):
    """The constraint :func:`constraint_config` described."""
    cls = _CLASSES.get(spec.get("class"))
    if cls is None:
        raise ValueError(f"unknown constraint class {spec.get('class')!r}; known: "
                         f"{', '.join(_CLASSES)}")
    config = dict(spec["config"])
    if cls is Box:
        config["low"] = [float(v) for v in config["low"]]
        config["high"] = [float(v) for v in config["high"]]
    if cls is OnMap:
        config["constraint"] = constraint_from_config(config["constraint"])
    return cls(**config)
