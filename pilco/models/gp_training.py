"""Training the dynamics GPs: data-driven starting values, soft bounds, batched losses, restarts.

Hyperparameter safety (documented defaults; the noise variance's hard lower bound
``noise_floor`` is the model's, :mod:`pilco.models.mgpr`):

- hyperparameters start from the data: lengthscales at the inputs' standard deviations,
  signal variance at the targets' variance, noise variance at 1% of it;
- the evidence is penalised as MATLAB PILCO's training does, so that the signal-to-noise
  ratio ``sf / sn`` stays below ``max_snr`` (default 500) and every lengthscale within a
  factor ``max_lengthscale_ratio`` (default 100) of its input's standard deviation: the
  penalty ``((log a - log b) / log bound)^30`` is negligible inside the bound and steep
  outside. Without it a noise-free target drives ``sn`` to the floor and ``sf`` up, and
  moment matching loses its precision (``sf^2 - tr(K^-1 Q)`` cancels);
- a Cholesky failure during training is caught: the best values seen so far are
  restored, the noise is raised (unless it is fixed), and a warning is logged;
- a hyperparameter made non-trainable (``gpflow.set_trainable(p, False)``) keeps the
  value it was given through training, restarts and failures included.

:class:`GPTraining` holds these methods of :class:`~pilco.models.mgpr.MGPR` (its base
class; it reads the model's data variables, ``models``, ``noise_floor``, ``max_snr``,
``max_lengthscale_ratio``, ``_batchable`` and ``_optimizer``).
"""
from __future__ import annotations

import logging
from typing import Callable, Dict, List, Optional

import gpflow
import numpy as np
import tensorflow as tf

from ..seeding import generator
from ..snapshots import Stalled, restore, snapshot
from ..validation import check_min_rel_improvement, check_positive_int, check_seed

__all__ = ["GPTraining"]

# MGPR.optimize logs under the model's name, pilco.models.mgpr, as it did inside that module
logger = logging.getLogger("pilco.models.mgpr")


def _assign_free(param: gpflow.Parameter, value) -> None:
    """Assign ``value`` unless ``param`` is fixed (non-trainable): set by the user, kept."""
    if param.trainable:
        param.assign(value)


