"""Evaluate an exported PILCO policy with NumPy alone: no TensorFlow or GPflow on the robot.

Export a trained agent's policy with ``agent.export_policy("policy.npz")`` (a controller
used without an agent: :func:`pilco.models.storage.export_policy`), copy the file to the
robot, then::

    from pilco.deploy import load_policy

    policy = load_policy("policy.npz")
    u = policy(x)          # x [D] -> u [U]
    U = policy(X)          # X [N, D] -> U [N, U]

The action is the one :meth:`pilco.models.PILCO.compute_action` returns: the policy's
prediction at a known state (zero variance), squashed with the squash function's moment
formula. This module imports only the standard library and NumPy.
"""
from __future__ import annotations

import json
import logging
import zipfile
import zlib
from typing import Optional, Sequence

import numpy as np

from .features import angle_features
from .validation import (
    as_2d_float,
    check_format_version,
    check_indices,
    check_matrix,
    check_option,
    check_path,
    check_positive_int,
    check_states,
)

__all__ = ["Policy", "load_policy"]

logger = logging.getLogger(__name__)

POLICY_FORMAT = "pilco-policy"
POLICY_VERSION = 1
META_KEY = "__meta__"

_KINDS = ("rbf", "linear")
_SQUASHES = ("sin", "sat", "none")


def _matrix(value, shape, name: str) -> np.ndarray:
    return check_matrix(value, shape, f"policy {name}")


class Policy:
    """A deterministic PILCO policy ``u = policy(x)`` evaluated with NumPy.

    Args:
        kind: ``"rbf"`` (RBF network / deterministic GP) or ``"linear"``.
        squash: ``"sin"``, ``"sat"`` or ``"none"``.
        state_dim: D, the size of the measured state.
        angle_indices: state dimensions that are angles; the policy reads the features
            ``[non-angle dims, sin θ1, cos θ1, sin θ2, cos θ2, ...]`` of size F = D + A.
        max_action: action bounds [U] (or a scalar).
        unsquashed_variance: variance of the unsquashed action at a known state (the
            moment-matching jitter of the RBF policy; 0 for the linear one).
        centers [n, F], beta [U, n], lengthscales [U, F], variance [U]: the RBF policy,
            ``v_u(z) = variance_u * sum_i beta_ui exp(-|(z - c_i) / ell_u|^2 / 2)``.
        W [U, F], b [1, U] (or [U]): the linear policy ``v(z) = W z + b``.
    """

    def __init__(self, kind: str, squash: str, state_dim: int, angle_indices: Sequence[int],
                 max_action, unsquashed_variance: float = 0.0, centers=None, beta=None,
                 lengthscales=None, variance=None, W=None, b=None):
        self.kind = check_option(kind, _KINDS, "policy kind")
        self.squash = check_option(squash, _SQUASHES, "policy squash")
        self.state_dim = D = check_positive_int(int(state_dim), "policy state_dim")
        self.angle_indices = check_indices(np.asarray(angle_indices).reshape(-1).tolist(), D,
                                           "policy angle_indices")
        self.feature_dim = F = D + len(self.angle_indices)
        self.unsquashed_variance = float(unsquashed_variance)
        if kind == "rbf":
            self.beta = as_2d_float(beta, "policy beta")
            U, n = self.beta.shape
            self.centers = _matrix(centers, (n, F), "centers")
            self.lengthscales = _matrix(lengthscales, (U, F), "lengthscales")
            self.variance = _matrix(variance, (U,), "variance")
            self._inv_ell = 1.0 / self.lengthscales
        else:
            U = as_2d_float(W, "policy W").shape[0]
            self.W = _matrix(W, (U, F), "W")
            self.b = _matrix(np.reshape(b, (1, -1)), (1, U), "b")
        self.control_dim = U
        e = np.asarray(max_action, dtype=np.float64).reshape(-1)
        self.max_action = _matrix(np.broadcast_to(e, (U,)) if e.size == 1 else e, (U,),
                                  "max_action")

    def __repr__(self) -> str:
        extra = f", {self.centers.shape[0]} basis functions" if self.kind == "rbf" else ""
        return (f"Policy({self.kind}, squash={self.squash}, state_dim={self.state_dim}, "
                f"control_dim={self.control_dim}, angle_indices={list(self.angle_indices)}"
                f"{extra})")

    # -- evaluation ------------------------------------------------------------------------
    def features(self, states: np.ndarray) -> np.ndarray:
        """Policy inputs: states [N, D] -> features [N, F] (angles as sin, cos pairs)."""
        return angle_features(states, self.angle_indices)

    def unsquashed(self, features: np.ndarray) -> np.ndarray:
        """Unsquashed actions: features [N, F] -> [N, U]."""
        if self.kind == "linear":
            return features @ self.W.T + self.b
        out = np.empty((len(features), self.control_dim))
        inp = self.centers[None, :, :] - features[:, None, :]  # [N, n, F]
        for u in range(self.control_dim):
            scaled = inp * self._inv_ell[u]
            k = np.exp(-0.5 * np.sum(scaled * scaled, axis=-1))  # [N, n]
            out[:, u] = self.variance[u] * (k @ self.beta[u])
        return out

    def squash_actions(self, v: np.ndarray) -> np.ndarray:
        """Expected squashed action for v ~ N(v, unsquashed_variance): [N, U] -> [N, U]."""
        e = self.max_action
        s = self.unsquashed_variance
        if self.squash == "sin":
            return e * np.exp(-0.5 * s) * np.sin(v)
        if self.squash == "sat":
            return e / 8.0 * (9.0 * np.exp(-0.5 * s) * np.sin(v)
                              + np.exp(-4.5 * s) * np.sin(3.0 * v))
        return v

    def __call__(self, state) -> np.ndarray:
        """The action at a measured state: [D] -> [U], or a batch [N, D] -> [N, U]."""
        x = check_states(state, self.state_dim, "state")
        single = x.ndim == 1
        X = x.reshape(1, -1) if single else x
        u = self.squash_actions(self.unsquashed(self.features(X)))
        return u[0] if single else u


