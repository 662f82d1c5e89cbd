"""Multi-output GP regression with moment matching at uncertain inputs.

:class:`MGPR` holds one ``gpflow.models.GPR`` per output dimension (independent GPs with
ARD squared-exponential kernels sharing the training inputs) and predicts the Gaussian
moments of all outputs at a Gaussian input exactly (Deisenroth's moment matching).

Hyperparameter safety: the likelihood (noise) variance has a hard lower bound
``noise_floor`` (default 1e-6, relative to a unit-variance target), so it cannot collapse
to 0 and make the kernel matrix singular; the training (starting values, the soft bounds
on the signal-to-noise ratio and the lengthscales, restarts, Cholesky failures) is
:mod:`pilco.models.gp_training`, whose :class:`~pilco.models.gp_training.GPTraining` is a
base class of :class:`MGPR`.

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

from typing import Callable, List, Optional

import gpflow
import numpy as np
import tensorflow as tf
from check_shapes import check_shapes, inherit_check_shapes
from gpflow.models.training_mixins import InternalDataTrainingLossMixin
from gpflow.utilities.model_utils import add_noise_cov

from .. import moments
from ..snapshots import TrackingScipy
from ..validation import (
    check_data,
    check_gaussian,
    check_noise_scales,
    check_pair,
    check_points,
    check_positive_float,
    check_ratio_bound,
    checked_arguments,
)
from .gp_training import GPTraining

__all__ = ["MGPR"]

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


class MGPR(GPTraining, InternalDataTrainingLossMixin, gpflow.models.BayesianModel):
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

    # -- the training loss (GPflow's objectives; the training: pilco.models.gp_training) --
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

    @inherit_check_shapes
    def _training_loss(self) -> tf.Tensor:
        """The outputs' losses summed (what :meth:`training_loss` returns)."""
        return tf.reduce_sum(self._output_losses())

    @inherit_check_shapes
    def maximum_log_likelihood_objective(self) -> tf.Tensor:
        """The penalised log evidence: the outputs' log evidence minus the soft bounds on
        the signal-to-noise ratios and lengthscales (:mod:`pilco.models.gp_training`),
        summed. The training loss is minus this plus the log prior density (equal up to
        rounding)."""
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
