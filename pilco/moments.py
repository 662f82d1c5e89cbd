"""Exact moment matching of squared-exponential GP predictions at a Gaussian input.

This module holds the numerical core shared by the dynamics models (:class:`MGPR`,
:class:`SMGPR`) and the RBF policy: given E independent GPs with squared-exponential
kernels that share their training (or inducing) inputs, and a Gaussian input
``x ~ N(m, s)``, it returns the mean ``M``, covariance ``S`` of ``f(x)`` and
``V = inv(s) Cov[x, f(x)]``.

Everything a prediction needs that does not depend on the test input (the Cholesky
factor of the kernel matrix, ``beta = K^-1 y`` and ``K^-1``) is computed separately by
:func:`factorize`, so a caller that predicts many times with the same GP (a horizon
rollout during policy optimisation) computes it once.

The E x E output covariance is symmetric: only its E(E+1)/2 upper-triangular pairs
are evaluated, batched in one tensor, and the two quadratic terms of each pair's
exponent are folded into one matrix product so that each pair costs one n x n
``exp`` and one contraction.
"""
from __future__ import annotations

from typing import NamedTuple, Optional

import numpy as np
import tensorflow as tf
from gpflow.config import default_float

__all__ = [
    "Factorization",
    "factorize",
    "fitc_factorize",
    "symmetric_pairs",
    "pair_weights",
    "moment_match",
]


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


def _scaled_sq_dist(X: tf.Tensor, lengthscales: tf.Tensor) -> tf.Tensor:
    """[n, D], [E, D] -> [E, n, n] squared distances scaled by each output's lengthscales."""
    Xs = X[None, :, :] / lengthscales[:, None, :]
    sq = tf.reduce_sum(tf.square(Xs), axis=-1)
    d2 = sq[:, :, None] + sq[:, None, :] - 2.0 * tf.matmul(Xs, Xs, transpose_b=True)
    return tf.maximum(d2, 0.0)


def se_kernel(X: tf.Tensor, lengthscales: tf.Tensor, variance: tf.Tensor) -> tf.Tensor:
    """Squared-exponential kernel matrices: [n, D], [E, D], [E] -> [E, n, n]."""
    return variance[:, None, None] * tf.exp(-0.5 * _scaled_sq_dist(X, lengthscales))


def factorize(
    X: tf.Tensor,
    Y: tf.Tensor,
    lengthscales: tf.Tensor,
    variance: tf.Tensor,
    noise: tf.Tensor,
    with_inverse: bool = True,
) -> Factorization:
    """Cholesky-based pieces of E exact GPs sharing inputs X.

    Shapes: X [n, D], Y [n, E], lengthscales [E, D], variance [E], noise [E]
    -> Factorization(centers [n, D], beta [E, n], iK [E, n, n] or None, ...).
    """
    n = tf.shape(X)[0]
    K = se_kernel(X, lengthscales, variance)
    K += noise[:, None, None] * tf.eye(n, dtype=K.dtype)[None]
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
    Zs = Z[None] / lengthscales[:, None, :]
    Xs = X[None] / lengthscales[:, None, :]
    d2 = (
        tf.reduce_sum(tf.square(Zs), -1)[:, :, None]
        + tf.reduce_sum(tf.square(Xs), -1)[:, None, :]
        - 2.0 * tf.matmul(Zs, Xs, transpose_b=True)
    )
    Kzx = variance[:, None, None] * tf.exp(-0.5 * tf.maximum(d2, 0.0))  # [E, m, n]
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


def symmetric_pairs(E: int):
    """Index arrays of the upper-triangular pairs of an E x E symmetric matrix.

    Returns (I [P], J [P], index [E, E]) with P = E(E+1)/2, where ``index[a, b]`` is the
    position of pair (min(a, b), max(a, b)); ``I == J`` marks the diagonal pairs.
    """
    I, J = np.triu_indices(E)
    index = np.zeros((E, E), dtype=np.int32)
    index[I, J] = np.arange(len(I))
    index[J, I] = np.arange(len(I))
    return I.astype(np.int32), J.astype(np.int32), index


def pair_weights(beta: tf.Tensor, iK: Optional[tf.Tensor]) -> tf.Tensor:
    """Weights W of the output covariance, one n x n matrix per symmetric output pair.

    ``W[p] = beta_i beta_j^T - [i == j] iK_i`` for pair p = (i, j), so that the
    non-central second moment of a pair is ``t_p * sum(Q_p * W_p)``.
    Shapes: beta [E, n], iK [E, n, n] or None -> [P, n, n], P = E(E+1)/2.
    """
    E = beta.shape[0]
    I, J, _ = symmetric_pairs(E)
    W = tf.gather(beta, I)[:, :, None] * tf.gather(beta, J)[:, None, :]
    if iK is not None:
        diag = tf.constant((I == J).astype(np.float64), dtype=beta.dtype)
        W -= diag[:, None, None] * tf.gather(iK, I)
    return W


