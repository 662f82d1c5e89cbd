"""Where a saturating reward puts its target, in task units: :class:`CostGeometry`.

A reward that measures a distance to a target (the gripper's to the point it reaches, the
pendulum tip's to upright) says so by a ``cost_geometry()`` method returning a
:class:`CostGeometry` (the rewards of :mod:`pilco.rewards` do; the protocol
:class:`pilco.protocols.Reward` makes it optional). The diagnosis reads its distance and
cost checks from it (:mod:`pilco.diagnose`); a reward without it is diagnosed without them.
The builders here derive a geometry from what the reward itself holds (its weight matrix
and target, or its width), so that a width set once in a task's settings is read back
from the reward in use, whatever schedule changed it since.
"""
from __future__ import annotations

import dataclasses
from typing import Callable, Optional, Sequence, Tuple

import numpy as np

__all__ = ["CostGeometry", "geometry_of", "quadratic_geometry", "tip_geometry",
           "weighted_geometry"]


@dataclasses.dataclass
class CostGeometry:
    """Where a saturating reward puts the target, in task units.

    ``offset(states [N, D]) -> [N, k]``: the vector from the target to the point the
    reward measures (the gripper, the pendulum tip), in the state's units when the reward's
    weight matrix is isotropic on the dimensions it reads (``width`` is then σ_c in those
    units), else in cost widths (``width`` 1); :meth:`distance` is its length. ``dims``: the
    state dimensions the reward reads; ``max_reward``: the reward at the target (cost =
    max_reward - reward).
    """

    width: float
    dims: Tuple[int, ...]
    offset: Callable[[np.ndarray], np.ndarray]
    max_reward: float = 1.0

    def distance(self, X) -> np.ndarray:
        """Task distance of states [N, D] -> [N]."""
        return np.linalg.norm(self.offset(X), axis=1)


def geometry_of(reward) -> Optional[CostGeometry]:
    """What the reward's own ``cost_geometry()`` says (the rewards of :mod:`pilco.rewards`
    and any reward of the user's that offers the method); None without it."""
    own = getattr(reward, "cost_geometry", None)
    return own() if callable(own) else None


def quadratic_geometry(W, t) -> CostGeometry:
    """The geometry of ``exp(-(x - t)ᵀ W (x - t) / 2)``: W [D, D] positive semi-definite,
    t [D]. Its width is σ_c where W is isotropic on its range (``I / σ_c²`` on the
    dimensions it reads), else 1 (distances in cost widths)."""
    W = np.asarray(W, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    lam, V = np.linalg.eigh(0.5 * (W + W.T))
    keep = lam > 1e-12 * max(lam.max(), 1e-300)
    iso = keep.any() and np.allclose(lam[keep], lam[keep][0], rtol=1e-6)
    width = float(1.0 / np.sqrt(lam[keep][0])) if iso else 1.0
    L = V[:, keep] * np.sqrt(lam[keep])  # W = L Lᵀ on its range

    def offset(X):
        return width * (np.asarray(X, dtype=np.float64) - t) @ L

    dims = tuple(int(i) for i in np.nonzero(np.any(W != 0, axis=1))[0])
    return CostGeometry(width, dims, offset)


def tip_geometry(length: float, width: float) -> CostGeometry:
    """The geometry of the cart-pole's tip reward: state ``[x, ẋ, θ̇, θ]`` (θ = 0 hanging),
    the tip at ``(x + l sin θ, -l cos θ)``, the target upright at ``(0, l)``."""
    length = float(length)

    def tip_offset(X):
        X = np.asarray(X, dtype=np.float64)
        return np.stack([X[:, 0] + length * np.sin(X[:, 3]),
                         -length * (np.cos(X[:, 3]) + 1.0)], axis=1)

    return CostGeometry(float(width), (0, 3), tip_offset)


def weighted_geometry(coefs: Sequence[float], parts: Sequence[Optional[CostGeometry]]
                      ) -> Optional[CostGeometry]:
    """The geometry of a weighted sum of rewards with geometries ``parts``: the widest
    positively weighted part's, its best reward the weighted sum of theirs. Parts with a
    negative weight are penalties (e.g. joint-limit bumps, ~0 at the target) and left out;
    None when a positively weighted part has no geometry, or none is positive."""
    positive = [(float(c), p) for c, p in zip(coefs, parts) if c > 0]
    if not positive or any(p is None for _, p in positive):
        return None
    widest = max((p for _, p in positive), key=lambda p: p.width)
    return dataclasses.replace(
        widest, max_reward=float(sum(c * p.max_reward for c, p in positive)))
