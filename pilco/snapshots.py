"""Helpers of the optimisers: copies of a module's parameter values, to keep the best ones
found, the adapter of a progress callback to GPflow's step callback, and the early stop of
a run whose loss has stalled.

Snapshots live in memory only, for the length of a search (or to copy values between
two models); an agent is saved to a file with ``agent.save`` (:mod:`pilco.models.storage`).

Values are copied in the optimiser's (unconstrained) space: a constrained value that sits
on its bound (a noise variance at its floor) would not survive the round trip through
the constraining transform, whereas the unconstrained value restores it exactly.
"""
from __future__ import annotations

import logging
from typing import Callable, Dict, List, Optional

import gpflow
import numpy as np
import tensorflow as tf
from gpflow.utilities import parameter_dict

__all__ = ["snapshot", "restore", "Stalled", "TrackingScipy"]

logger = logging.getLogger(__name__)


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


class Stalled(Exception):
    """Raised by a step callback to end a run whose loss stopped improving.

    ``iterations``: the iterations the run made.
    """

    def __init__(self, iterations: int):
        super().__init__(f"stalled after {iterations} iterations")
        self.iterations = iterations


class TrackingScipy(gpflow.optimizers.Scipy):
    """GPflow's Scipy optimiser that remembers the lowest finite loss of the current run
    (``run_best_loss``; :meth:`start_run` begins a new run)."""

    def __init__(self):
        super().__init__()
        self.run_best_loss = np.inf

    def start_run(self) -> None:
        self.run_best_loss = np.inf

    def eval_func(self, closure, variables, tf_fun_args, compile=True,
                  allow_unused_variables=False):
        inner = super().eval_func(closure, variables, tf_fun_args, compile=compile,
                                  allow_unused_variables=allow_unused_variables)

        def tracked(x):
            loss, grad = inner(x)
            if np.isfinite(loss) and loss < self.run_best_loss and np.all(np.isfinite(grad)):
                self.run_best_loss = float(loss)
            return loss, grad

        return tracked

    def step_callback(self, callback: Optional[Callable[[int], None]] = None,
                      min_rel_improvement: Optional[float] = None, patience: int = 10,
                      what: str = "loss"):
        """A GPflow step callback for one run: ``callback(iteration)``, then, with
        ``min_rel_improvement``, :class:`Stalled` once the run's best loss fell by less than
        ``min_rel_improvement * max(1, |best loss|)`` over the last ``patience`` iterations
        (relative, like scipy's ``ftol``, so one value serves losses of any scale)."""
        history: List[float] = []

        def on_step(step, variables, values):  # gpflow's callback signature
            if callback is not None:
                callback(int(step))
            logger.debug("iteration %d: best %s %.6g", step, what, self.run_best_loss)
            if min_rel_improvement is None:
                return
            history.append(self.run_best_loss)
            if len(history) > patience and (history[-patience - 1] - history[-1]
                                             < min_rel_improvement * max(1.0, abs(history[-1]))):
                raise Stalled(len(history))

        return on_step

