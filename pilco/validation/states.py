"""States and Gaussian state distributions.

A measured state (one row, or a batch of rows), a covariance matrix (symmetric, positive
semi-definite) and a Gaussian ``N(m, s)``. :func:`check_gaussian` is the one check that
returns TensorFlow tensors: it imports TensorFlow when called, so importing this module
(and :mod:`pilco.deploy`, which uses :func:`check_states`) loads NumPy only.
"""
from __future__ import annotations

import numpy as np

from .arrays import _check_finite, _to_numpy, as_2d_float

__all__ = ["check_state_row", "check_states", "check_covariance", "check_gaussian"]


def check_state_row(x, dim: int, name: str = "state") -> np.ndarray:
    """One measured state [dim] or [1, dim] of finite numbers, as float64 [1, dim]."""
    x = _to_numpy(x, name)
    x = as_2d_float(x.reshape(1, -1) if x.ndim == 1 else x, name)
    if x.shape != (1, dim):
        raise ValueError(f"{name} must have shape (1, {dim}), got {x.shape}")
    return x


def check_states(state, dim: int, name: str = "state") -> np.ndarray:
    """One measured state [dim] or a batch [N, dim] of finite numbers, as float64."""
    x = _to_numpy(state, name)  # strings, booleans, ragged lists: TypeError
    if x.ndim not in (1, 2):
        raise ValueError(f"{name} must have shape [{dim}] or [N, {dim}], got {x.shape}")
    if x.shape[-1] != dim:
        raise ValueError(f"{name} must have {dim} entries per row (the policy's state "
                         f"dimension), got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(x))[0])
        raise ValueError(f"{name} contains NaN or inf (first at index {bad})")
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
    originals, so a gradient tape watching them still connects to the outputs. Inside a
    traced ``tf.function`` their shapes are checked when tracing and their finiteness when
    run (:mod:`pilco.validation.inputs`).
    """
    from .inputs import check_symbolic_gaussian, is_symbolic

    if is_symbolic(m) or is_symbolic(s):  # traced: shapes now, finiteness when run
        return check_symbolic_gaussian(m, s, dim, name)
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
