"""Single values: counts, positive numbers, seeds, flags, names from a list, indices.

Booleans are never taken as numbers, nor strings as numbers or names of the wrong kind;
each check returns the value as a plain Python ``int``, ``float``, ``bool`` or ``str``
(indices as a tuple of ``int``).
"""
from __future__ import annotations

import numbers
from collections.abc import Iterable
from typing import Optional, Sequence, Tuple

import numpy as np

__all__ = [
    "check_positive_int",
    "check_positive_float",
    "check_non_negative_float",
    "check_min_rel_improvement",
    "check_ratio_bound",
    "check_seed",
    "check_bool",
    "check_option",
    "check_indices",
]


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


def check_ratio_bound(value, name: str) -> float:
    """A finite number > 1 (a bound on a ratio, such as a signal-to-noise ratio)."""
    if not check_positive_float(value, name) > 1:
        raise ValueError(f"{name} must be a finite number > 1, got {value}")
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


def check_option(value, options: Sequence[str], name: str, ignore_case: bool = False) -> str:
    """One of the strings ``options`` (returned in upper case with ``ignore_case``)."""
    key = value.upper() if ignore_case and isinstance(value, str) else value
    if not isinstance(value, str) or key not in options:
        raise ValueError(f"{name} must be one of {tuple(options)}, got {value!r}")
    return key


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
