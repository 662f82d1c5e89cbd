"""Inputs of prediction methods, eager or inside ``tf.function``.

The rule (every public prediction method of :mod:`pilco.models`, :mod:`pilco.controllers`
and :mod:`pilco.rewards` follows it):

- **what is accepted**: NumPy arrays, nested lists and TensorFlow tensors or variables of
  real numbers (any float or integer dtype); they are converted to float64, GPflow's
  ``default_float()`` (a float32 input is widened exactly, never refused);
- **values known** (NumPy, lists, eager tensors, and NumPy values given to a traced
  function): rank, size, finiteness (and, for covariances, symmetry and positive
  semi-definiteness) are checked before TensorFlow sees the input, and a bad one raises
  :class:`ValueError` (wrong values or shapes) or :class:`TypeError` (wrong kinds)
  naming the argument and the problem;
- **symbolic tensors** (arguments of a ``tf.function`` being traced): the rank and the
  sizes that are known when tracing are checked then (the same ValueError and
  TypeError), and finiteness when the function runs (``tf.debugging.assert_all_finite``,
  an ``InvalidArgumentError`` whose message names the argument). Nothing calls
  ``.numpy()`` on the traced path.

Tensors given are returned as tensors derived from them (cast, reshaped), so a gradient
tape watching them still connects to the outputs. TensorFlow is imported when these
functions are first called (the package loads NumPy only at import time).
"""
from __future__ import annotations

import functools
import inspect
from typing import Callable, Dict

from .arrays import _check_finite, _to_numpy

__all__ = ["is_symbolic", "check_points", "check_symbolic_gaussian", "checked_arguments"]


def is_symbolic(x) -> bool:
    """Whether ``x`` is a tensor or variable whose values are unknown now (traced)."""
    import tensorflow as tf

    return (tf.is_tensor(x) or isinstance(x, tf.Variable)) and not tf.executing_eagerly()


def _symbolic(x, name: str):
    """A symbolic tensor of real numbers, cast to float64 (shapes checked by callers)."""
    import tensorflow as tf
    from gpflow.config import default_float

    x = tf.convert_to_tensor(x)
    if not (x.dtype.is_floating or x.dtype.is_integer) or x.dtype.is_bool:
        raise TypeError(f"{name} must hold real numbers, got a {x.dtype.name} tensor")
    return tf.cast(x, default_float())


def _finite(x, name: str):
    """``x`` with a run-time check that its entries are finite."""
    import tensorflow as tf

    return tf.debugging.assert_all_finite(x, f"{name} contains NaN or inf values")


def check_points(x, dim: int, name: str = "Xnew"):
    """Points at which a model predicts: ``[N, dim]`` real numbers, as float64 tensor.

    Follows the module's rule; a single point must be given as one row ``[1, dim]``.
    """
    import tensorflow as tf
    from gpflow.config import default_float

    if is_symbolic(x):
        t = _symbolic(x, name)
        shape = t.shape
        if shape.rank is not None and shape.rank != 2:
            raise ValueError(f"{name} must be 2-D [points, {dim}], got a rank-{shape.rank} "
                             f"tensor of shape {shape}")
        if shape.rank == 2 and shape[1] is not None and shape[1] != dim:
            raise ValueError(f"{name} must have {dim} columns (the input dimension), got "
                             f"shape {shape}")
        return _finite(tf.reshape(t, [-1, dim]), name)
    arr = _to_numpy(x, name)
    if arr.ndim != 2:
        hint = (" (one point: reshape it with x.reshape(1, -1))" if arr.ndim == 1 else "")
        raise ValueError(f"{name} must be 2-D [points, {dim}], got shape {arr.shape}{hint}")
    if arr.shape[1] != dim:
        raise ValueError(f"{name} must have {dim} columns (the input dimension), got shape "
                         f"{arr.shape}")
    _check_finite(arr, name)
    if tf.is_tensor(x) or isinstance(x, tf.Variable):
        return tf.cast(x, default_float())
    return tf.convert_to_tensor(arr, dtype=default_float())


def check_symbolic_gaussian(m, s, dim: int, name: str = "state"):
    """:func:`pilco.validation.check_gaussian` for traced tensors: the shapes known when
    tracing (mean ``[1, dim]`` or ``[dim]``, covariance ``[dim, dim]``), finiteness when
    run. Symmetry and positive semi-definiteness need the values: not checked here."""
    import tensorflow as tf

    m = _symbolic(m, f"{name} mean")
    s = _symbolic(s, f"{name} covariance")
    if m.shape.rank is not None and (m.shape.rank not in (1, 2)
                                     or not m.shape.is_compatible_with(
                                         [dim] if m.shape.rank == 1 else [1, dim])):
        raise ValueError(f"{name} mean must have shape (1, {dim}), got {m.shape}")
    if not s.shape.is_compatible_with([dim, dim]):
        raise ValueError(f"{name} covariance must have shape ({dim}, {dim}), got {s.shape}")
    m = _finite(tf.reshape(m, [1, dim]), f"{name} mean")
    s = _finite(tf.reshape(s, [dim, dim]), f"{name} covariance")
    return m, s


def checked_arguments(check: Callable) -> Callable:
    """Decorator of methods: ``check(self, arguments)`` (a dict of the call's arguments by
    name, defaults filled in) replaces arguments by their checked values before the method
    (and a ``check_shapes`` declaration under this decorator) sees them, so bad input
    raises this package's ValueError or TypeError naming the problem rather than a
    shape-checker or TensorFlow error."""

    def decorate(method: Callable) -> Callable:
        signature = inspect.signature(method)

        @functools.wraps(method)
        def wrapper(self, *args, **kwargs):
            bound = signature.bind(self, *args, **kwargs)
            bound.apply_defaults()
            arguments: Dict = bound.arguments
            check(self, arguments)
            return method(*bound.args, **bound.kwargs)

        return wrapper

    return decorate
