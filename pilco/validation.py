"""Checks at the public API boundary: bad input is reported before TensorFlow sees it.

Every check raises :class:`ValueError` (wrong values or shapes) or :class:`TypeError`
(wrong kinds of object) whose message names the argument and the problem. All argument
checks of the package live here.

This module imports only NumPy and the standard library at import time (the NumPy-only
:mod:`pilco.deploy` uses it); TensorFlow is imported by the checks that return tensors.
"""
from __future__ import annotations

import numbers
import os
from collections.abc import Iterable
from typing import Optional, Sequence, Tuple

import numpy as np

from .protocols import Controller, Reward

__all__ = [
    "as_2d_float",
    "check_data",
    "check_noise_scales",
    "check_transitions",
    "check_columns",
    "check_state_row",
    "check_gaussian",
    "check_covariance",
    "check_positive_int",
    "check_max_action",
    "check_positive_float",
    "check_seed",
    "check_bool",
    "check_indices",
    "check_matrix",
    "check_states",
    "check_ratio_bound",
    "check_squash",
    "check_reward",
    "check_controller",
    "check_option",
    "check_entries",
    "check_weight_matrix",
    "check_reward_list",
    "check_pair",
    "check_path",
    "check_format_version",
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


def check_columns(x, columns: int, name: str, meaning: str = "") -> np.ndarray:
    """A finite float64 matrix [N, columns], or a clear error."""
    arr = as_2d_float(x, name)
    if arr.shape[1] != columns:
        raise ValueError(f"{name} must have {columns} columns{' ' + meaning if meaning else ''}, "
                         f"got {arr.shape[1]}")
    return arr


def check_state_row(x, dim: int, name: str = "state") -> np.ndarray:
    """One measured state [dim] or [1, dim] of finite numbers, as float64 [1, dim]."""
    x = _to_numpy(x, name)
    x = as_2d_float(x.reshape(1, -1) if x.ndim == 1 else x, name)
    if x.shape != (1, dim):
        raise ValueError(f"{name} must have shape (1, {dim}), got {x.shape}")
    return x


def check_covariance(s, dim: int, name: str) -> np.ndarray:
    """A finite symmetric positive semi-definite [dim, dim] matrix, or a clear error."""
    s = _to_numpy(s, name)
    if s.ndim == 0 and dim == 1:
        s = s.reshape(1, 1)
    if s.shape != (dim, dim):
        raise ValueError(f"{name} must have shape ({dim}, {dim}), got {s.shape}")
    _check_finite(s, name)
    scale = max(1.0, float(np.max(np.abs(s))))
    if not np.allclose(s, s.T, rtol=1e-8, atol=1e-10 * scale):
        raise ValueError(
            f"{name} is not symmetric (max |s - s^T| = {np.max(np.abs(s - s.T)):.3g})"
        )
    lo = float(np.min(np.linalg.eigvalsh(0.5 * (s + s.T))))
    if lo < -1e-9 * scale:
        raise ValueError(
            f"{name} is not positive semi-definite (smallest eigenvalue {lo:.3g})"
        )
    return s


def check_gaussian(m, s, dim: int, name: str = "state"):
    """Check a Gaussian ``N(m, s)`` of dimension ``dim``; returns float tensors.

    Shapes: m [1, dim] (or [dim]), s [dim, dim] -> m [1, dim], s [dim, dim].
    TensorFlow inputs are checked by value and returned as tensors derived from the
    originals, so a gradient tape watching them still connects to the outputs.
    """
    m_in, s_in = m, s
    m = _to_numpy(m, f"{name} mean")
    if m.ndim == 1:
        m = m.reshape(1, -1)
    if m.shape != (1, dim):
        raise ValueError(f"{name} mean must have shape (1, {dim}), got {m.shape}")
    _check_finite(m, f"{name} mean")
    s = check_covariance(s, dim, f"{name} covariance")
    import tensorflow as tf  # only here: the NumPy checks must not load TensorFlow
    from gpflow.config import default_float

    f = default_float()
    m_out = (tf.reshape(tf.cast(m_in, f), (1, dim)) if tf.is_tensor(m_in)
             else tf.convert_to_tensor(m, dtype=f))
    s_out = (tf.reshape(tf.cast(s_in, f), (dim, dim)) if tf.is_tensor(s_in)
             else tf.convert_to_tensor(s, dtype=f))
    return m_out, s_out


def check_positive_int(value, name: str) -> int:
    """A strictly positive integer, or a clear error."""
    if isinstance(value, bool) or not isinstance(value, (numbers.Integral, np.integer)):
        if isinstance(value, float) and float(value).is_integer():
            value = int(value)
        else:
            raise TypeError(f"{name} must be a positive integer, got {value!r}")
    if value <= 0:
        raise ValueError(f"{name} must be a positive integer, got {value}")
    return int(value)


def check_positive_float(value, name: str) -> float:
    """A finite number > 0 (not a boolean or a string), or a clear error."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, np.number)):
        raise TypeError(f"{name} must be a positive number, got {value!r}")
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be a positive finite number, got {value}")
    return value


def check_non_negative_float(value, name: str) -> float:
    """A finite number >= 0 (not a boolean or a string), or a clear error."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, np.number)):
        raise TypeError(f"{name} must be a number >= 0, got {value!r}")
    value = float(value)
    if not np.isfinite(value) or value < 0:
        raise ValueError(f"{name} must be a finite number >= 0, got {value}")
    return value


def check_min_rel_improvement(value, name: str = "min_rel_improvement") -> Optional[float]:
    """``None`` or a finite number >= 0 (an optimiser's early-stop bar), or a clear error."""
    if value is None:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, np.number)):
        raise TypeError(f"{name} must be a finite number >= 0 or None, got "
                        f"{type(value).__name__}")
    if not np.isfinite(value) or value < 0:
        raise ValueError(f"{name} must be a finite number >= 0 or None, got {value!r}")
    return float(value)


