"""The symmetric output pairs of an E x E moment-matched covariance.

The E x E output covariance is symmetric: only its E(E+1)/2 upper-triangular pairs
(:func:`symmetric_pairs`, the E diagonal pairs first) are evaluated, batched in one
tensor. :func:`pair_weights` forms each pair's n x n weight matrix;
:func:`_pair_exponent_factors` folds the two quadratic terms of a pair's exponent into
one matrix product, so each pair costs one n x n ``exp`` and one contraction; and
:func:`_pair_second_moments` is the fused block, with a hand-made gradient, used when
the GP's weights are constants (the dynamics GP during policy optimisation). That block
can be split into :func:`pair_groups`, independent parts of the graph that TensorFlow's
inter-op threads run side by side (``PILCO_PAIR_GROUPS``; one block by default, whose
rounding does not depend on the CPUs).
"""
from __future__ import annotations

import os
from typing import List, Optional, Tuple

import numpy as np
import tensorflow as tf

__all__ = ["MAX_PAIR_GROUPS", "GROUPS_VARIABLE", "configured_groups", "pair_groups",
           "symmetric_pairs", "pair_weights"]

#: at most this many groups of output pairs (:func:`pair_groups`)
MAX_PAIR_GROUPS = 4
#: the environment variable that asks for groups of output pairs (:func:`pair_groups`)
GROUPS_VARIABLE = "PILCO_PAIR_GROUPS"


def configured_groups() -> int:
    """The groups of output pairs asked for by ``PILCO_PAIR_GROUPS``: unset, one (the
    unsplit block); a whole number N >= 1, N; ``threads``, one per inter-op thread.

    One is the default because the arithmetic depends on the grouping: batched
    operations over fewer pairs vectorise and sum in another order, so the same run with
    two groups (a run alone on two CPUs, when the groups followed the threads) and with
    one (a sweep's run on one CPU) parted in the last bits and then in its path. With
    one group a seed gives the same run alone, in a sweep and in a diagnosis on any
    number of CPUs; more groups are faster alone on several CPUs (docs/performance.md)
    but round as their number says."""
    text = os.environ.get(GROUPS_VARIABLE, "").strip()
    if not text:
        return 1
    if text == "threads":
        return min(_parallel_threads(), MAX_PAIR_GROUPS)
    try:
        groups = int(text)
    except ValueError:
        groups = 0
    if groups < 1:
        raise ValueError(f"{GROUPS_VARIABLE}={text!r}: expected a whole number >= 1 or "
                         f"'threads'")
    return groups


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
    ``groups`` defaults to :func:`configured_groups` (one, the unsplit block, unless
    ``PILCO_PAIR_GROUPS`` asks for more).
    """
    if groups is None:
        groups = configured_groups()
    groups = max(1, min(int(groups), P - E + 1))
    bounds = [int(round(b)) for b in np.linspace(0, P, groups + 1)]
    bounds[1] = max(bounds[1], E)
    return [(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


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
    # add_n, not +: kI and kJ may be matrix products (the policy's), and a product
    # followed by an addition is a pattern TensorFlow's oneDNN graph rewrite inspects and
    # refuses for float64 with a warning line each time (the same sum either way)
    u = tf.math.add_n([kI, 0.5 * tf.reduce_sum(aI * iiI, axis=1)])
    v = tf.math.add_n([kJ, 0.5 * tf.reduce_sum(aJ * iiJ, axis=1)])
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
            # the halves inside the products (exact: a power of two) and a sum of
            # three products, which TensorFlow's oneDNN rewrite leaves alone (a product
            # scaled and added draws a float64 warning line from it)
            dT = (tf.matmul(iiI, tf.expand_dims(g1, 2) * GJ)
                  + tf.matmul(iiI * (0.5 * r)[:, None, :], iiI, transpose_b=True)
                  + tf.matmul(iiJ * (0.5 * c)[:, None, :], iiJ, transpose_b=True))
            dm = -(tf.linalg.matvec(aI, r) + tf.linalg.matvec(aJ, c))
            return dT, dm, dm, r, c

        return value, grad

    return block(T, mI, mJ, kI, kJ)
