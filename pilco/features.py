"""The (sin, cos) feature map of angle dimensions, with NumPy alone.

PILCO's GP and policy never read an angle θ directly: they read ``(sin θ, cos θ)``. The
features of a state ``x [D]`` are the non-angle dimensions in order, then one
``(sin, cos)`` pair per angle in the order of ``angle_indices``:
``[x_other..., sin θ1, cos θ1, sin θ2, cos θ2, ...]``, of size ``F = D + A`` for A angles.
This module defines that layout once; :func:`pilco.angles.augment_state` computes the
moments of the same features under a Gaussian state. It imports only NumPy (it runs on
robots through :mod:`pilco.deploy`).
"""
from __future__ import annotations

from typing import List, Sequence

import numpy as np

__all__ = ["non_angle_indices", "angle_features"]


def non_angle_indices(state_dim: int, angle_indices: Sequence[int]) -> List[int]:
    """The state dimensions that are not angles, in order (the first features)."""
    angles = set(int(a) for a in angle_indices)
    return [d for d in range(state_dim) if d not in angles]


def angle_features(states: np.ndarray, angle_indices: Sequence[int]) -> np.ndarray:
    """States [N, D] -> features [N, D + A] (angles replaced by sin, cos pairs, appended).

    Columns after the first ``D`` (such as actions) are not part of the state: pass the
    state columns only. Without angles the input is returned unchanged.
    """
    states = np.asarray(states, dtype=np.float64)
    if not len(angle_indices):
        return states
    angles = states[:, list(angle_indices)]
    trig = np.stack([np.sin(angles), np.cos(angles)], axis=-1).reshape(len(states), -1)
    return np.concatenate([states[:, non_angle_indices(states.shape[1], angle_indices)], trig],
                          axis=1)
