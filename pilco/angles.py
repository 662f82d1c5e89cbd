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

__all__ = ["trig_moments", "augment_state"]


def _as_float(x) -> tf.Tensor:
    return tf.convert_to_tensor(x, dtype=default_float())


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
    if scale is None:
        e = tf.ones([I], dtype=m.dtype)
    else:
        e = tf.broadcast_to(tf.reshape(_as_float(scale), [-1]), [I])

    mi = tf.gather(m[0], idx)  # [I]
    vi = tf.gather(tf.gather(s, idx, axis=0), idx, axis=1)  # [I, I]
    vii = tf.linalg.diag_part(vi)
    damp = e * tf.exp(-0.5 * vii)
    msin = damp * tf.sin(mi)
    mcos = damp * tf.cos(mi)

    lq = -0.5 * (vii[:, None] + vii[None, :])
    q = tf.exp(lq)
    dif = mi[:, None] - mi[None, :]
    add = mi[:, None] + mi[None, :]
    plus = tf.exp(lq + vi) - q
    minus = tf.exp(lq - vi) - q
    ss = plus * tf.cos(dif) - minus * tf.cos(add)  # Cov(sin, sin) * 2
    cc = plus * tf.cos(dif) + minus * tf.cos(add)
    sc = plus * tf.sin(dif) + minus * tf.sin(add)  # Cov(sin_i, cos_j) * 2
    # interleave [sin, cos] per angle
    top = tf.reshape(tf.stack([ss, sc], axis=-1), [I, 2 * I])
    bottom = tf.reshape(tf.stack([tf.transpose(sc), cc], axis=-1), [I, 2 * I])
    S = tf.reshape(tf.stack([top, bottom], axis=1), [2 * I, 2 * I])
    E2 = tf.reshape(tf.stack([e, e], axis=-1), [2 * I])
    S = 0.5 * S * E2[:, None] * E2[None, :]
    M = tf.reshape(tf.stack([msin, mcos], axis=-1), [1, 2 * I])
    # C: rows idx; column 2k is d/dm sin = cos part, 2k+1 is -sin part
    Cblock = tf.reshape(tf.stack([tf.linalg.diag(mcos), tf.linalg.diag(-msin)], axis=-1),
                        [I, 2 * I])
    C = tf.scatter_nd(idx[:, None], Cblock, [D, 2 * I])
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
    Mf = tf.concat([tf.gather(m, keep, axis=1), Mt], axis=1)
    s_keep = tf.gather(tf.gather(s, keep, axis=0), keep, axis=1)
    cross = tf.matmul(tf.gather(s, keep, axis=0), Ct)  # Cov[x_keep, trig], [K, 2I]
    Sf = tf.concat(
        [tf.concat([s_keep, cross], axis=1), tf.concat([tf.transpose(cross), St], axis=1)],
        axis=0,
    )
    return Mf, Sf, Cf
