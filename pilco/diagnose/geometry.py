"""Where a saturating cost puts the target, in task units (a reward's own
:class:`~pilco.reward_geometry.CostGeometry`): the distance the cost measures (the
gripper's or the pendulum tip's to the target) for states and for the state Gaussians of a
multi-step prediction, and how steep the cost is at a given distance."""
from __future__ import annotations

from typing import Tuple

import numpy as np

from ..reward_geometry import CostGeometry, geometry_of

__all__ = ["slope_ratio", "CostGeometry", "cost_geometry", "distance_moments"]


def slope_ratio(widths: float) -> float:
    """Slope of ``1 - exp(-d² / 2σ²)`` at ``d = widths · σ`` over its maximum (at d = σ)."""
    r = float(widths)
    return r * float(np.exp((1.0 - r * r) / 2.0))


#: the reward's own geometry (:func:`pilco.reward_geometry.geometry_of`); None without one
#: (the diagnosis then skips its distance and cost checks)
cost_geometry = geometry_of


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
