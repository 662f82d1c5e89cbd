"""The input-independent half of a moment-matching prediction: factorising E GPs.

Everything a prediction needs that does not depend on the test input (the Cholesky
factor of the kernel matrix, ``beta = K^-1 y`` and ``K^-1``) is computed here once, by
:func:`factorize` for exact GPs and :func:`fitc_factorize` for sparse FITC GPs, so a
caller that predicts many times with the same GP (a horizon rollout during policy
optimisation) computes it once. :func:`se_kernel` is the squared-exponential kernel the
dynamics models also use for their plain (noise-free input) predictions.
"""
from __future__ import annotations

from typing import NamedTuple, Optional

import tensorflow as tf

__all__ = ["Factorization", "se_kernel", "factorize", "fitc_factorize"]


class Factorization(NamedTuple):
    """Input-independent pieces of E independent GP predictors.

    - ``centers``: [n, D] training (or inducing) inputs shared by all outputs.
    - ``beta``: [E, n] weights of the predictive mean, ``K^-1 y``.
    - ``iK``: [E, n, n] ``K^-1`` used by the predictive variance, or ``None`` for a
      deterministic GP (the RBF policy), whose variance carries no model uncertainty.
    - ``lengthscales``: [E, D]; ``variance``: [E] signal variances.
    """

    centers: tf.Tensor
    beta: tf.Tensor
    iK: Optional[tf.Tensor]
    lengthscales: tf.Tensor
    variance: tf.Tensor


def _scaled_sq_dist(X: tf.Tensor, Z: tf.Tensor, lengthscales: tf.Tensor) -> tf.Tensor:
    """[n, D], [m, D], [E, D] -> [E, n, m] squared distances scaled by each output's
    lengthscales."""
    Xs = X[None, :, :] / lengthscales[:, None, :]
    Zs = Z[None, :, :] / lengthscales[:, None, :]
    d2 = (tf.reduce_sum(tf.square(Xs), axis=-1)[:, :, None]
          + tf.reduce_sum(tf.square(Zs), axis=-1)[:, None, :]
          - 2.0 * tf.matmul(Xs, Zs, transpose_b=True))
    return tf.maximum(d2, 0.0)


def se_kernel(X: tf.Tensor, lengthscales: tf.Tensor, variance: tf.Tensor,
              Z: Optional[tf.Tensor] = None) -> tf.Tensor:
    """Squared-exponential kernel matrices k(X, Z) (Z defaults to X):
    [n, D], [E, D], [E], [m, D] -> [E, n, m]."""
    Z = X if Z is None else Z
    return variance[:, None, None] * tf.exp(-0.5 * _scaled_sq_dist(X, Z, lengthscales))


def factorize(
    X: tf.Tensor,
    Y: tf.Tensor,
    lengthscales: tf.Tensor,
    variance: tf.Tensor,
    noise: tf.Tensor,
    with_inverse: bool = True,
    noise_scales: Optional[tf.Tensor] = None,
) -> Factorization:
    """Cholesky-based pieces of E exact GPs sharing inputs X.

    Shapes: X [n, D], Y [n, E], lengthscales [E, D], variance [E], noise [E],
    noise_scales [n] or [E, n] or None -> Factorization(centers [n, D], beta [E, n],
    iK [E, n, n] or None, ...). With ``noise_scales`` transition i of output e has the
    noise variance ``noise[e] * noise_scales[i]`` (or ``noise_scales[e, i]``: a
    heteroscedastic GP); None means all ones.
    """
    n = tf.shape(X)[0]
    K = se_kernel(X, lengthscales, variance)
    if noise_scales is None:
        K += noise[:, None, None] * tf.eye(n, dtype=K.dtype)[None]
    else:
        K = tf.linalg.set_diag(K, tf.linalg.diag_part(K) + noise[:, None] * noise_scales)
    L = tf.linalg.cholesky(K)
    beta = tf.linalg.cholesky_solve(L, tf.transpose(Y)[:, :, None])[:, :, 0]
    iK = None
    if with_inverse:
        E = tf.shape(L)[0]
        eye = tf.eye(n, batch_shape=[E], dtype=K.dtype)
        iK = tf.linalg.cholesky_solve(L, eye)
    return Factorization(X, beta, iK, lengthscales, variance)


def fitc_factorize(
    X: tf.Tensor,
    Y: tf.Tensor,
    Z: tf.Tensor,
    lengthscales: tf.Tensor,
    variance: tf.Tensor,
    noise: tf.Tensor,
    jitter: float,
) -> Factorization:
    """Pieces of E sparse FITC GPs with shared inducing inputs Z.

    The FITC predictor at x is ``k(x, Z) beta`` with variance
    ``k(x, x) - k(x, Z) (Kzz^-1 - Sigma) k(Z, x)``, where
    ``Sigma = (Kzz + Kzx Lambda^-1 Kxz)^-1`` and
    ``Lambda = diag(Kxx - Qxx) + noise``, ``beta = Sigma Kzx Lambda^-1 y``.
    The returned ``iK`` is ``Kzz^-1 - Sigma``, so the moment matching of
    :func:`moment_match` applies unchanged with the inducing inputs as centers.

    Shapes: X [n, D], Y [n, E], Z [m, D], lengthscales [E, D], variance [E], noise [E]
    -> Factorization(centers [m, D], beta [E, m], iK [E, m, m], ...).
    """
    dtype = X.dtype
    m = tf.shape(Z)[0]
    E = tf.shape(lengthscales)[0]
    eye_m = tf.eye(m, batch_shape=[E], dtype=dtype)
    Kzz = se_kernel(Z, lengthscales, variance) + jitter * eye_m
    Kzx = se_kernel(Z, lengthscales, variance, X)  # [E, m, n]
    Lz = tf.linalg.cholesky(Kzz)
    A = tf.linalg.triangular_solve(Lz, Kzx, lower=True)  # Lz^-1 Kzx, [E, m, n]
    lam = variance[:, None] - tf.reduce_sum(tf.square(A), axis=1) + noise[:, None]  # [E, n]
    As = A / tf.sqrt(lam)[:, None, :]
    B = eye_m + tf.matmul(As, As, transpose_b=True)  # I + A Lambda^-1 A^T
    LB = tf.linalg.cholesky(B)
    # Sigma = Lz^-T B^-1 Lz^-1
    rhs = tf.matmul(A, (tf.transpose(Y) / lam)[:, :, None])  # A Lambda^-1 y, [E, m, 1]
    c = tf.linalg.cholesky_solve(LB, rhs)
    beta = tf.linalg.triangular_solve(Lz, c, lower=True, adjoint=True)[:, :, 0]
    # Kzz^-1 - Sigma = Lz^-T (I - B^-1) Lz^-1
    inner = eye_m - tf.linalg.cholesky_solve(LB, eye_m)
    left = tf.linalg.triangular_solve(Lz, inner, lower=True, adjoint=True)
    iK = tf.linalg.triangular_solve(Lz, tf.linalg.adjoint(left), lower=True, adjoint=True)
    iK = 0.5 * (iK + tf.linalg.adjoint(iK))
    return Factorization(Z, beta, iK, lengthscales, variance)
