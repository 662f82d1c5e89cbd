"""Which state dimensions the dynamics model and the policy read, and which it predicts.

The MATLAB PILCO release describes this with index sets into the state (``plant.dyni``,
``plant.poli``, ``plant.dyno``, ``plant.difi``); :class:`StateLayout` is this library's
version of them, on the raw state ``x [D]`` and its features (:mod:`pilco.features`:
the non-angle dimensions in order, then one ``(sin, cos)`` pair per angle):

- ``angle_indices`` (MATLAB ``angi``): dimensions read through their ``(sin, cos)`` pair;
- ``context_indices``: dimensions that are constant through an episode (e.g. the target
  of a multi-task policy). The dynamics model does not predict them: the next state's
  context is the current one (same mean, same variance, cross-covariances with the
  other dimensions carried along). Every other dimension is predicted, as a difference
  ``x_{t+1} - x_t`` (MATLAB ``dyno`` = ``difi`` = the non-context dimensions);
- ``dynamics_indices`` (MATLAB ``dyni``): dimensions whose features the dynamics GPs
  read (then the action); default: every non-context dimension;
- ``policy_indices`` (MATLAB ``poli``): dimensions whose features the policy reads;
  default: every dimension, context included.

Unlike MATLAB's ``dyni`` and ``poli``, which index the augmented state
``[x, sin, cos]``, these sets name raw dimensions: an angle in a set contributes its
``(sin, cos)`` pair and never its raw value, as everywhere in this library. A selection
keeps the feature order. With the defaults (no context, every dimension read by both)
the layout is the identity and the rollout runs the code path of a plain agent.

Selections are applied as products with constant one-hot matrices (as
:mod:`pilco.angles` does): exact, and with a one-product gradient.
"""
from __future__ import annotations

from typing import Optional, Sequence

import numpy as np

from ..features import angle_features, non_angle_indices
from ..validation import check_indices

__all__ = ["StateLayout"]


def _feature_columns(state_dim: int, angle_indices: Sequence[int]) -> dict:
    """Feature columns of each state dimension: ``{d: (col,)}`` for a non-angle
    dimension, ``{a: (sin col, cos col)}`` for an angle (:mod:`pilco.features` layout)."""
    keep = non_angle_indices(state_dim, angle_indices)
    cols = {d: (k,) for k, d in enumerate(keep)}
    for i, a in enumerate(angle_indices):
        cols[a] = (len(keep) + 2 * i, len(keep) + 2 * i + 1)
    return cols


def _pick(columns: Sequence[int], size: int) -> Optional[np.ndarray]:
    """One-hot [size, len(columns)] selecting ``columns``; None when it is the identity."""
    if list(columns) == list(range(size)):
        return None
    return np.eye(size)[:, list(columns)]