def check_seed(seed, name: str = "seed") -> Optional[int]:
    """A random seed: None or a non-negative integer, or a clear error."""
    if seed is None:
        return None
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (numbers.Integral, np.integer)):
        raise TypeError(f"{name} must be None or a non-negative integer, got {seed!r}")
    if seed < 0:
        raise ValueError(f"{name} must be None or a non-negative integer, got {seed}")
    return int(seed)


def check_bool(value, name: str) -> bool:
    """A boolean (``True``/``False``, also NumPy's), or a clear error."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def check_indices(indices, dim: int, name: str, distinct: bool = True) -> Tuple[int, ...]:
    """Integer indices into ``range(dim)`` (distinct unless ``distinct=False``), or a clear
    error."""
    if isinstance(indices, (str, bytes)) or not isinstance(indices, Iterable):
        raise TypeError(f"{name} must be a sequence of integers, got {indices!r}")
    out = []
    for a in indices:
        if isinstance(a, (bool, np.bool_)) or not isinstance(a, (numbers.Integral, np.integer)):
            raise TypeError(f"{name} must hold integers, got {a!r}")
        if not 0 <= a < dim:
            raise ValueError(f"{name}: index {int(a)} is outside the state (dimension {dim})")
        out.append(int(a))
    if distinct and len(set(out)) != len(out):
        raise ValueError(f"{name} has duplicates: {out}")
    return tuple(out)


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


def check_matrix(value, shape: Tuple[int, ...], name: str) -> np.ndarray:
    """A finite float64 array of exactly ``shape``, or a clear error."""
    arr = _to_numpy(value, name)
    if arr.shape != tuple(shape):
        raise ValueError(f"{name} must have shape {tuple(shape)}, got {arr.shape}")
    _check_finite(arr, name)
    return arr


def check_states(state, dim: int, name: str = "state") -> np.ndarray:
    """One measured state [dim] or a batch [N, dim] of finite numbers, as float64."""
    if isinstance(state, (str, bytes)) or state is None:
        raise TypeError(f"{name} must be an array of numbers, got {type(state).__name__}")
    try:
        x = np.asarray(state, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name} must be an array of numbers: {err}") from None
    if x.ndim not in (1, 2):
        raise ValueError(f"{name} must have shape [{dim}] or [N, {dim}], got {x.shape}")
    if x.shape[-1] != dim:
        raise ValueError(f"{name} must have {dim} entries per row (the policy's state "
                         f"dimension), got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(x))[0])
        raise ValueError(f"{name} contains NaN or inf (first at index {bad})")
    return x


def check_ratio_bound(value, name: str) -> float:
    """A finite number > 1 (a bound on a ratio, such as a signal-to-noise ratio)."""
    if not check_positive_float(value, name) > 1:
        raise ValueError(f"{name} must be a finite number > 1, got {value}")
    return float(value)


def check_squash(squash):
    """A squashing function ``(m, s, max_action) -> (M, S, C)`` or None, or a clear error."""
    if squash is not None and not callable(squash):
        raise TypeError(
            f"squash must be a function such as squash_sin or squash_sat (or None), got "
            f"{squash!r}"
        )
    return squash


def _missing(obj, members: Sequence[str]) -> list:
    return [name for name in members if not callable(getattr(obj, name, None))]


def check_reward(reward, state_dim: Optional[int] = None, name: str = "reward"):
    """An object following :class:`pilco.protocols.Reward` (with ``state_dim`` if given)."""
    if (getattr(reward, "state_dim", None) is None or _missing(reward, ["moments"])
            or not isinstance(reward, Reward)):
        raise TypeError(
            f"{name} must be a reward (such as ExponentialReward) following "
            f"pilco.protocols.Reward: a state_dim attribute and a method moments(m, s), got "
            f"{type(reward).__name__}"
        )
    if state_dim is not None and reward.state_dim != state_dim:
        raise ValueError(f"{name}.state_dim is {reward.state_dim} but the state has "
                         f"dimension {state_dim}")
    return reward


def check_controller(controller, feature_dim: int, control_dim: int, state_dim: int):
    """An object following :class:`pilco.protocols.Controller` that reads ``feature_dim``
    inputs (``state_dim`` plus one per angle) and returns ``control_dim`` actions."""
    if getattr(controller, "state_dim", None) is None:
        raise TypeError("controller must have a state_dim attribute (see "
                        "pilco.protocols.Controller)")
    missing = _missing(controller, ["prepare", "moments"])
    if not hasattr(controller, "trainable_variables"):
        missing.append("trainable_variables")
    if missing or not isinstance(controller, Controller):
        raise TypeError(
            f"controller must follow pilco.protocols.Controller (state_dim, control_dim, "
            f"trainable_variables, prepare() and moments(m, s, squash, prepared)); "
            f"{type(controller).__name__} lacks {', '.join(missing) or 'control_dim'}"
        )
    if controller.state_dim != feature_dim:
        raise ValueError(
            f"controller.state_dim is {controller.state_dim} but the policy input has "
            f"dimension {feature_dim} (state {state_dim} + one extra per angle in "
            f"angle_indices)"
        )
    if getattr(controller, "control_dim", None) != control_dim:
        raise ValueError(
            f"controller.control_dim is {getattr(controller, 'control_dim', None)} but the "
            f"data has {control_dim} action columns"
        )
    return controller


def check_option(value, options: Sequence[str], name: str, ignore_case: bool = False) -> str:
    """One of the strings ``options`` (returned in upper case with ``ignore_case``)."""
    key = value.upper() if ignore_case and isinstance(value, str) else value
    if not isinstance(value, str) or key not in options:
        raise ValueError(f"{name} must be one of {tuple(options)}, got {value!r}")
    return key


def check_entries(value, size: int, name: str, label: Optional[str] = None) -> np.ndarray:
    """``size`` finite numbers (any shape with that many entries), flattened to [size]."""
    arr = _to_numpy(value, name).reshape(-1)
    if arr.size != size:
        raise ValueError(f"{label or name} must have {size} entries, got {arr.size}")
    _check_finite(arr, name)
    return arr


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


def check_weight_matrix(W, dim: int, name: str = "W") -> np.ndarray:
    """A finite symmetric positive semi-definite weight matrix [dim, dim]."""
    W = check_matrix(W, (dim, dim), name)
    if not np.allclose(W, W.T):
        raise ValueError(f"{name} must be symmetric")
    if np.min(np.linalg.eigvalsh(W)) < -1e-10 * max(1.0, np.abs(W).max()):
        raise ValueError(f"{name} must be positive semi-definite")
    return W


def check_reward_list(rewards, state_dim: int, name: str = "rewards") -> list:
    """A non-empty list of rewards (:class:`pilco.protocols.Reward`) on a state of
    ``state_dim`` dimensions."""
    if not isinstance(rewards, (list, tuple)):
        raise TypeError(f"{name} must be a list of rewards, got {type(rewards).__name__}")
    if len(rewards) == 0:
        raise ValueError(f"{name} must not be empty")
    for i, r in enumerate(rewards):
        check_reward(r, name=f"{name}[{i}]")
        if r.state_dim != state_dim:
            raise ValueError(f"every reward must have state_dim {state_dim}, got "
                             f"{r.state_dim} for {type(r).__name__}")
    return list(rewards)


def check_pair(data, name: str, what: str = "(X, Y)"):
    """A pair (tuple or list of two), or a clear error."""
    if not isinstance(data, (tuple, list)) or len(data) != 2:
        raise TypeError(f"{name} must be a pair {what}, got {type(data).__name__}")
    return data


def check_path(path, name: str = "path") -> str:
    """A file path (``str`` or ``os.PathLike``) as a ``str``, or a clear error."""
    if isinstance(path, (bytes, bytearray)) or not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{name} must be a file path (str or os.PathLike), got "
                        f"{type(path).__name__}")
    path = os.fspath(path)
    if not isinstance(path, str) or not path:
        raise ValueError(f"{name} must be a non-empty file path, got {path!r}")
    return path


def check_format_version(meta: dict, path: str, kind: str, supported: int,
                         reader: str) -> int:
    """The ``version`` of a pilco file's metadata if this ``reader`` reads it (1 to
    ``supported``), else a ``ValueError`` saying which version wrote the file."""
    version = meta.get("version")
    if isinstance(version, bool) or not isinstance(version, int) or not 1 <= version <= supported:
        written = meta.get("pilco_version")
        by = f" (written by pilco {written})" if isinstance(written, str) else ""
        known = "version 1" if supported == 1 else f"versions 1 to {supported}"
        raise ValueError(f"{path} has {kind} format version {version!r}{by}; {reader} reads "
                         f"{kind} format {known}")
    return version
