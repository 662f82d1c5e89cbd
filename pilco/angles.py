"""Angles under a Gaussian: moments of (sin, cos) of selected state dimensions.

PILCO represents an angle θ by the pair (sin θ, cos θ) so that the GP and the policy see
a continuous, periodic input. With x ~ N(m, s) these moments are exact.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import tensorflow as tf
from gpflow.config import default_float

from .features import non_angle_indices

__all__ = ["trig_moments", "augment_state", "point_features"]


def _as_float(x) -> tf.Tensor:
    return tf.convert_to_tensor(x, dtype=default_float())


def _interleave(count: int, dtype) -> tf.Tensor:
    """The constant permutation [2I, 2I] that takes columns in blocks
    ``[sin θ1..θI, cos θ1..θI]`` to ``[sin θ1, cos θ1, sin θ2, ...]`` (I = ``count``)."""
    order = np.stack([np.arange(count), count + np.arange(count)], axis=1).reshape(-1)
    return tf.constant(np.eye(2 * count)[:, order], dtype=dtype)


def trig_moments(m, s, indices: Sequence[int], scale=None):
    """Moments of ``scale * [sin x_i, cos x_i]`` for the angle dimensions ``indices``.

    Shapes: m [1, D], s [D, D], ``indices`` I integers, ``scale`` [I] or scalar or None
    -> M [1, 2I], S [2I, 2I], C [D, 2I], outputs interleaved ``[sin θ1, cos θ1, sin θ2, ...]``
    and ``C = inv(s) Cov[x, (sin, cos)]`` (rows outside ``indices`` are 0).
    """
    m = _as_float(m)
    s = _as_float(s)
    idx = np.asarray(indices, dtype=np.int64).reshape(-1)
    I = len(idx)
    D = m.shape[-1]
    # Constant one-hot selections and permutations instead of gathers and scatters: a
    # matrix product with a constant has a one-product gradient, and the loop body of a
    # rollout stays short (this runs twice per step of an angle task).
    pick = tf.constant(np.eye(D)[:, idx], dtype=m.dtype)  # [D, I]
    mi = tf.matmul(m, pick)  # [1, I]
    vi = tf.matmul(pick, tf.matmul(s, pick), transpose_a=True)  # [I, I]
    vii = tf.linalg.diag_part(vi)[None, :]  # [1, I]
    damp = tf.exp(-0.5 * vii)
    if scale is not None:
        e = tf.reshape(tf.broadcast_to(tf.reshape(_as_float(scale), [-1]), [I]), [1, I])
        damp = e * damp
    msin = damp * tf.sin(mi)  # [1, I]
    mcos = damp * tf.cos(mi)

    lq = -0.5 * (tf.transpose(vii) + vii)
    q = tf.exp(lq)
    dif = tf.transpose(mi) - mi
    add = tf.transpose(mi) + mi
    plus = tf.exp(lq + vi) - q
    minus = tf.exp(lq - vi) - q
    cos_dif, cos_add = tf.cos(dif), tf.cos(add)
    ss = plus * cos_dif - minus * cos_add  # Cov(sin_i, sin_j) * 2
    cc = plus * cos_dif + minus * cos_add  # Cov(cos_i, cos_j) * 2
    sc = plus * tf.sin(dif) + minus * tf.sin(add)  # Cov(sin_i, cos_j) * 2
    # blocks [sin θ1..θI, cos θ1..θI] first, then interleaved by a constant permutation
    S = 0.5 * tf.concat([tf.concat([ss, sc], 1), tf.concat([tf.transpose(sc), cc], 1)], 0)
    if scale is not None:
        e2 = tf.concat([e, e], 1)
        S = S * tf.transpose(e2) * e2
    M = tf.concat([msin, mcos], 1)
    # C = inv(s) Cov[x, (sin, cos)]: column k of sin is e_k cos, of cos is -e_k sin
    C = tf.concat([pick * mcos, pick * -msin], 1)  # [D, 2I]
    if I > 1:
        perm = _interleave(I, m.dtype)  # block -> interleaved
        M = tf.matmul(M, perm)
        S = tf.matmul(perm, tf.matmul(S, perm), transpose_a=True)
        C = tf.matmul(C, perm)
    return M, S, C


def augment_state(m, s, angle_indices: Sequence[int]):
    """Distribution of the features ``[x_other, sin θ1, cos θ1, ...]`` for x ~ N(m, s).

    The non-angle dimensions are kept in order and each angle is replaced by its
    (sin, cos) pair appended after them (the layout of :mod:`pilco.features`, whose
    :func:`~pilco.features.angle_features` is the mean of these features at a known
    state). Shapes: m [1, D], s [D, D] ->
    Mf [1, F], Sf [F, F], Cf [D, F] with F = D + len(angle_indices) and
    ``Cf = inv(s) Cov[x, features]``.
    """
    m = _as_float(m)
    s = _as_float(s)
    D = m.shape[-1]
    ang = list(angle_indices)
    if not ang:
        return m, s, tf.eye(D, dtype=m.dtype)
    keep = non_angle_indices(D, ang)
    Mt, St, Ct = trig_moments(m, s, ang)
    sel = tf.constant(np.eye(D)[:, keep], dtype=m.dtype)  # [D, K]
    Cf = tf.concat([sel, Ct], axis=1)  # [D, F]
    Mf = tf.concat([tf.matmul(m, sel), Mt], axis=1)
    s_rows = tf.matmul(sel, s, transpose_a=True)  # Cov[x_keep, x], [K, D]
    s_keep = tf.matmul(s_rows, sel)
    cross = tf.matmul(s_rows, Ct)  # Cov[x_keep, trig], [K, 2I]
    Sf = tf.concat(
        [tf.concat([s_keep, cross], axis=1), tf.concat([tf.transpose(cross), St], axis=1)],
        axis=0,
    )
    return Mf, Sf, Cf


def point_features(x, angle_indices: Sequence[int]):
    """The features ``[x_other, sin θ1, cos θ1, ...]`` of P known states, as tensors (what
    :func:`augment_state` returns as the mean for a zero covariance, and
    :func:`pilco.features.angle_features` with NumPy). Shapes: x [P, D] -> [P, F]."""
    x = _as_float(x)
    D = x.shape[-1]
    ang = list(angle_indices)
    if not ang:
        return x
    keep = tf.constant(np.eye(D)[:, non_angle_indices(D, ang)], dtype=x.dtype)  # [D, K]
    pick = tf.constant(np.eye(D)[:, ang], dtype=x.dtype)  # [D, I]
    theta = tf.matmul(x, pick)  # [P, I]
    trig = tf.concat([tf.sin(theta), tf.cos(theta)], axis=1)  # blocks [sin..., cos...]
    I = len(ang)
    if I > 1:
        trig = tf.matmul(trig, _interleave(I, x.dtype))
    return tf.concat([tf.matmul(x, keep), trig], axis=1)
