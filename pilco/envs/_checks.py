"""Argument checks shared by the environments of :mod:`pilco.envs`.

Each check raises a ``TypeError`` (wrong kind of value) or ``ValueError`` (wrong shape,
range, NaN/inf, unknown name) whose message starts with the argument's name, and returns
the value in the form the environments store (float64 arrays, Python numbers).

These checks are the environments' own, not :mod:`pilco.validation`'s: :mod:`pilco.envs`
imports nothing from the rest of pilco (the split of argument checks by layer is
described in :mod:`pilco.validation`).
"""
from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any

import numpy as np

__all__ = [
    "choice",
    "horizon",
    "mapping",
    "real",
    "render_mode",
    "render_size",
    "reset_options",
    "seed",
    "std",
    "vector",
]


_KINDS = {"b": "booleans", "U": "strings", "S": "bytes", "c": "complex numbers"}


def _numbers(value: Any, name: str, expected: str) -> np.ndarray:
    """``value`` as a float64 array if it holds real numbers (integers or floats), else a
    ``TypeError`` naming ``name`` (a string such as ``"0.1"`` is not taken as a number)."""
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:  # e.g. ragged nested lists
        raise TypeError(f"{name} must be {expected}: {exc}") from exc
    if arr.dtype.kind not in "iuf":
        got = _KINDS.get(arr.dtype.kind) or (
            type(value).__name__ if arr.ndim == 0 else "objects")
        raise TypeError(f"{name} must be {expected}, got {got}")
    return arr.astype(np.float64)


def vector(value: Any, size: int, name: str, *, layout: str = "") -> np.ndarray:
    """Convert ``value`` to a new finite float64 array of shape ``(size,)``.

    Args:
        value: array-like of ``size`` numbers.
        size: required length.
        name: argument name used in error messages.
        layout: optional description of the components for the shape error, e.g.
            ``"[x, x_dot, theta_dot, theta]"``.

    Raises:
        TypeError: not numbers (strings, booleans, None and other objects are refused).
        ValueError: wrong shape, or NaN/inf entries.
    """
    arr = _numbers(value, name, f"array-like of {size} numbers")
    if arr.shape != (size,):
        shape = f"({size},) = {layout}" if layout else f"({size},)"
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr}")
    return arr.copy()


def std(value: Any, size: int, name: str) -> np.ndarray:
    """Standard deviations: a scalar or shape ``(size,)``, finite and ``>= 0``, returned
    as a new float64 array of shape ``(size,)``."""
    arr = _numbers(value, name, f"a number or array of shape ({size},)")
    if arr.shape not in ((), (1,), (size,)):
        raise ValueError(f"{name} must be a scalar or have shape ({size},), got shape {arr.shape}")
    arr = np.broadcast_to(arr, (size,)).copy()
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValueError(f"{name} must be finite and >= 0, got {arr}")
    return arr


def real(value: Any, name: str, *, allow_zero: bool, allow_negative: bool = False) -> float:
    """A finite real number, as ``float``: ``> 0``, or ``>= 0`` with ``allow_zero``, or of
    any sign with ``allow_negative``.

    Raises:
        TypeError: not a real number (``bool`` is refused too).
        ValueError: NaN, infinite, or of a sign not allowed.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    value = float(value)
    if not np.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value}")
    if allow_negative:
        return value
    if value < 0 or (value == 0 and not allow_zero):
        raise ValueError(f"{name} must be {'>= 0' if allow_zero else '> 0'}, got {value}")
    return value


def _check_int(value: Any, name: str, minimum: int, *, kind: str = "an int") -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be {kind}, got {type(value).__name__}")
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    return int(value)


def horizon(max_episode_steps: Any) -> int | None:
    """``max_episode_steps``: a positive int, or ``None`` (no internal limit)."""
    if max_episode_steps is None:
        return None
    return _check_int(max_episode_steps, "max_episode_steps", 1, kind="an int or None")


def seed(seed: Any) -> int | None:
    """``reset(seed=...)``: ``None`` or an int ``>= 0`` (NumPy integers are converted)."""
    if seed is None:
        return None
    return _check_int(seed, "seed", 0, kind="an int or None")


def render_size(width: Any, height: Any) -> tuple[int, int]:
    """``render_width`` and ``render_height``: ints of at least 16 pixels."""
    return _check_int(width, "render_width", 16), _check_int(height, "render_height", 16)


def render_mode(render_mode: Any, modes: Collection[str]) -> str | None:
    """``render_mode``: ``None`` or one of ``modes``."""
    if render_mode is not None and render_mode not in modes:
        raise ValueError(f"render_mode must be None or one of {list(modes)}, got {render_mode!r}")
    return render_mode


def choice(value: Any, name: str, choices: Collection[str]) -> str:
    """``value`` must be one of the strings ``choices``."""
    if not isinstance(value, str):
        raise TypeError(f"{name} must be a string, one of {list(choices)}, got {value!r}")
    if value not in choices:
        raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")
    return value


def mapping(value: Any, name: str) -> Mapping:
    """``value`` must be a mapping (e.g. a dict)."""
    if not isinstance(value, Mapping):
        raise TypeError(f"{name} must be a mapping, got {type(value).__name__}")
    return value


def reset_options(options: Any, valid: Collection[str]) -> dict[str, Any]:
    """``reset(options=...)``: ``None`` or a dict whose keys are all in ``valid``.

    Returns:
        The options as a dict (empty for ``None``).
    """
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise TypeError(f"options must be a dict or None, got {type(options).__name__}")
    unknown = set(options) - set(valid)
    if unknown:
        raise ValueError(
            f"Unknown reset options {sorted(unknown, key=repr)}; valid: {sorted(valid)}"
        )
    return options
