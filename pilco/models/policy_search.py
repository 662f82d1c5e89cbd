"""Policy search: the optimiser loop of :meth:`pilco.models.PILCO.optimize_policy`.

:class:`GuardedScipy` is GPflow's Scipy optimiser made robust to trial points where the
rollout fails numerically; :func:`search_policy` runs it (with restarts and early stops)
on a loss of the policy parameters and leaves the best policy evaluated in place.
"""
from __future__ import annotations

import logging
import time
from typing import Callable, List, Optional

import numpy as np
import tensorflow as tf

from ..moments.compiled import align_graph_names
from ..snapshots import Stalled, TrackingScipy, restore, snapshot

__all__ = ["GuardedScipy", "search_policy"]

logger = logging.getLogger(__name__)


class GuardedScipy(TrackingScipy):
    """GPflow's Scipy optimiser that survives numerical failures and remembers its best point.

    A trial point far out (a collapsed lengthscale, say) can make the rollout's linear
    algebra fail or its value NaN. Reporting a very large loss there, instead of raising
    or returning NaN, makes the line search step back and the run go on; each such point
    is counted in ``failures``. Every finite evaluation is compared with the best so far,
    so the caller can restore the best parameters ever evaluated without spending extra
    objective evaluations (or a separate forward-only compilation) on bookkeeping.
    """

    PENALTY = 1e10

    def __init__(self):
        super().__init__()
        self.reset()

    def reset(self):
        """Forget the failures and the best points of earlier runs."""
        self.failures = 0
        self.evaluations = 0
        self.first_loss = None
        #: per run since the reset: ``[best loss, best point]`` (``[inf, None]`` if none)
        self.runs: List[list] = []
        TrackingScipy.start_run(self)

    @property
    def best_loss(self) -> float:
        """The lowest finite loss evaluated since the reset (``inf`` if none)."""
        return min((loss for loss, _ in self.runs), default=np.inf)

    @property
    def best_x(self) -> Optional[np.ndarray]:
        """The point of :attr:`best_loss` (the earliest run's on a tie; None if none)."""
        losses = [loss for loss, _ in self.runs]
        return self.runs[int(np.argmin(losses))][1] if losses else None

    def start_run(self) -> None:
        """Begin a new run: its best point is tracked on its own (``runs[-1]``)."""
        super().start_run()
        self.runs.append([np.inf, None])

    def eval_func(self, closure, variables, tf_fun_args, compile=True,
                  allow_unused_variables=False):
        if compile and tf_fun_args.get("jit_compile") and self._will_trace(
                closure, variables, tf_fun_args, allow_unused_variables):
            # XLA's persistent cache is keyed on the traced program's names: the same
            # names in every run (pilco.moments.compiled.align_graph_names)
            align_graph_names()
        inner = super().eval_func(closure, variables, tf_fun_args, compile=compile,
                                  allow_unused_variables=allow_unused_variables)

        def guarded(x):
            self.evaluations += 1
            try:
                loss, grad = inner(x)
            except tf.errors.InvalidArgumentError:
                loss, grad = np.nan, None
            if not np.isfinite(loss) or grad is None or not np.all(np.isfinite(grad)):
                self.failures += 1
                return self.PENALTY, np.zeros_like(x)
            if self.first_loss is None:
                self.first_loss = float(loss)
            if not self.runs:  # evaluated without start_run: one run since the reset
                self.runs.append([np.inf, None])
            if loss < self.runs[-1][0]:
                self.runs[-1] = [float(loss), np.array(x, dtype=np.float64, copy=True)]
            return loss, grad

        return guarded

    def _will_trace(self, closure, variables, tf_fun_args, allow_unused_variables) -> bool:
        """Whether the function GPflow's ``eval_func`` is about to return has not been
        traced yet (GPflow keeps one per closure, variables and arguments; if its cache
        is not found, True)."""
        key = (closure, tuple(id(v) for v in variables), frozenset(tf_fun_args.items()),
               allow_unused_variables)
        function = getattr(self, "compile_cache", {}).get(key)
        return function is None or function.experimental_get_tracing_count() == 0

    def restore_best(self, variables) -> bool:
        """Assign the best point evaluated so far to ``variables``; False if there is none."""
        return self._assign(variables, self.best_x)

    def restore_run_best(self, variables, run: int) -> bool:
        """Assign the best point of run ``run`` (0-based, since the last :meth:`reset`) to
        ``variables``; False if that run evaluated no finite point."""
        return self._assign(variables, self.runs[run][1])

    def _assign(self, variables, x) -> bool:
        if x is None:
            return False
        values = self.unpack_tensors(variables, tf.constant(x))
        self.assign_tensors(variables, values)
        return True


