"""Where a saturating cost puts the target, in task units: the distance the cost measures
(the gripper's or the pendulum tip's to the target) for states and for the state Gaussians
of a multi-step prediction, and how steep the cost is at a given distance."""
from __future__ import annotations

import dataclasses
from typing import Callable, Optional, Tuple

import numpy as np

__all__ = ["slope_ratio", "CostGeometry", "cost_geometry", "distance_moments"]


def slope_ratio(widths: float) -> float:
    """Slope of ``1 - exp(-d² / 2σ²)`` at ``d = widths · σ`` over its maximum (at d = σ)."""
    r = float(widths)
    return r * float(np.exp((1.0 - r * r) / 2.0))


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


def cost_geometry(reward) -> Optional[CostGeometry]:
    """The :class:`CostGeometry` of ``ExponentialReward``, ``CartPoleReward`` and
    ``CombinedRewards`` of them (the widest positively weighted part's; parts with a
    negative weight are penalties and left out); of a reward of another class, what its
    ``cost_geometry()`` method returns, if it has one; else None (the diagnosis then skips
    its distance and cost checks)."""
    from ..rewards import CartPoleReward, CombinedRewards, ExponentialReward

    own = getattr(reward, "cost_geometry", None)
    if callable(own):
        return own()

    if isinstance(reward, ExponentialReward):
        W, t = np.asarray(reward.W.numpy()), np.asarray(reward.t.numpy())[0]
        lam, V = np.linalg.eigh(0.5 * (W + W.T))
        keep = lam > 1e-12 * max(lam.max(), 1e-300)
        iso = keep.any() and np.allclose(lam[keep], lam[keep][0], rtol=1e-6)
        width = float(1.0 / np.sqrt(lam[keep][0])) if iso else 1.0
        L = V[:, keep] * np.sqrt(lam[keep])  # W = L L^T on its range

        def offset(X):
            return width * (np.asarray(X, dtype=np.float64) - t) @ L

        dims = tuple(int(i) for i in np.nonzero(np.any(W != 0, axis=1))[0])
        return CostGeometry(width, dims, offset)
    if isinstance(reward, CartPoleReward):
        length = float(reward.pendulum_length)

        def tip_offset(X):
            X = np.asarray(X, dtype=np.float64)
            # the tip at (x + l sin θ, -l cos θ), the target at (0, l)
            return np.stack([X[:, 0] + length * np.sin(X[:, 3]),
                             -length * (np.cos(X[:, 3]) + 1.0)], axis=1)

        return CostGeometry(float(reward.width), (0, 3), tip_offset)
    if isinstance(reward, CombinedRewards):
        # parts with a negative weight are penalties (e.g. joint-limit bumps), ~0 at the
        # target: the geometry and the best reward are those of the positive parts
        coefs = np.asarray(reward.coefs.numpy(), dtype=np.float64)
        parts = [(c, cost_geometry(r)) for c, r in zip(coefs, reward.base_rewards) if c > 0]
        if not parts or any(p is None for _, p in parts):
            return None
        widest = max((p for _, p in parts), key=lambda p: p.width)
        return dataclasses.replace(
            widest, max_reward=float(sum(c * p.max_reward for c, p in parts)))
    return None


def distance_moments(geometry: CostGeometry, M: np.ndarray, S: np.ndarray,
                     samples: int = 4000, seed: int = 0) -> Tuple[np.ndarray, np.ndarray]:
    """Mean and std [T] of the task distance under the Gaussians ``N(M[t], S[t])``
    (M [T, D], S [T, D, D]), from ``samples`` draws (the same normal draws at every step)."""
    z = np.random.default_rng(seed).standard_normal((samples, M.shape[1]))
    mean, std = np.empty(len(M)), np.empty(len(M))
    for i, (m, s) in enumerate(zip(M, S)):
        w, V = np.linalg.eigh(0.5 * (s + s.T))
        d = geometry.distance(m + (z * np.sqrt(np.clip(w, 0.0, None))) @ V.T)
        mean[i], std[i] = d.mean(), d.std()
    return mean, std