def _logdet_from_chol(L: tf.Tensor) -> tf.Tensor:
    return 2.0 * tf.reduce_sum(tf.math.log(tf.linalg.diag_part(L)), axis=-1)


def moment_match(
    m: tf.Tensor,
    s: tf.Tensor,
    fact: Factorization,
    W: Optional[tf.Tensor] = None,
    deterministic: Optional[bool] = None,
    deterministic_jitter: float = 1e-6,
):
    """Mean, covariance and input-output covariance of E GPs at x ~ N(m, s).

    Shapes: m [1, D], s [D, D], ``fact`` from :func:`factorize` (or :func:`fitc_factorize`),
    optional ``W`` [P, n, n] from :func:`pair_weights` (computed here when omitted)
    -> M [1, E], S [E, E], V [D, E] with ``V = inv(s) Cov[x, f(x)]``.

    For a deterministic GP (``deterministic``, by default ``fact.iK is None``) the covariance holds no model
    uncertainty and ``deterministic_jitter`` is added to its diagonal; otherwise the
    latent variance ``sf^2 - tr(K^-1 Q)`` is included (observation noise is not).
    """
    centers, beta, iK, ell, sf2 = fact
    dtype = beta.dtype
    D = tf.shape(centers)[1]
    E = beta.shape[0]
    eyeD = tf.eye(D, dtype=dtype)

    inp = centers - m  # [n, D]
    iL = 1.0 / ell  # [E, D]
    iN = inp[None, :, :] * iL[:, None, :]  # [E, n, D]

    # Mean and inv(s) Cov[x, f(x)].
    B = iL[:, :, None] * s[None, :, :] * iL[:, None, :] + eyeD  # [E, D, D]
    LB = tf.linalg.cholesky(B)
    t = tf.linalg.adjoint(tf.linalg.cholesky_solve(LB, tf.linalg.adjoint(iN)))  # [E, n, D]
    lb = tf.exp(-0.5 * tf.reduce_sum(iN * t, axis=-1)) * beta  # [E, n]
    c = sf2 * tf.exp(-0.5 * _logdet_from_chol(LB))  # [E]
    M = c * tf.reduce_sum(lb, axis=-1)  # [E]
    V = c[:, None] * tf.einsum("end,en->ed", t * iL[:, None, :], lb)  # [E, D]

    # Non-central second moments, one entry per symmetric output pair (i <= j).
    I, J, index = symmetric_pairs(E)
    k = tf.math.log(sf2)[:, None] - 0.5 * tf.reduce_sum(tf.square(iN), axis=-1)  # [E, n]
    iL2 = tf.square(iL)
    ii = inp[None, :, :] * iL2[:, None, :]  # [E, n, D]
    Pd = tf.gather(iL2, I) + tf.gather(iL2, J)  # [P, D]
    sqP = tf.sqrt(Pd)
    # R = s diag(P) + I; det R = det(A) and R^-1 s = P^-1/2 A^-1 P^1/2 s with
    # A = P^1/2 s P^1/2 + I symmetric positive definite.
    A = sqP[:, :, None] * s[None] * sqP[:, None, :] + eyeD
    LA = tf.linalg.cholesky(A)
    T = tf.linalg.cholesky_solve(LA, sqP[:, :, None] * s[None]) / sqP[:, :, None]
    T = 0.5 * (T + tf.linalg.adjoint(T))  # [P, D, D]
    tP = tf.exp(-0.5 * _logdet_from_chol(LA))  # [P]
    iiI = tf.gather(ii, I)
    iiJ = tf.gather(ii, J)
    aI = tf.matmul(iiI, T)  # [P, n, D]
    aJ = tf.matmul(iiJ, T)
    u = tf.gather(k, I) + 0.5 * tf.reduce_sum(aI * iiI, axis=-1)  # [P, n]
    v = tf.gather(k, J) + 0.5 * tf.reduce_sum(aJ * iiJ, axis=-1)
    ones = tf.ones_like(u)[:, :, None]
    # exponent_ab = u_a + v_b + iiI_a^T T iiJ_b as a single product of augmented factors
    left = tf.concat([aI, u[:, :, None], ones], axis=-1)
    right = tf.concat([iiJ, ones, v[:, :, None]], axis=-1)
    Q = tf.exp(tf.matmul(left, right, transpose_b=True))  # [P, n, n]
    if W is None:
        W = pair_weights(beta, iK)
    S_pairs = tP * tf.einsum("pab,pab->p", Q, W)  # [P]
    S = tf.gather(S_pairs, index)  # [E, E]
    if deterministic is None:
        deterministic = iK is None
    if deterministic:
        S += deterministic_jitter * tf.eye(E, dtype=dtype)
    else:
        S += tf.linalg.diag(sf2)
    S -= M[:, None] * M[None, :]
    return M[None, :], S, tf.transpose(V)