def search_policy(loss: Callable[[], tf.Tensor], controller, optimizer: GuardedScipy,
                  maxiter: int, restarts: int, rng: np.random.Generator, method: str,
                  callback: Optional[Callable[[int], None]] = None,
                  min_rel_improvement: Optional[float] = None, patience: int = 10,
                  jit_compile: bool = False) -> float:
    """Minimise ``loss()`` (a scalar tensor) over ``controller.trainable_variables``.

    The first run starts from the current policy, each further restart from
    ``controller.randomize(seed=...)``. The best policy evaluated by any run is left in
    place: never one worse than the starting policy, which is the first point evaluated
    (the start is kept if no point was finite). A run that fails numerically is logged and
    the next one goes on; an interruption (Ctrl-C, an exception of ``callback``) leaves the
    best policy so far in place and propagates. ``loss`` is compiled once by the optimiser
    and reused by every run and later calls (by XLA with ``jit_compile``). Arguments are
    checked by the caller.
    Returns ``-best loss``, the best total reward.
    """
    variables = controller.trainable_variables
    opt = optimizer
    opt.reset()
    start_values = snapshot(controller)

    def keep_best() -> bool:
        """Put the best policy evaluated in place (the start if none); False if none."""
        if opt.restore_best(variables):
            return True
        restore(controller, start_values)
        return False

    compile_args = dict(autograph=False, jit_compile=True) if jit_compile \
        else dict(autograph=False)
    t0 = time.perf_counter()
    stalled: List[int] = []
    for r in range(restarts):
        if r > 0:
            controller.randomize(seed=int(rng.integers(2**31)))
        opt.start_run()
        try:
            opt.minimize(
                loss, variables, method=method,
                options=dict(maxiter=maxiter), tf_fun_args=compile_args,
                step_callback=opt.step_callback(callback, min_rel_improvement, patience,
                                                what="negative expected return"),
            )
        except Stalled as stop:
            stalled.append(stop.iterations)
        except (tf.errors.InvalidArgumentError, ValueError) as err:
            logger.warning("policy optimisation run %d failed (%s); keeping the best policy "
                           "so far", r, str(err).splitlines()[0][:120])
        except BaseException:
            # interrupted (Ctrl-C, a callback's exception): leave the best policy
            # evaluated so far in place, not the last trial point of a line search
            keep_best()
            logger.warning("policy optimisation interrupted after %d evaluations; the best "
                           "policy so far is kept", opt.evaluations)
            raise
    if not keep_best():
        logger.warning("policy optimisation evaluated no point where the expected return "
                       "is finite; the starting policy is kept")
        try:
            return float(-loss().numpy())
        except tf.errors.InvalidArgumentError:
            return -np.inf
    if opt.failures:
        logger.warning("policy optimisation met %d trial points where the rollout failed "
                       "numerically; the line search stepped back from them", opt.failures)
    start = -np.inf if opt.first_loss is None else -opt.first_loss
    logger.info("policy optimised in %.2f s (%d evaluations%s): expected return %.4f -> %.4f",
                time.perf_counter() - t0, opt.evaluations,
                f"; {len(stalled)} run(s) stopped early, after {stalled} iterations"
                if stalled else "", start, -opt.best_loss)
    return -opt.best_loss
