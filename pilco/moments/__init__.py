"""Exact moment matching of squared-exponential GP predictions at a Gaussian input.

The numerical core shared by the dynamics models (:class:`~pilco.models.MGPR`,
:class:`~pilco.models.SMGPR`) and the RBF policy: given E independent GPs with
squared-exponential kernels that share their training (or inducing) inputs, and a
Gaussian input ``x ~ N(m, s)``, it returns the mean ``M``, covariance ``S`` of ``f(x)``
and ``V = inv(s) Cov[x, f(x)]``. A prediction runs in three steps: factorise once,
prepare once, predict per input.

=================  ==============================================================
module             job
=================  ==============================================================
``factorization``  :func:`factorize` (exact GPs), :func:`fitc_factorize` (sparse
                   FITC GPs), :func:`se_kernel`: the input-independent pieces
                   (``beta = K^-1 y``, ``K^-1``) as a :class:`Factorization`
``pairs``          the E(E+1)/2 symmetric output pairs of the covariance: their
                   indices, weights, the fused block with its hand-made gradient,
                   and :func:`pair_groups`, the parts that run side by side
``prediction``     :func:`prepare` (a :class:`Predictor`), :func:`predict` at one
                   Gaussian input, :func:`moment_match` (both in one call),
                   :func:`point_means` at many known inputs
``compiled``       what XLA needs: log-determinants without ``slogdet``
                   (:func:`xla_compatible`), factorisations padded to fixed sizes
                   (:func:`pad_factorization`, :func:`bucket_size`)
=================  ==============================================================

The public names below are importable from :mod:`pilco.moments` itself.
"""
from .compiled import bucket_size, pad_factorization, xla_compatible
from .factorization import Factorization, factorize, fitc_factorize, se_kernel
from .pairs import MAX_PAIR_GROUPS, pair_groups, pair_weights, symmetric_pairs
from .prediction import Predictor, eye_like, moment_match, point_means, predict, prepare

__all__ = [
    "Factorization",
    "Predictor",
    "prepare",
    "predict",
    "factorize",
    "fitc_factorize",
    "se_kernel",
    "eye_like",
    "symmetric_pairs",
    "pair_weights",
    "pair_groups",
    "MAX_PAIR_GROUPS",
    "moment_match",
    "point_means",
    "xla_compatible",
    "pad_factorization",
    "bucket_size",
]
