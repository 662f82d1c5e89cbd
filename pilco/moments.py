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
``exp`` and one contraction. With constant dynamics-GP weights (policy optimisation) the
pairs are split into :func:`pair_groups`, independent parts of the graph that
TensorFlow's inter-op threads run side by side (each pair's arithmetic is unchanged).
"""
from __future__ import annotations

import os
from typing import List, NamedTuple, Optional, Tuple

import numpy as np
import tensorflow as tf

__all__ = [
    "Factorization",
    "Predictor",
    "prepare",
    "predict",
    "factorize",
    "fitc_factorize",
    "symmetric_pairs",
    "pair_weights",
    "pair_groups",
    "moment_match",
]

#: at most this many groups of output pairs (:func:`pair_groups`)
MAX_PAIR_GROUPS = 4


def _parallel_threads() -> int:
    """TensorFlow's inter-op threads: the number configured (``tf.config.threading`` or
    ``TF_NUM_INTEROP_THREADS``), else the CPUs this process may use."""
    configured = tf.config.threading.get_inter_op_parallelism_threads()
    if configured:
        return int(configured)
    try:
        configured = int(os.environ.get("TF_NUM_INTEROP_THREADS", "0"))
    except ValueError:
        configured = 0
    if configured > 0:
        return configured
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def pair_groups(P: int, E: int, groups: Optional[int] = None) -> List[Tuple[int, int]]:
    """Consecutive ranges ``[(start, stop), ...]`` of the P output pairs of
    :func:`symmetric_pairs` for E outputs, the first one holding the E diagonal pairs.

    Each group's share of the pair block is an independent part of the compiled graph, so
    TensorFlow runs the groups side by side on its inter-op threads: one group's batched
    operations, split over threads, leave the other cores partly idle at these sizes,
    while independent groups keep every core busy (timings: docs/performance.md).
    ``groups`` defaults to the inter-op threads (at most :data:`MAX_PAIR_GROUPS`, at
    least 1); with one thread a single group (the unsplit block) is used.
    """
    if groups is None:
        groups = min(_parallel_threads(), MAX_PAIR_GROUPS)
    groups = max(1, min(int(groups), P - E + 1))
    bounds = [int(round(b)) for b in np.linspace(0, P, groups + 1)]
    bounds[1] = max(bounds[1], E)
    return [(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


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


def symmetric_pairs(E: int):
    """Index arrays of the upper-triangular pairs of an E x E symmetric matrix.

    Returns (I [P], J [P], index [E, E]) with P = E(E+1)/2, where ``index[a, b]`` is the
    position of pair (min(a, b), max(a, b)); ``I == J`` marks the diagonal pairs, which
    come first (pair p < E is (p, p)), followed by the pairs i < j in row order.
    """
    I, J = np.triu_indices(E, k=1)
    I = np.concatenate([np.arange(E), I])
    J = np.concatenate([np.arange(E), J])
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


def _pair_exponent_factors(T, iiI, iiJ, kI, kJ):
    """Augmented factors whose product is each pair's n x n exponent.

    ``exponent_ab = u_a + v_b + iiI_a^T T iiJ_b`` with ``u = kI + iiI^T T iiI / 2`` and
    ``v = kJ + iiJ^T T iiJ / 2`` equals ``leftT_a^T rightT_b`` for
    ``leftT = [T iiI; u; 1]`` and ``rightT = [iiJ; 1; v]``.
    Shapes: T [P, D, D], iiI/iiJ [P, D, n], kI/kJ [P, n] -> aI, aJ [P, D, n],
    leftT, rightT [P, D + 2, n].
    """
    aI = tf.matmul(T, iiI)
    aJ = tf.matmul(T, iiJ)
    u = kI + 0.5 * tf.reduce_sum(aI * iiI, axis=1)
    v = kJ + 0.5 * tf.reduce_sum(aJ * iiJ, axis=1)
    u, v = tf.expand_dims(u, 1), tf.expand_dims(v, 1)
    ones = tf.ones_like(u)
    leftT = tf.concat([aI, u, ones], axis=1)
    rightT = tf.concat([iiJ, ones, v], axis=1)
    return aI, aJ, leftT, rightT


def _pair_second_moments(T, mI, mJ, kI, kJ, XI, XJ, bI, bJ, iK):
    """``sum_ab W[p]_ab exp(exponent[p]_ab)`` per output pair p, with a hand-made gradient.

    The exponent of pair p = (i, j) is ``u_a + v_b + iiI_a^T T iiJ_b`` where
    ``iiI = XI - mI`` (centers minus the input mean, over ``l_i^2``), ``iiJ = XJ - mJ``,
    ``u = kI + iiI^T T iiI / 2`` and ``v = kJ + iiJ^T T iiJ / 2`` (see
    :func:`_pair_exponent_factors`); the weights are ``W[p] = bI bJ^T - [i == j] iK_i``
    (:func:`pair_weights`), the diagonal pairs first (:func:`symmetric_pairs`). ``XI``,
    ``XJ``, ``bI``, ``bJ`` and ``iK`` are constants (the dynamics GP's centers, ``beta``
    and ``K^-1``): no gradient flows to them.

    The weights are never formed: with ``Q = exp(exponent)`` the rank-one part is
    ``bI^T Q bJ``, and the gradient only needs ``G = g W * Q`` through its row and column
    sums ``r``, ``c`` (for the mean shifts and ``kI``, ``kJ``) and ``G iiJ^T`` (for
    ``T``). For the rank-one part these are ``bI * (Q bJ)``, ``bJ * (Q^T bI)`` and
    ``bI * Q (bJ * iiJ)^T``: one [n, n] x [n, D + 1] product and one [n, n] x [n]
    product per pair, computed with the value, so no n x n tensor is kept for the
    backward pass and no n x n elementwise product or reduction is needed for the
    E(E-1)/2 off-diagonal pairs. The E diagonal pairs add ``iK_i * Q`` and one more
    [n, n] x [n, D + 1] product.

    Shapes: T [P, D, D] (symmetric), mI/mJ [P, D], kI/kJ [P, n], XI/XJ [P, D, n],
    bI/bJ [P, n], iK [E, n, n] or None -> [P].
    """

    @tf.custom_gradient
    def block(T, mI, mJ, kI, kJ):
        iiI = XI - tf.expand_dims(mI, 2)
        iiJ = XJ - tf.expand_dims(mJ, 2)
        aI, aJ, leftT, rightT = _pair_exponent_factors(T, iiI, iiJ, kI, kJ)
        Q = tf.exp(tf.matmul(leftT, rightT, transpose_a=True))  # [P, n, n]
        # [Q bJ, Q (bJ * iiJ)^T]: [P, n, D + 1]
        QB = tf.matmul(Q, tf.concat([bJ[:, None, :], bJ[:, None, :] * iiJ], axis=1),
                       transpose_b=True)
        Qb = bI * QB[:, :, 0]  # row sums of the rank-one part, [P, n]
        bQ = bJ * tf.linalg.matvec(Q, bI, adjoint_a=True)  # its column sums, [P, n]
        GJ = tf.expand_dims(bI, 2) * QB[:, :, 1:]  # [P, n, D]
        if iK is not None:
            E = iK.shape[0]
            Ones_iiJ = tf.concat([tf.ones_like(bJ[:E, None, :]), iiJ[:E]], axis=1)
            KQ = tf.matmul(iK * Q[:E], Ones_iiJ, transpose_b=True)  # [E, n, D + 1]
            pad = [[0, bI.shape[0] - E], [0, 0]]
            # iK_i * Q is symmetric for a diagonal pair: its row and column sums agree
            d = tf.pad(KQ[:, :, 0], pad)
            Qb -= d
            bQ -= d
            GJ -= tf.pad(KQ[:, :, 1:], pad + [[0, 0]])
        value = tf.reduce_sum(Qb, axis=1)

        def grad(g):
            g1 = tf.expand_dims(g, 1)
            r = g1 * Qb  # [P, n], d/du
            c = g1 * bQ  # [P, n], d/dv
            dT = (tf.matmul(iiI, tf.expand_dims(g1, 2) * GJ)
                  + 0.5 * tf.matmul(iiI * r[:, None, :], iiI, transpose_b=True)
                  + 0.5 * tf.matmul(iiJ * c[:, None, :], iiJ, transpose_b=True))
            dm = -(tf.linalg.matvec(aI, r) + tf.linalg.matvec(aJ, c))
            return dT, dm, dm, r, c

        return value, grad

    return block(T, mI, mJ, kI, kJ)


@tf.custom_gradient
def _inv_logdet(A: tf.Tensor):
    """Inverse and log-determinant of symmetric positive definite matrices.

    Shapes: A [..., D, D] -> (A^-1 [..., D, D], log det A [...]). The backward pass
    reuses the inverse for both outputs (d log det A = A^-1 : dA). (An inverse through
    one Cholesky factorisation measured slower than TensorFlow's batched LU inverse
    for these small matrices on CPU.)
    """
    Ainv = tf.linalg.inv(A)
    logdet = tf.linalg.slogdet(A)[1]

    def grad(g_inv, g_logdet):
        gA = -tf.matmul(Ainv, tf.matmul(g_inv, Ainv), transpose_a=True)
        return gA + g_logdet[..., None, None] * tf.linalg.adjoint(Ainv)

    return (Ainv, logdet), grad


class Predictor(NamedTuple):
    """Everything of a moment-matching prediction that does not depend on the input.

    Built by :func:`prepare` once (e.g. before a horizon loop) and used by :func:`predict`
    at every step. E outputs, n centers, input dimension D, P = E(E+1)/2 output pairs
    (i <= j, see :func:`symmetric_pairs`); ``l_i`` [D] are output i's lengthscales.
    """

    #: [E, D, n] the centers divided by each output's lengthscales, transposed
    scaled_centers: tf.Tensor
    #: [E, D] ``1 / l_i``
    inv_lengthscales: tf.Tensor
    #: [E, D, D] outer product ``(1 / l_i) (1 / l_i)^T``
    inv_lengthscales_outer: tf.Tensor
    #: [E, n] weights of the predictive mean, ``K^-1 y``
    beta: tf.Tensor
    #: [E] signal variances ``sf_i^2``
    signal_variance: tf.Tensor
    #: [P, D, n] the centers over ``l_i^2`` of each pair's first output i
    first_centers: tf.Tensor
    #: [P, D, n] the centers over ``l_j^2`` of each pair's second output j
    second_centers: tf.Tensor
    #: [P, D] ``1 / l_i^2`` of each pair's first output
    first_inv_sq_lengthscales: tf.Tensor
    #: [P, D] ``1 / l_j^2`` of each pair's second output
    second_inv_sq_lengthscales: tf.Tensor
    #: [P, D, D] outer product of ``r = sqrt(1 / l_i^2 + 1 / l_j^2)`` with itself
    pair_scale_outer: tf.Tensor
    #: [P, D, D] outer product of ``1 / r`` with itself
    pair_inv_scale_outer: tf.Tensor
    #: [P, n] ``beta`` of each pair's first output
    first_beta: tf.Tensor
    #: [P, n] ``beta`` of each pair's second output
    second_beta: tf.Tensor
    #: [P, n, n] pair weights (:func:`pair_weights`), or None for a deterministic GP or
    #: a constant one
    pair_weights: Optional[tf.Tensor]
    #: [E, n, n] ``K^-1`` of a constant GP (see :func:`prepare`), else None
    constant_inverse: Optional[tf.Tensor]
    #: Python bool: the GP's centers, ``beta`` and ``K^-1`` are constants (no gradient
    #: flows to them), so the pair block with the hand-made gradient is used
    weights_constant: bool
    #: Python bool: the GP carries no model uncertainty (the RBF policy)
    deterministic: bool


def prepare(factorization: Factorization, constant: bool = False,
            deterministic: Optional[bool] = None) -> Predictor:
    """Input-independent pieces of :func:`predict` for a factorised GP.

    With ``constant`` the factorisation's centers, ``beta`` and ``K^-1`` are treated as
    constants (no gradient flows to them; the dynamics GP during policy optimisation) and
    the output covariance uses the fused block of :func:`_pair_second_moments`;
    otherwise the pair weights are formed from ``beta`` and ``iK`` with gradients
    flowing through them.
    """
    centers, beta, iK, ell, sf2 = factorization
    E = beta.shape[0]
    I, J, _ = symmetric_pairs(E)
    if deterministic is None:
        deterministic = iK is None
    iL = 1.0 / ell
    iL2 = tf.square(iL)
    XT = tf.transpose(centers)[None, :, :]  # [1, D, n]
    iL2I = tf.gather(iL2, I)
    iL2J = tf.gather(iL2, J)
    sqP = tf.sqrt(iL2I + iL2J)
    constant = bool(constant)
    W = None
    if not constant and not deterministic:
        W = pair_weights(beta, iK)
    return Predictor(
        scaled_centers=XT * iL[:, :, None], inv_lengthscales=iL,
        inv_lengthscales_outer=iL[:, :, None] * iL[:, None, :], beta=beta,
        signal_variance=sf2, first_centers=XT * iL2I[:, :, None],
        second_centers=XT * iL2J[:, :, None], first_inv_sq_lengthscales=iL2I,
        second_inv_sq_lengthscales=iL2J, pair_scale_outer=sqP[:, :, None] * sqP[:, None, :],
        pair_inv_scale_outer=1.0 / (sqP[:, :, None] * sqP[:, None, :]),
        first_beta=tf.gather(beta, I), second_beta=tf.gather(beta, J),
        pair_weights=W, constant_inverse=None if deterministic else iK,
        weights_constant=constant, deterministic=bool(deterministic),
    )


def _one_hot(index: np.ndarray, size: int, dtype) -> tf.Tensor:
    """Constant [len(index), size] matrix whose row k picks entry ``index[k]``."""
    return tf.constant(np.eye(size)[np.asarray(index)], dtype=dtype)


def eye_like(s: tf.Tensor) -> tf.Tensor:
    """Identity of the size of the square matrix ``s``: a constant when the size is static."""
    n = s.shape[-1]
    if n is not None:
        return tf.constant(np.eye(n), dtype=s.dtype)
    return tf.eye(tf.shape(s)[-1], dtype=s.dtype)


def predict(m: tf.Tensor, s: tf.Tensor, pred: Predictor, deterministic_jitter: float = 1e-6):
    """Moments of the E GP outputs at x ~ N(m, s), given :func:`prepare`'s pieces.

    Shapes: m [1, D], s [D, D] -> M [1, E], S [E, E], V [D, E] (``V = inv(s) Cov[x, f]``).
    """
    E = pred.beta.shape[0]
    first, second, pair_of = symmetric_pairs(E)
    eye = eye_like(s)

    # Mean and inv(s) Cov[x, f(x)]: B = L^-1 s L^-1 + I per output.
    diff = pred.scaled_centers - tf.expand_dims(m * pred.inv_lengthscales, 2)  # (c - m) / l
    B_inv, logdet_B = _inv_logdet(s * pred.inv_lengthscales_outer + eye)
    B_inv_diff = tf.matmul(B_inv, diff)  # [E, D, n]
    weighted = tf.exp(-0.5 * tf.reduce_sum(diff * B_inv_diff, axis=1)) * pred.beta  # [E, n]
    scale = pred.signal_variance * tf.exp(-0.5 * logdet_B)  # [E]
    M = scale * tf.reduce_sum(weighted, axis=-1)
    V = (tf.expand_dims(scale, 1) * pred.inv_lengthscales) * tf.linalg.matvec(B_inv_diff, weighted)

    # Second moments of each output pair (i <= j).
    log_k = (tf.expand_dims(tf.math.log(pred.signal_variance), 1)
             - 0.5 * tf.reduce_sum(tf.square(diff), axis=1))  # [E, n]
    # With A = P^1/2 s P^1/2 + I (P = 1/l_i^2 + 1/l_j^2): R = s P + I has det R = det A
    # and R^-1 s = P^-1/2 (I - A^-1) P^-1/2 =: T, symmetric.
    A_inv, logdet_A = _inv_logdet(s * pred.pair_scale_outer + eye)
    T = (eye - A_inv) * pred.pair_inv_scale_outer
    det_factor = tf.exp(-0.5 * logdet_A)  # [P]
    # constant one-hot products instead of gathers: exact, and a one-product gradient
    log_k_first = tf.matmul(_one_hot(first, E, m.dtype), log_k)  # [P, n]
    log_k_second = tf.matmul(_one_hot(second, E, m.dtype), log_k)
    m_first = m * pred.first_inv_sq_lengthscales  # m / l_i^2, [P, D]
    m_second = m * pred.second_inv_sq_lengthscales  # m / l_j^2, [P, D]
    if pred.weights_constant:
        # centers and weights constant: the fused block with its cheaper gradient, in
        # groups of pairs that can run side by side (the first one has the diagonal pairs)
        parts = [m_first, m_second, log_k_first, log_k_second, pred.first_centers,
                 pred.second_centers, pred.first_beta, pred.second_beta]
        raw = tf.concat([
            _pair_second_moments(T[a:b], *(x[a:b] for x in parts),
                                 pred.constant_inverse if a == 0 else None)
            for a, b in pair_groups(len(first), E)], axis=0)
    else:
        iiI = pred.first_centers - tf.expand_dims(m_first, 2)  # (centers - m) / l_i^2
        iiJ = pred.second_centers - tf.expand_dims(m_second, 2)
        _, _, leftT, rightT = _pair_exponent_factors(T, iiI, iiJ, log_k_first, log_k_second)
        Q = tf.exp(tf.matmul(leftT, rightT, transpose_a=True))  # [P, n, n]
        if pred.deterministic:
            raw = tf.reduce_sum(pred.first_beta * tf.linalg.matvec(Q, pred.second_beta), axis=-1)
        else:
            raw = tf.reduce_sum(Q * pred.pair_weights, axis=[1, 2])
    pair_entries = _one_hot(pair_of.reshape(-1), len(first), m.dtype)  # [E * E, P]
    S = tf.reshape(tf.linalg.matvec(pair_entries, det_factor * raw), [E, E])
    if pred.deterministic:
        S += tf.constant(deterministic_jitter * np.eye(E), dtype=S.dtype)
    else:
        S += tf.linalg.diag(pred.signal_variance)
    M = tf.expand_dims(M, 0)  # [1, E]
    S -= tf.matmul(M, M, transpose_a=True)
    return M, S, tf.transpose(V)


def moment_match(
    m: tf.Tensor,
    s: tf.Tensor,
    fact: Factorization,
    constant: bool = False,
    deterministic: Optional[bool] = None,
    deterministic_jitter: float = 1e-6,
):
    """Mean, covariance and input-output covariance of E GPs at x ~ N(m, s).

    Shapes: m [1, D], s [D, D], ``fact`` from :func:`factorize` (or :func:`fitc_factorize`)
    -> M [1, E], S [E, E], V [D, E] with ``V = inv(s) Cov[x, f(x)]``. With ``constant``
    no gradient flows to the factorisation (see :func:`prepare`).

    For a deterministic GP (``deterministic``, by default ``fact.iK is None``) the
    covariance holds no model uncertainty and ``deterministic_jitter`` is added to its
    diagonal; otherwise the latent variance ``sf^2 - tr(K^-1 Q)`` is included
    (observation noise is not).
    """
    return predict(m, s, prepare(fact, constant, deterministic), deterministic_jitter)
