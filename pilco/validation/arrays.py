"""Arrays of numbers: finite float64 values of the expected rank, shape or size.

The base of the other checks (:func:`_to_numpy` refuses strings, booleans, complex
numbers and ragged lists; :func:`_check_finite` names the first NaN or inf entry), the
regression data sets ``(X, Y)`` and the numeric settings given as arrays (action bounds,
weight matrices, noise factors).
"""
from __future__ import annotations

from typing import Optional, Tuple

import numpy as np

__all__ = [
    "as_2d_float",
    "check_matrix",
    "check_entries",
    "check_columns",
    "check_pair",
    "check_data",
    "check_transitions",
    "check_noise_scales",
    "check_max_action",
    "check_weight_matrix",
]


def _to_numpy(x, name: str) -> np.ndarray:
    if isinstance(x, (str, bytes)) or x is None:
        raise TypeError(f"{name} must be an array of numbers, got {type(x).__name__}")
    if callable(getattr(x, "numpy", None)):  # TensorFlow tensors, variables, parameters
        x = x.numpy()
    try:
        raw = np.asarray(x)
    except (TypeError, ValueError) as err:  # e.g. ragged nested lists
        raise TypeError(f"{name} must be an array of numbers: {err}") from None
    kind = {"b": "booleans", "U": "strings", "S": "strings", "c": "complex numbers"}.get(
        raw.dtype.kind)
    if kind is not None:
        raise TypeError(f"{name} must be an array of (real) numbers, got {kind}")
    try:
        arr = raw.astype(np.float64)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name} must be an array of numbers: {err}") from None
    return arr


def _check_finite(arr: np.ndarray, name: str) -> None:
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))
        kind = "NaN" if np.any(np.isnan(arr)) else "inf"
        raise ValueError(
            f"{name} contains {kind} values ({len(bad)} entries, first at index "
            f"{tuple(int(i) for i in bad[0])})"
        )


def as_2d_float(x, name: str, allow_empty: bool = False) -> np.ndarray:
    """A finite float64 array of rank 2, or a clear error. Shape: [N, K] -> [N, K]."""
    arr = _to_numpy(x, name)
    if arr.ndim != 2:
        raise ValueError(
            f"{name} must be 2-D [rows, columns], got shape {arr.shape}"
            + (" (reshape a single row with x.reshape(1, -1) or a column with x.reshape(-1, 1))"
               if arr.ndim == 1 else "")
        )
    if arr.size == 0 and not allow_empty:
        raise ValueError(f"{name} is empty (shape {arr.shape})")
    _check_finite(arr, name)
    return arr


def check_matrix(value, shape: Tuple[int, ...], name: str) -> np.ndarray:
    """A finite float64 array of exactly ``shape``, or a clear error."""
    arr = _to_numpy(value, name)
    if arr.shape != tuple(shape):
        raise ValueError(f"{name} must have shape {tuple(shape)}, got {arr.shape}")
    _check_finite(arr, name)
    return arr


def check_entries(value, size: int, name: str, label: Optional[str] = None) -> np.ndarray:
    """``size`` finite numbers (any shape with that many entries), flattened to [size]."""
    arr = _to_numpy(value, name).reshape(-1)
    if arr.size != size:
        raise ValueError(f"{label or name} must have {size} entries, got {arr.size}")
    _check_finite(arr, name)
    return arr


def check_columns(x, columns: int, name: str, meaning: str = "") -> np.ndarray:
    """A finite float64 matrix [N, columns], or a clear error."""
    arr = as_2d_float(x, name)
    if arr.shape[1] != columns:
        raise ValueError(f"{name} must have {columns} columns{' ' + meaning if meaning else ''}, "
                         f"got {arr.shape[1]}")
    return arr


def check_pair(data, name: str, what: str = "(X, Y)"):
    """A pair (tuple or list of two), or a clear error."""
    if not isinstance(data, (tuple, list)) or len(data) != 2:
        raise TypeError(f"{name} must be a pair {what}, got {type(data).__name__}")
    return data