#: what NumPy raises for an entry of an .npz it cannot read
_UNREADABLE = (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error)


def read_npz(path, kind: str):
    """Arrays and JSON metadata of a ``.npz`` written by pilco, or a clear ``ValueError``
    (``TypeError`` for a path that is not a path; ``FileNotFoundError`` when missing).

    Returns (arrays without the metadata entry, metadata dict). No pickles are loaded.
    """
    path = check_path(path)
    not_ours = f"{path} is not a {kind} file written by pilco"
    try:
        data = np.load(path, allow_pickle=False)
    except (FileNotFoundError, PermissionError):
        raise
    except (EOFError, ValueError, zipfile.BadZipFile) as err:
        raise ValueError(f"{not_ours}: it is truncated or not an .npz archive ({err})") from None
    except OSError as err:  # e.g. a directory
        raise ValueError(f"{not_ours}: {err}") from None
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise ValueError(f"{not_ours}: it holds a single array (.npy), not an .npz archive")
    try:
        with data:
            arrays = {k: data[k] for k in data.files}
    except _UNREADABLE as err:  # a damaged entry, or pickled objects
        raise ValueError(f"{not_ours}: its entries cannot be read ({err})") from None
    if META_KEY not in arrays:
        raise ValueError(f"{not_ours} (no {META_KEY!r} entry)")
    try:
        meta = json.loads(str(arrays.pop(META_KEY)))
    except ValueError:
        meta = None
    if not isinstance(meta, dict):
        raise ValueError(f"{not_ours}: its {META_KEY!r} entry is not a JSON object")
    return arrays, meta


def load_policy(path) -> Policy:
    """Read a policy file written by ``export_policy``; returns a callable :class:`Policy`.

    ``policy(state)`` maps a state [D] to an action [U] (or a batch [N, D] to [N, U]).
    A file that is not such a policy file (truncated, another kind of file, a format
    version this reader does not know) raises a ``ValueError`` saying so.
    """
    path = check_path(path)
    arrays, meta = read_npz(path, "PILCO policy")
    if meta.get("format") != POLICY_FORMAT:
        raise ValueError(f"{path} holds format {meta.get('format')!r}, expected "
                         f"{POLICY_FORMAT!r} (agent files are read with "
                         f"pilco.models.PILCO.load)")
    check_format_version(meta, path, "policy", POLICY_VERSION, "this reader")

    def get(key: str, default: Optional[np.ndarray] = None):
        if key in arrays:
            return arrays[key]
        if default is not None:
            return default
        raise ValueError(f"{path} is incomplete: entry {key!r} is missing")

    kind = meta.get("kind")
    common = dict(
        kind=kind, squash=meta.get("squash"), state_dim=int(get("state_dim")),
        angle_indices=get("angle_indices"), max_action=get("max_action"),
        unsquashed_variance=float(get("unsquashed_variance", np.array(0.0))),
    )
    if kind == "rbf":
        policy = Policy(centers=get("centers"), beta=get("beta"),
                        lengthscales=get("lengthscales"), variance=get("variance"), **common)
    elif kind == "linear":
        policy = Policy(W=get("W"), b=get("b"), **common)
    else:
        raise ValueError(f"{path}: unknown policy kind {kind!r}")
    logger.info("loaded %r from %s", policy, path)
    return policy
