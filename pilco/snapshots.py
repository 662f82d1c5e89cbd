"""Helpers of the optimisers: copies of a module's parameter values, to keep the best ones
found, and the adapter of a progress callback to GPflow's step callback.

Values are copied in the optimiser's (unconstrained) space: a constrained value that sits
on its bound (a noise variance at its floor) would not survive the round trip through
the constraining transform, whereas the unconstrained value restores it exactly.
"""
from __future__ import annotations

from typing import Callable, Dict, Optional

import numpy as np
import tensorflow as tf
from gpflow.utilities import parameter_dict

__all__ = ["snapshot", "restore", "step_callback"]


def _variables(module) -> Dict[str, tf.Variable]:
    out = {}
    for path, p in parameter_dict(module).items():
        var = getattr(p, "unconstrained_variable", p)
        out[path] = var
    return out


def snapshot(module) -> Dict[str, np.ndarray]:
    """Copies (NumPy arrays) of every parameter of ``module``, unconstrained."""
    return {path: np.array(v.numpy(), copy=True) for path, v in _variables(module).items()}


def restore(module, values: Dict[str, np.ndarray]) -> None:
    """Assign values taken by :func:`snapshot` of the same module back to it."""
    variables = _variables(module)
    for path, value in values.items():
        variables[path].assign(value)


def step_callback(callback: Optional[Callable[[int], None]]):
    """A ``gpflow.optimizers.Scipy`` step callback calling ``callback(iteration)``, or None."""
    if callback is None:
        return None

    def on_step(step, variables, values):  # noqa: ARG001 - gpflow's callback signature
        callback(int(step))

    return on_step
