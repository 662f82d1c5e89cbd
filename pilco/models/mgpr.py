"""Multi-output GP regression with moment matching at uncertain inputs.

:class:`MGPR` holds one ``gpflow.models.GPR`` per output dimension (independent GPs with
ARD squared-exponential kernels sharing the training inputs) and predicts the Gaussian
moments of all outputs at a Gaussian input exactly (Deisenroth's moment matching).

Hyperparameter safety (documented defaults):

- the likelihood (noise) variance has a hard lower bound ``noise_floor`` (default 1e-6,
  relative to a unit-variance target), so it cannot collapse to 0 and make the kernel
  matrix singular;
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

Per-transition noise: ``set_data(data, noise_scales=w)`` gives transition i the noise
variance ``w[i]`` times its output's noise variance (a heteroscedastic GP; all ones by
default and after every ``set_data`` without ``w``); ``w [E, N]`` gives each output its
own factors, ``w[e, i]`` for output e (e.g. old data forgotten by the outputs they
contradict and kept by the others). A large factor down-weights a
transition: where better-trusted data disagree with it the posterior follows them, where
it is alone it still shapes the prediction. Training, :meth:`MGPR.factorize` (so moment
matching and the policy search), :meth:`MGPR.predict_f` and
:meth:`MGPR.log_marginal_likelihood` use the factors; they need the plain GPR outputs
this class builds (not a sparse model).

GPflow conventions: :class:`MGPR` is a ``gpflow.models.BayesianModel`` with its data
inside (``InternalDataTrainingLossMixin``): :meth:`~MGPR.training_loss` (what
:meth:`~MGPR.optimize` minimises, so ``gpflow.optimizers.Scipy().minimize(
model.training_loss, model.trainable_variables)`` trains it too),
:meth:`~MGPR.maximum_log_likelihood_objective`, ``log_prior_density``,
``training_loss_closure``; :meth:`~MGPR.predict_f`, :meth:`~MGPR.predict_y` and
:meth:`~MGPR.predict_log_density` as GPflow defines them for P = E independent outputs.
Every public computation returns tensors and runs inside ``tf.function``; its inputs
follow :mod:`pilco.validation.inputs` (converted to float64, checked before TensorFlow
sees them). ``print_summary`` lists the hyperparameters only (the data are not
parameters).
"""
from __future__ import annotations

import logging
from typing import Callable, Dict, List, Optional

import gpflow
import numpy as np
import tensorflow as tf
from check_shapes import check_shapes, inherit_check_shapes
from gpflow.models.training_mixins import InternalDataTrainingLossMixin
from gpflow.utilities.model_utils import add_noise_cov

from .. import moments
from ..seeding import generator
from ..snapshots import Stalled, TrackingScipy, restore, snapshot
from ..validation import (
    check_data,
    check_gaussian,
    check_min_rel_improvement,
    check_noise_scales,
    check_pair,
    check_points,
    check_positive_float,
    check_positive_int,
    check_ratio_bound,
    check_seed,
    checked_arguments,
)

__all__ = ["MGPR"]

logger = logging.getLogger(__name__)

#: shapes of a prediction at new inputs, GPflow's layout for ``full_cov`` and
#: ``full_output_cov`` (``predict_f``, ``predict_y``)
_PREDICTION_SHAPES = check_shapes(
    "Xnew: [N, D]",
    "return[0]: [N, E]",
    "return[1]: [N, E, N, E] if full_cov and full_output_cov",
    "return[1]: [E, N, N] if full_cov and (not full_output_cov)",
    "return[1]: [N, E, E] if (not full_cov) and full_output_cov",
    "return[1]: [N, E] if (not full_cov) and (not full_output_cov)",
)


def _assign_free(param: gpflow.Parameter, value) -> None:
    """Assign ``value`` unless ``param`` is fixed (non-trainable): set by the user, kept."""
    if param.trainable:
        param.assign(value)


