"""The input-dependent half of a moment-matching prediction: moments at ``x ~ N(m, s)``.

:func:`prepare` turns a :class:`~pilco.moments.factorization.Factorization` into a
:class:`Predictor` (everything that does not depend on the input, built once, e.g.
before a horizon loop); :func:`predict` returns the mean ``M``, covariance ``S`` of
``f(x)`` and ``V = inv(s) Cov[x, f(x)]`` for one Gaussian input; :func:`moment_match`
does both in one call.
"""
from __future__ import annotations

from typing import NamedTuple, Optional

import numpy as np
import tensorflow as tf

from .compiled import log_determinant
from .factorization import Factorization
from .pairs import (_pair_exponent_factors, _pair_second_moments, pair_groups, pair_weights,
                    symmetric_pairs)

__all__ = ["Predictor", "prepare", "predict", "moment_match", "eye_like"]


@tf.custom_gradient
def _inv_logdet(A: tf.Tensor):
    """Inverse and log-determinant of symmetric positive definite matrices.

    Shapes: A [..., D, D] -> (A^-1 [..., D, D], log det A [...]). The backward pass
    reuses the inverse for both outputs (d log det A = A^-1 : dA). (An inverse through
    one Cholesky factorisation measured slower than TensorFlow's batched LU inverse
    for these small matrices on CPU.) Traced inside
    :func:`~pilco.moments.compiled.xla_compatible`, the log-determinant comes from a
    Cholesky factor instead (XLA has no ``slogdet`` on CPU).
    """
    Ainv = tf.linalg.inv(A)
    logdet = log_determinant(A, spd=True)

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


def point_means(x: tf.Tensor, pred: Predictor) -> tf.Tensor:
    """Predictive means of the E GP outputs at P known inputs (no input uncertainty).

    Shapes: x [P, D] -> [P, E]. ``sum_k beta_ik sf_i^2 exp(-|(x - c_k) / l_i|^2 / 2)``:
    what :func:`predict` returns as ``M`` for a zero input covariance, for many inputs at
    once at the cost of one kernel row per input and output.
    """
    scaled = x[:, None, :] * pred.inv_lengthscales[None, :, :]  # [P, E, D]
    diff = pred.scaled_centers[None, :, :, :] - scaled[:, :, :, None]  # [P, E, D, n]
    k = tf.exp(-0.5 * tf.reduce_sum(tf.square(diff), axis=2))  # [P, E, n]
    return pred.signal_variance[None, :] * tf.reduce_sum(k * pred.beta[None, :, :], axis=-1)


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