class StateLayout:
    """Index sets of a state of dimension ``state_dim`` (see the module doc).

    Args:
        state_dim: D.
        angle_indices: A angle dimensions (features: F = D + A).
        context_indices: C context dimensions, not angles, fewer than D.
        dynamics_indices: dimensions the dynamics GPs read (None: the non-context ones).
        policy_indices: dimensions the policy reads (None: all of them; not empty).

    Bad indices raise ValueError (out of range, duplicates, overlapping sets) or
    TypeError (not integers) naming the argument, before TensorFlow sees them.

    Attributes (all tuples sorted, except ``angle_indices`` which keeps its order):
        predicted_indices: the E = D - C predicted dimensions (MATLAB ``dyno``).
        feature_dim: F = D + A.
        dynamics_features, policy_features: the feature columns each reads.
        gp_state_dim: Fd, the dynamics GP's state inputs (its inputs are Fd + U).
        policy_dim: Fp, the policy's input size (its ``state_dim``).
        dynamics_pick [F, Fd], policy_pick [F, Fp], output_place [E, D]: one-hot
            matrices (features -> selection, predicted outputs -> state), each None
            when it is the identity.
    """

    def __init__(self, state_dim: int, angle_indices: Sequence[int] = (),
                 context_indices: Sequence[int] = (),
                 dynamics_indices: Optional[Sequence[int]] = None,
                 policy_indices: Optional[Sequence[int]] = None):
        self.state_dim = D = int(state_dim)
        self.angle_indices = check_indices(angle_indices, D, "angle_indices")
        context = check_indices(context_indices, D, "context_indices")
        self.context_indices = tuple(sorted(context))
        both = sorted(set(context) & set(self.angle_indices))
        if both:
            raise ValueError(
                f"context_indices and angle_indices overlap at {both}: a context dimension "
                f"is read as its raw value, an angle as (sin, cos); context angles are not "
                f"supported")
        if len(context) == D:
            raise ValueError(f"context_indices name all {D} state dimensions: at least one "
                             f"must be predicted by the dynamics model")
        self.predicted_indices = tuple(d for d in range(D) if d not in set(context))
        if dynamics_indices is None:
            dynamics = self.predicted_indices
        else:
            dynamics = tuple(sorted(check_indices(dynamics_indices, D, "dynamics_indices")))
        if policy_indices is None:
            policy = tuple(range(D))
        else:
            policy = tuple(sorted(check_indices(policy_indices, D, "policy_indices")))
            if not policy:
                raise ValueError("policy_indices is empty: the policy must read at least one "
                                 "state dimension")
        self.dynamics_indices = dynamics
        self.policy_indices = policy
        self.feature_dim = F = D + len(self.angle_indices)
        cols = _feature_columns(D, self.angle_indices)
        self.dynamics_features = tuple(sorted(c for d in dynamics for c in cols[d]))
        self.policy_features = tuple(sorted(c for d in policy for c in cols[d]))
        self.gp_state_dim = len(self.dynamics_features)
        self.policy_dim = len(self.policy_features)
        self.dynamics_pick = _pick(self.dynamics_features, F)
        self.policy_pick = _pick(self.policy_features, F)
        E = len(self.predicted_indices)
        self.output_place = None if E == D else np.eye(D)[list(self.predicted_indices)]

    @property
    def num_outputs(self) -> int:
        """E, the number of dynamics GPs (one per predicted dimension)."""
        return len(self.predicted_indices)

    @property
    def is_identity(self) -> bool:
        """True when the GP inputs are the raw state (no angles, no context, every
        dimension read by the GP): raw transitions and GP data are then the same."""
        return (not self.angle_indices and self.dynamics_pick is None
                and self.output_place is None)

    def describe(self) -> str:
        """The non-default sets, for error messages: e.g. ``"context dimensions [10, 11]"``."""
        parts = []
        if self.angle_indices:
            parts.append(f"angle dimensions {list(self.angle_indices)}")
        if self.context_indices:
            parts.append(f"context dimensions {list(self.context_indices)}")
        if self.dynamics_indices != self.predicted_indices:
            parts.append(f"dynamics_indices {list(self.dynamics_indices)}")
        return ", ".join(parts)

    # -- NumPy maps of known states -------------------------------------------------------
    def gp_inputs(self, X: np.ndarray) -> np.ndarray:
        """Raw ``[x, u]`` rows [N, D + U] -> GP inputs [N, Fd + U] (the dynamics features
        of x, then u). Returns X itself when the layout is the identity."""
        X = np.asarray(X, dtype=np.float64)
        if self.is_identity:
            return X
        D = self.state_dim
        features = angle_features(X[:, :D], self.angle_indices)
        return np.concatenate([features[:, list(self.dynamics_features)], X[:, D:]], axis=1)

    def gp_targets(self, Y: np.ndarray) -> np.ndarray:
        """State differences [N, D] -> the GP targets [N, E] (the predicted dimensions)."""
        Y = np.asarray(Y, dtype=np.float64)
        if self.output_place is None:
            return Y
        return Y[:, list(self.predicted_indices)]

    def policy_inputs(self, states: np.ndarray) -> np.ndarray:
        """Known states [N, D] -> the policy's inputs [N, Fp]."""
        features = angle_features(np.asarray(states, dtype=np.float64), self.angle_indices)
        if self.policy_pick is None:
            return features
        return features[:, list(self.policy_features)]

    def to_state(self, values: np.ndarray) -> np.ndarray:
        """Per-output values [N, E] -> [N, D], zero in the context dimensions (whose
        difference is 0 with no uncertainty)."""
        values = np.asarray(values, dtype=np.float64)
        if self.output_place is None:
            return values
        return values @ self.output_place

    def settings(self) -> dict:
        """The constructor arguments that differ from their defaults (for agent files)."""
        out = {}
        if self.context_indices:
            out["context_indices"] = list(self.context_indices)
        if self.dynamics_indices != self.predicted_indices:
            out["dynamics_indices"] = list(self.dynamics_indices)
        if self.policy_indices != tuple(range(self.state_dim)):
            out["policy_indices"] = list(self.policy_indices)
        return out
