"""Sparse (FITC) multi-output GP regression with moment matching at uncertain inputs."""
from __future__ import annotations

import logging
from typing import Optional

import gpflow
import tensorflow as tf
from check_shapes import check_shapes
from gpflow.config import default_jitter

from .. import moments
from ..seeding import generator
from ..validation import check_positive_int
from .mgpr import MGPR

__all__ = ["SMGPR"]

logger = logging.getLogger(__name__)


class _FITC(gpflow.models.GPRFITC):
    """GPflow's FITC regression whose data count follows data held in resizable variables
    (the :class:`SMGPR`'s: not listed among this model's parameters a second time)."""

    _TF_MODULE_IGNORED_PROPERTIES = (gpflow.models.GPRFITC._TF_MODULE_IGNORED_PROPERTIES
                                     | frozenset({"data"}))

    @property
    def num_data(self):
        return tf.cast(tf.shape(self.data[0])[0], self.data[0].dtype)

    @num_data.setter
    def num_data(self, value):  # set by the parent constructor; the data decide
        pass


class SMGPR(MGPR):
    """E independent sparse GPs (FITC) sharing one set of inducing inputs ``Z [M, D]``.

    ``models[i]`` is a ``gpflow.models.GPRFITC``; all of them hold the *same*
    ``inducing_variable``, so assigning ``models[i].inducing_variable.Z`` sets Z for every
    output. Prediction at a Gaussian input has the same API and the same exact moment
    matching as :class:`MGPR`, with the inducing inputs playing the role of the training
    inputs. Worth it once the data set is much larger than ``num_induced_points``.
    """

    def __init__(self, data, num_induced_points: int, noise_floor: float = 1e-6,
                 max_snr: float = 500.0, max_lengthscale_ratio: float = 100.0,
                 seed: Optional[int] = None, name: Optional[str] = None):
        self.num_induced_points = check_positive_int(num_induced_points, "num_induced_points")
        self._seed = seed
        super().__init__(data, noise_floor=noise_floor, max_snr=max_snr,
                         max_lengthscale_ratio=max_lengthscale_ratio, name=name)

    def _build_models(self, X, Y):
        rng = generator(self._seed)
        M = self.num_induced_points
        rows = rng.choice(len(X), size=M, replace=len(X) < M)
        Z = X[rows] + (1e-3 * rng.standard_normal((M, X.shape[1])) if len(X) < M else 0.0)
        self.inducing_variable = gpflow.inducing_variables.InducingPoints(Z)
        return [
            _FITC(
                (self._X, self._Y[i]), kernel=self._new_kernel(),
                inducing_variable=self.inducing_variable, likelihood=self._new_likelihood(),
            )
            for i in range(self.num_outputs)
        ]

    @property
    def Z(self) -> tf.Tensor:
        """Inducing inputs [M, D]."""
        return tf.convert_to_tensor(self.inducing_variable.Z)

    def factorize(self) -> moments.Factorization:
        """FITC prediction pieces on the inducing inputs (beta, Kzz^-1 - Sigma)."""
        ell, sf2, sn2 = self.hyperparameters()
        return moments.fitc_factorize(self.X, self.Y, self.Z, ell, sf2, sn2, default_jitter())

    @check_shapes("return: [E]")
    def log_marginal_likelihood(self) -> tf.Tensor:
        """FITC approximation of each output's log evidence, [E] (priors excluded)."""
        return tf.stack([m.maximum_log_likelihood_objective() for m in self.models])

    def _check_noise_scales_supported(self) -> None:
        raise ValueError("SMGPR (FITC) has one noise variance per output: noise_scales "
                         "other than 1 need the exact MGPR")

    def _selection_groups(self):
        """The outputs share Z, so restarts are compared on the summed loss."""
        return [(self, list(range(self.num_outputs)))]