class _SharedDataGPR(gpflow.models.GPR):
    """A ``gpflow.models.GPR`` whose data are variables its :class:`MGPR` owns: they are
    not listed among its parameters (``print_summary``, ``parameter_dict``) a second time."""

    _TF_MODULE_IGNORED_PROPERTIES = (gpflow.models.GPR._TF_MODULE_IGNORED_PROPERTIES
                                     | frozenset({"data"}))


def _check_Xnew(model: "MGPR", arguments) -> None:
    arguments["Xnew"] = check_points(arguments["Xnew"], model.num_dims, "Xnew")


def _check_data_pair(model: "MGPR", arguments) -> None:
    X, Y = check_pair(arguments["data"], "data")
    X = check_points(X, model.num_dims, "data X")
    Y = check_points(Y, model.num_outputs, "data Y")
    rows_X, rows_Y = X.shape[0], Y.shape[0]  # None when traced with unknown sizes
    if rows_X is not None and rows_Y is not None and rows_X != rows_Y:
        raise ValueError(f"data: X and Y must have the same number of rows, got "
                         f"{rows_X} and {rows_Y}")
    arguments["data"] = (X, Y)


def _check_input_gaussian(model: "MGPR", arguments) -> None:
    arguments["m"], arguments["s"] = check_gaussian(arguments["m"], arguments["s"],
                                                    model.num_dims, "input")


def _output_covariance(var, full_cov: bool, full_output_cov: bool):
    """Variances of independent outputs in GPflow's layout: [N, E] or [E, N, N] (full_cov)
    -> with ``full_output_cov`` the diagonal output covariances [N, E, E] or the full
    covariance [N, E, N, E] (zero between outputs)."""
    if not full_output_cov:
        return var
    if not full_cov:
        return tf.linalg.diag(var)
    eye = tf.eye(tf.shape(var)[0], dtype=var.dtype)
    return tf.einsum("enm,ef->nemf", var, eye)