def check_data(data, name: str = "data", x_dim: Optional[int] = None,
               y_dim: Optional[int] = None) -> Tuple[np.ndarray, np.ndarray]:
    """Check a regression data set ``(X [N, Din], Y [N, E])`` and return it as float64."""
    check_pair(data, name)
    X = as_2d_float(data[0], f"{name} X")
    Y = as_2d_float(data[1], f"{name} Y")
    if X.shape[0] != Y.shape[0]:
        raise ValueError(
            f"{name}: X and Y must have the same number of rows, got {X.shape[0]} and {Y.shape[0]}"
        )
    if x_dim is not None and X.shape[1] != x_dim:
        raise ValueError(f"{name} X must have {x_dim} columns, got {X.shape[1]}")
    if y_dim is not None and Y.shape[1] != y_dim:
        raise ValueError(f"{name} Y must have {y_dim} columns, got {Y.shape[1]}")
    return X, Y


def check_transitions(data, name: str = "data") -> Tuple[np.ndarray, np.ndarray]:
    """Raw transitions ``(X [N, D + U], Y [N, D])`` with at least one action column."""
    X, Y = check_data(data, name)
    if X.shape[1] <= Y.shape[1]:
        raise ValueError(
            f"{name} X must hold [state, action] with {Y.shape[1]} state columns (from Y) and "
            f"at least one action column, got {X.shape[1]} columns"
        )
    return X, Y


def check_noise_scales(value, size: int, name: str = "noise_scales",
                       outputs: Optional[int] = None) -> np.ndarray:
    """Noise-variance factors: ``size`` finite positive numbers, one per transition
    ``[size]``, or, given ``outputs``, one per output and transition ``[outputs, size]``
    (returned in the shape given); None gives ones ``[size]``."""
    if value is None:
        return np.ones(size)
    arr = _to_numpy(value, name)
    if arr.ndim == 2 and outputs is not None:
        if arr.shape != (outputs, size):
            raise ValueError(f"{name} per output must have shape [outputs, transitions] = "
                             f"[{outputs}, {size}], got {arr.shape}")
        _check_finite(arr, name)
    elif arr.ndim != 1:
        shapes = "1-D [transitions]" + (" or 2-D [outputs, transitions]"
                                        if outputs is not None else "")
        raise ValueError(f"{name} must be {shapes}, got shape {arr.shape}")
    else:
        arr = check_entries(arr, size, name, f"{name} (one factor per transition)")
    if np.any(arr <= 0):
        at = np.argwhere(arr <= 0)[0]
        raise ValueError(f"{name} must be positive (factors of the noise variance), got "
                         f"{arr[tuple(at)]!r} at index "
                         f"{int(at[0]) if arr.ndim == 1 else tuple(int(i) for i in at)}")
    return arr


def check_max_action(max_action, control_dim: int) -> np.ndarray:
    """Action bounds as a float64 vector [control_dim] of non-negative finite values (a
    bound of 0: the policy never moves that action, e.g. a joint known to be stuck)."""
    arr = _to_numpy(max_action, "max_action").reshape(-1)
    if arr.size == 1:
        arr = np.repeat(arr, control_dim)
    if arr.size != control_dim:
        raise ValueError(
            f"max_action must be a scalar or have {control_dim} entries, got {arr.size}"
        )
    _check_finite(arr, "max_action")
    if np.any(arr < 0):
        raise ValueError(f"max_action must be non-negative, got {arr}")
    return arr


def check_weight_matrix(W, dim: int, name: str = "W") -> np.ndarray:
    """A finite symmetric positive semi-definite weight matrix [dim, dim]."""
    W = check_matrix(W, (dim, dim), name)
    if not np.allclose(W, W.T):
        raise ValueError(f"{name} must be symmetric")
    if np.min(np.linalg.eigvalsh(W)) < -1e-10 * max(1.0, np.abs(W).max()):
        raise ValueError(f"{name} must be positive semi-definite")
    return W