class GPTraining:
    """The training methods of :class:`~pilco.models.mgpr.MGPR`: data-driven starting
    values, the penalised per-output losses (batched when the outputs allow it) and
    :meth:`optimize`."""

    def initialize_hyperparameters(self, rng: Optional[np.random.Generator] = None,
                                   spread: float = 0.0):
        """Data-driven starting values, optionally perturbed log-normally by ``spread``.

        A hyperparameter made non-trainable (``gpflow.set_trainable(p, False)``, e.g. a
        noise variance fixed by the user) keeps its value: restarts start from new values
        of the trainable ones only.
        """
        X = self._X.numpy()
        if rng is None and spread:
            rng = generator()
        ell0 = np.std(X, axis=0) if len(X) > 1 else np.ones(self.num_dims)
        # a constant input (a joint that never moves) carries no scale: start it at 1
        ell0 = np.where(ell0 > 1e-8, np.maximum(ell0, 1e-3), 1.0)
        for i, model in enumerate(self.models):
            y = self._Y[i].numpy()
            var = float(np.var(y)) if len(y) > 1 else 1.0
            var = max(var, 1e-6)
            jitter = lambda size: (np.exp(spread * rng.standard_normal(size))  # noqa: E731
                                   if spread else np.ones(size))
            _assign_free(model.kernel.lengthscales, ell0 * jitter(self.num_dims))
            _assign_free(model.kernel.variance, var * jitter(1)[0])
            _assign_free(model.likelihood.variance,
                         max(0.01 * var * jitter(1)[0], 2 * self.noise_floor))

    # -- losses ---------------------------------------------------------------------------
    def _penalty(self, model) -> tf.Tensor:
        """Soft bounds on the signal-to-noise ratio and the lengthscales (see module doc)."""
        return self._penalties(tf.convert_to_tensor(model.kernel.lengthscales)[None, :],
                               tf.convert_to_tensor(model.kernel.variance)[None],
                               tf.convert_to_tensor(model.likelihood.variance)[None])[0]

    def _penalties(self, ell, sf2, sn2) -> tf.Tensor:
        """:meth:`_penalty` of E outputs at once: lengthscales [E, D], signal and noise
        variances [E] -> [E]."""
        power = 30.0
        X = tf.convert_to_tensor(self._X)
        n = tf.cast(tf.shape(X)[0], X.dtype)
        centred = X - tf.reduce_mean(X, 0)
        std = tf.sqrt(tf.reduce_sum(tf.square(centred), 0) / tf.maximum(n - 1.0, 1.0))
        # constant inputs leave the evidence flat in their lengthscale: bound it around 1
        # instead of pulling it towards a zero spread (which would make it ~1e-6)
        std = tf.where(std > 1e-8, std, tf.ones_like(std))
        ell_term = tf.reduce_sum(
            ((tf.math.log(ell) - tf.math.log(std)) / np.log(self.max_lengthscale_ratio))
            ** power, axis=-1)
        log_snr = 0.5 * (tf.math.log(sf2) - tf.math.log(sn2))
        return ell_term + (log_snr / np.log(self.max_snr)) ** power

    def _model_loss(self, model) -> tf.Tensor:
        return model.training_loss() + self._penalty(model)

    def _batched_losses(self, with_penalties: bool = True) -> tf.Tensor:
        """The outputs' training losses [E] (negative log evidence, minus the log prior
        densities, plus the soft bounds of :meth:`_penalty`) as one batched computation:
        the same values as :meth:`_model_loss` of each output, but one [E, N, N] Cholesky
        and a graph of ~1/E the operations, so tracing and compiling it take a fraction of
        the time (an evaluation itself is not faster: benchmarks/bench_models.py).
        Each transition's noise variance is scaled by its ``noise_scales`` factor. Without
        penalties: the outputs' log evidence [E] instead (priors and bounds left out)."""
        models = self.models
        X = tf.convert_to_tensor(self._X)  # [N, D]
        Y = tf.concat([tf.convert_to_tensor(y) for y in self._Y], axis=1)  # [N, E]
        ell = tf.stack([tf.convert_to_tensor(m.kernel.lengthscales) for m in models])  # [E, D]
        sf2 = tf.stack([tf.convert_to_tensor(m.kernel.variance) for m in models])  # [E]
        sn2 = tf.stack([tf.convert_to_tensor(m.likelihood.variance) for m in models])  # [E]
        Xs = X[None, :, :] / ell[:, None, :]  # [E, N, D]
        sq = tf.reduce_sum(tf.square(Xs), axis=-1)  # [E, N]
        r2 = sq[:, :, None] + sq[:, None, :] - 2.0 * tf.matmul(Xs, Xs, transpose_b=True)
        K = sf2[:, None, None] * tf.exp(-0.5 * tf.maximum(r2, 0.0))
        noise = sn2[:, None] * tf.convert_to_tensor(self._noise_scales)  # [E, N]
        K = tf.linalg.set_diag(K, tf.linalg.diag_part(K) + noise)
        L = tf.linalg.cholesky(K)  # [E, N, N]
        alpha = tf.linalg.triangular_solve(L, tf.transpose(Y)[:, :, None], lower=True)
        n = tf.cast(tf.shape(X)[0], X.dtype)
        log_evidence = (-0.5 * tf.reduce_sum(tf.square(alpha), axis=[1, 2])
                        - tf.reduce_sum(tf.math.log(tf.linalg.diag_part(L)), axis=1)
                        - 0.5 * n * np.log(2.0 * np.pi))
        if not with_penalties:
            return log_evidence
        loss = -log_evidence + self._penalties(ell, sf2, sn2)
        if any(p.prior is not None for m in models for p in m.trainable_parameters):
            loss -= tf.stack([tf.cast(m.log_prior_density(), X.dtype) for m in models])
        return loss

    def _output_losses(self) -> tf.Tensor:
        """Training loss of every output [E]: batched when :meth:`_batchable`."""
        if self._batchable():
            return self._batched_losses()
        return tf.stack([self._model_loss(m) for m in self.models])

    def _model_losses(self) -> np.ndarray:
        return self._output_losses().numpy().astype(np.float64)

    # -- optimisation ---------------------------------------------------------------------
    def optimize(self, maxiter: int = 1000, restarts: int = 1, seed: Optional[int] = None,
                 callback: Optional[Callable[[int], None]] = None,
                 min_rel_improvement: Optional[float] = None, patience: int = 10):
        """Maximise the evidence of every output's GP with L-BFGS-B (gpflow Scipy).

        The first run starts from the current hyperparameters; each further restart starts
        from data-driven values perturbed at random. The outputs are independent, so the
        best values of each output across runs are kept (copies of the values, not
        references to the live variables). ``callback(iteration)`` is called after every
        L-BFGS iteration (progress bars; an exception it raises stops training). With
        ``min_rel_improvement``, a run stops once the summed loss (negative log evidence plus
        the soft bounds) fell by less than ``min_rel_improvement * max(1, |loss|)`` over the
        last ``patience`` iterations.
        Returns the final per-output losses [E].
        """
        maxiter = check_positive_int(maxiter, "maxiter")
        restarts = check_positive_int(restarts, "restarts")
        patience = check_positive_int(patience, "patience")
        min_rel_improvement = check_min_rel_improvement(min_rel_improvement)
        rng = generator(check_seed(seed))
        if self._scaled():  # models replaced after the factors were set would ignore them
            self._check_noise_scales_supported()
        opt = self._optimizer  # one instance: its compiled objective is reused across calls
        groups = self._selection_groups()
        best_losses = [np.inf] * len(groups)
        best_values: List[Optional[Dict[str, np.ndarray]]] = [None] * len(groups)

        def record():
            """Keep each group's best values; returns the groups whose loss is not finite."""
            try:
                losses = self._model_losses()
            except tf.errors.InvalidArgumentError:
                return list(range(len(groups)))
            failed = []
            for g, (module, idx) in enumerate(groups):
                loss = float(np.sum(losses[idx]))
                if not np.isfinite(loss):
                    failed.append(g)
                elif loss < best_losses[g]:
                    best_losses[g] = loss
                    best_values[g] = snapshot(module)
            return failed

        if record():  # never end worse than where we started
            # A singular kernel matrix (Cholesky failure) gives a NaN loss that the optimiser
            # cannot leave: start those outputs from data-driven values instead.
            logger.warning("the starting GP hyperparameters fail numerically (non-finite "
                           "loss); starting from data-driven values instead")
            self.initialize_hyperparameters()
            self._restore(groups, best_values)  # the outputs that were fine keep theirs
            record()
        for r in range(restarts):
            if r > 0:
                self.initialize_hyperparameters(rng, spread=0.5)
            opt.start_run()
            try:
                opt.minimize(self.training_loss, self.trainable_variables,
                             options=dict(maxiter=maxiter), method="L-BFGS-B",
                             step_callback=opt.step_callback(callback, min_rel_improvement,
                                                             patience, what="GP loss"))
            except Stalled as stop:
                logger.debug("GP training run %d stopped early after %d iterations", r,
                             stop.iterations)
            except (tf.errors.InvalidArgumentError, ValueError) as err:
                logger.warning(
                    "GP training run %d failed (%s); keeping the best hyperparameters so far "
                    "and raising the noise variance", r, str(err).splitlines()[0][:120],
                )
                self._restore(groups, best_values)
                for model in self.models:
                    v = float(model.likelihood.variance.numpy())
                    _assign_free(model.likelihood.variance, max(10 * v, 100 * self.noise_floor))
            failed = record()
            if failed:
                logger.warning("GP training run %d ended at a non-finite loss (a numerically "
                               "singular kernel matrix) for %d of %d output groups; keeping "
                               "the best hyperparameters so far", r, len(failed), len(groups))
        self._restore(groups, best_values)
        logger.info("GP training done: losses %s", np.round(best_losses, 3))
        return self._model_losses()

    def _selection_groups(self):
        """Modules whose values are kept together across restarts, with their outputs.

        Independent outputs are selected one by one (the best run of each output).
        """
        return [(model, [i]) for i, model in enumerate(self.models)]

    @staticmethod
    def _restore(groups, values):
        for (module, _), vals in zip(groups, values):
            if vals is not None:
                restore(module, vals)