class MGPR(InternalDataTrainingLossMixin, gpflow.models.BayesianModel):
    """E independent GPs on shared inputs: ``X [N, D] -> Y [N, E]``.

    ``models[i]`` is the ``gpflow.models.GPR`` of output i; assign hyperparameters on
    ``models[i].kernel.lengthscales``, ``.kernel.variance`` and ``.likelihood.variance``.
    The data live in ``tf.Variable``s, so :meth:`set_data` never invalidates compiled code.
    A GPflow model (see the module doc): train it with :meth:`optimize` or any GPflow
    optimiser on :meth:`training_loss`, predict with :meth:`predict_f`,
    :meth:`predict_y`, :meth:`predict_log_density` and, at a Gaussian input,
    :meth:`predict_on_noisy_inputs`.
    """

    # the data (their own variables) are not parameters: print_summary shows none of them
    _TF_MODULE_IGNORED_PROPERTIES = (gpflow.models.BayesianModel._TF_MODULE_IGNORED_PROPERTIES
                                     | frozenset({"_X", "_Y", "_noise_scales"}))

    def __init__(self, data, noise_floor: float = 1e-6, max_snr: float = 500.0,
                 max_lengthscale_ratio: float = 100.0, name: Optional[str] = None):
        super().__init__(name=name)
        self._data_listeners: List[Callable[[np.ndarray, np.ndarray], None]] = []
        self.max_snr = check_ratio_bound(max_snr, "max_snr")
        self.max_lengthscale_ratio = check_ratio_bound(max_lengthscale_ratio,
                                                       "max_lengthscale_ratio")
        X, Y = check_data(data, "data")
        self.noise_floor = check_positive_float(noise_floor, "noise_floor")
        self.num_outputs = Y.shape[1]
        self.num_dims = X.shape[1]
        self._X = tf.Variable(X, shape=[None, self.num_dims], trainable=False, name="X")
        self._Y = [
            tf.Variable(Y[:, i : i + 1], shape=[None, 1], trainable=False, name=f"Y{i}")
            for i in range(self.num_outputs)
        ]
        # factor of each output's and transition's noise variance [E, N] (module doc)
        self._noise_scales = tf.Variable(np.ones((self.num_outputs, len(X))),
                                         shape=[self.num_outputs, None], trainable=False,
                                         name="noise_scales")
        self.models: List[gpflow.models.GPModel] = self._build_models(X, Y)
        self._optimizer = TrackingScipy()
        self.initialize_hyperparameters()

    # -- construction -------------------------------------------------------------------
    def _new_kernel(self):
        return gpflow.kernels.SquaredExponential(lengthscales=np.ones(self.num_dims))

    def _new_likelihood(self):
        return gpflow.likelihoods.Gaussian(variance=0.01, variance_lower_bound=self.noise_floor)

    def _build_models(self, X, Y):
        return [
            _SharedDataGPR(
                (self._X, self._Y[i]), kernel=self._new_kernel(), likelihood=self._new_likelihood()
            )
            for i in range(self.num_outputs)
        ]

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

    # -- data -----------------------------------------------------------------------------
    @property
    def X(self) -> tf.Tensor:
        """Training inputs [N, D]."""
        return tf.convert_to_tensor(self._X)

    @property
    def Y(self) -> tf.Tensor:
        """Training targets [N, E]."""
        return tf.concat([tf.convert_to_tensor(y) for y in self._Y], axis=1)

    @property
    def data(self):
        return self.X, self.Y

    @property
    def noise_scales(self) -> np.ndarray:
        """Factor of each transition's noise variance: [N] when every output has the same
        factors (ones unless :meth:`set_data` was given others), else [E, N]."""
        scales = self._noise_scales.numpy().copy()
        if np.all(scales == scales[:1]):
            return scales[0]
        return scales

    def set_data(self, data, noise_scales=None):
        """Replace the training data; shapes ``X [N, D]``, ``Y [N, E]`` (N may change),
        ``noise_scales`` positive factors of each transition's noise variance, [N] or per
        output [E, N] (None: all ones; see the module doc).

        Every listener (see :meth:`add_data_listener`) sees the data first and may refuse
        them by raising; the model is then unchanged.
        """
        X, Y = check_data(data, "data", x_dim=self.num_dims, y_dim=self.num_outputs)
        scales = self._checked_noise_scales(noise_scales, len(X))
        for listener in list(self._data_listeners):
            listener(X, Y)
        self._X.assign(X)
        for i, y in enumerate(self._Y):
            y.assign(Y[:, i : i + 1])
        self._noise_scales.assign(scales)

    def set_noise_scales(self, noise_scales) -> None:
        """Set the factors of the current transitions' noise variances, ``[N]`` or
        ``[E, N]`` positive (None: all ones), keeping the data."""
        self._noise_scales.assign(
            self._checked_noise_scales(noise_scales, int(tf.shape(self._X)[0])))

    def _checked_noise_scales(self, noise_scales, size: int) -> np.ndarray:
        """``noise_scales`` checked for ``size`` transitions and for this model (factors
        other than 1 need :meth:`_check_noise_scales_supported`), as [E, size]."""
        scales = check_noise_scales(noise_scales, size, outputs=self.num_outputs)
        if np.any(scales != 1.0):
            self._check_noise_scales_supported()
        return np.broadcast_to(scales, (self.num_outputs, size)).copy()

    def _check_noise_scales_supported(self) -> None:
        if not self._batchable():
            raise ValueError("noise_scales other than 1 need the plain GPR outputs with "
                             "squared-exponential kernels and Gaussian likelihoods that MGPR "
                             "builds; these models were replaced")

    def _scaled(self) -> bool:
        """Whether some transition's noise factor differs from 1."""
        return bool(np.any(self._noise_scales.numpy() != 1.0))

    def add_data_listener(self, listener: Callable[[np.ndarray, np.ndarray], None]) -> None:
        """Call ``listener(X [N, D], Y [N, E])`` (checked float64 arrays) on every
        :meth:`set_data`, before the data are assigned; raising refuses the data."""
        self._data_listeners.append(listener)

    def remove_data_listener(self, listener) -> None:
        """Stop calling ``listener`` (added by :meth:`add_data_listener`; no error if absent)."""
        self._data_listeners[:] = [f for f in self._data_listeners if f != listener]

    # -- hyperparameters ------------------------------------------------------------------
    def hyperparameters(self):
        """Stacked hyperparameters: lengthscales [E, D], signal variance [E], noise [E]."""
        ell = tf.stack([tf.convert_to_tensor(m.kernel.lengthscales) for m in self.models])
        sf2 = tf.stack([tf.convert_to_tensor(m.kernel.variance) for m in self.models])
        sn2 = tf.stack([tf.convert_to_tensor(m.likelihood.variance) for m in self.models])
        return ell, sf2, sn2

    @property
    def noise_variance(self) -> tf.Tensor:
        """Likelihood variances [E]."""
        return self.hyperparameters()[2]

    def factorize(self) -> moments.Factorization:
        """Input-independent prediction pieces (beta, K^-1) for the current hyperparameters."""
        ell, sf2, sn2 = self.hyperparameters()
        return moments.factorize(self.X, self.Y, ell, sf2, sn2,
                                 noise_scales=tf.convert_to_tensor(self._noise_scales))

    # -- prediction -----------------------------------------------------------------------
    @checked_arguments(_check_input_gaussian)
    @check_shapes(
        "m: [1, D]",
        "s: [D, D]",
        "return[0]: [1, E]",
        "return[1]: [E, E]",
        "return[2]: [D, E]",
    )
    def predict_on_noisy_inputs(self, m, s):
        """Moments of f(x) at x ~ N(m, s), exactly.

        Shapes: m [1, D] (or [D]), s [D, D] -> M [1, E], S [E, E], V [D, E] with
        ``V = inv(s) Cov[x, f(x)]``. ``S`` is the latent covariance (no observation noise).
        """
        return moments.moment_match(m, s, self.factorize())

    def _latent(self, Xnew, full_cov: bool):
        """Latent mean [N*, E] and variance [N*, E] or covariance [E, N*, N*]."""
        if not self._batchable():  # sparse or replaced models: their own predictions
            means, vars_ = zip(*(m.predict_f(Xnew, full_cov=full_cov) for m in self.models))
            return tf.concat(means, axis=1), tf.concat(vars_, axis=1 - int(full_cov))
        # GPflow's GPR prediction (its kernels and conditional) with each transition's
        # noise variance scaled by its factor: GPR's own numbers when the factors are 1
        X = tf.convert_to_tensor(self._X)
        scales = tf.convert_to_tensor(self._noise_scales)
        means, vars_ = [], []
        for e, model in enumerate(self.models):
            noise = tf.convert_to_tensor(model.likelihood.variance) * scales[e]
            Kmm = add_noise_cov(model.kernel(X), noise)
            Kmn = model.kernel(X, Xnew)
            Knn = model.kernel(Xnew, full_cov=full_cov)
            mean, var = gpflow.conditionals.base_conditional(
                Kmn, Kmm, Knn, tf.convert_to_tensor(self._Y[e]), full_cov=full_cov,
                white=False)
            means.append(mean)
            vars_.append(var)
        return tf.concat(means, axis=1), tf.concat(vars_, axis=1 - int(full_cov))

    @checked_arguments(_check_Xnew)
    @_PREDICTION_SHAPES
    def predict_f(self, Xnew, full_cov: bool = False, full_output_cov: bool = False):
        """Latent mean and variance at deterministic inputs, as GPflow defines them.

        Shapes: Xnew [N*, D] -> mean [N*, E] and variance [N*, E]; with ``full_cov`` the
        covariance between the inputs [E, N*, N*], with ``full_output_cov`` the covariance
        between the outputs ([N*, E, E], or [N*, E, N*, E] with both; the outputs are
        independent, so it is zero off the outputs' diagonal). The noise factors of the
        training transitions (``noise_scales``) are used.
        """
        mean, var = self._latent(Xnew, bool(full_cov))
        return mean, _output_covariance(var, bool(full_cov), bool(full_output_cov))

    @checked_arguments(_check_Xnew)
    @_PREDICTION_SHAPES
    def predict_y(self, Xnew, full_cov: bool = False, full_output_cov: bool = False):
        """Mean and variance of new observations: :meth:`predict_f` plus each output's
        noise variance (that of a new transition, factor 1), on the diagonal when
        ``full_cov``. Shapes as :meth:`predict_f`."""
        full_cov = bool(full_cov)
        mean, var = self._latent(Xnew, full_cov)
        noise = self.noise_variance  # [E]
        if full_cov:
            var = add_noise_cov(var, noise[:, None])
        else:
            var = var + noise
        return mean, _output_covariance(var, full_cov, bool(full_output_cov))

    @checked_arguments(_check_data_pair)
    @check_shapes(
        "data[0]: [N, D]",
        "data[1]: [N, E]",
        "return: [N]",
    )
    def predict_log_density(self, data, full_cov: bool = False,
                            full_output_cov: bool = False):
        """Log density of observations ``data = (X [N, D], Y [N, E])`` under
        :meth:`predict_y`, summed over the outputs: [N]. As in GPflow, only the
        point-wise density is available (``full_cov`` and ``full_output_cov`` False)."""
        if full_cov or full_output_cov:
            raise NotImplementedError("predict_log_density is point-wise: full_cov and "
                                      "full_output_cov must be False (as in GPflow)")
        X, Y = data
        mean, var = self.predict_y(X)
        return tf.reduce_sum(gpflow.logdensities.gaussian(Y, mean, var), axis=-1)

    # -- training -------------------------------------------------------------------------
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

    def _batchable(self) -> bool:
        """Every output is a plain GPR with an ARD squared-exponential kernel on all inputs,
        a Gaussian likelihood and a zero mean (the models this class builds): their losses
        can then be computed as one batch (:meth:`_batched_losses`)."""
        return all(
            type(m) in (gpflow.models.GPR, _SharedDataGPR)
            and type(m.kernel) is gpflow.kernels.SquaredExponential
            and m.kernel.active_dims == slice(None, None, None)
            and type(m.likelihood) is gpflow.likelihoods.Gaussian
            and type(m.mean_function) is gpflow.mean_functions.Zero
            for m in self.models)

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

    @inherit_check_shapes
    def _training_loss(self) -> tf.Tensor:
        """The outputs' losses summed (what :meth:`training_loss` returns)."""
        return tf.reduce_sum(self._output_losses())

    @inherit_check_shapes
    def maximum_log_likelihood_objective(self) -> tf.Tensor:
        """The penalised log evidence: the outputs' log evidence minus the soft bounds on
        the signal-to-noise ratios and lengthscales (module doc), summed. The training
        loss is minus this plus the log prior density (equal up to rounding)."""
        if self._batchable():
            ell, sf2, sn2 = self.hyperparameters()
            objective = (self._batched_losses(with_penalties=False)
                         - self._penalties(ell, sf2, sn2))
        else:
            objective = tf.stack([m.maximum_log_likelihood_objective() - self._penalty(m)
                                  for m in self.models])
        return tf.reduce_sum(objective)

    @check_shapes("return: [E]")
    def log_marginal_likelihood(self) -> tf.Tensor:
        """Log evidence of each output's GP, [E] (priors and soft bounds excluded)."""
        per_model = lambda: tf.stack(  # noqa: E731 - GPflow's own value per output
            [m.log_marginal_likelihood() for m in self.models])
        if not self._batchable():
            return per_model()
        scaled = tf.reduce_any(tf.not_equal(tf.convert_to_tensor(self._noise_scales), 1.0))
        return tf.cond(scaled, lambda: self._batched_losses(with_penalties=False), per_model)

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
