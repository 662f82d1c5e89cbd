"""A straightforward GPflow-style port of PILCO's policy objective: the speed baseline.

This is how PILCO is usually transcribed to TensorFlow, kept here only so that
``bench_policy.py --baseline`` can time it on the same machine as the library:

- every step of the horizon refactorises the dynamics GP (kernel matrix, Cholesky,
  ``beta``, ``K^-1``) and the policy's deterministic GP;
- the E x E output covariance is computed on all E^2 pairs with tiled [E, E, n, n]
  tensors, each pair's exponent as a broadcast sum of three terms;
- the horizon is a ``tf.while_loop`` inside one ``tf.function``, differentiated by
  TensorFlow's automatic differentiation throughout.

It computes the same quantity as :meth:`pilco.models.rollout.Rollout.policy_loss` (angle-free
problems, sine-squashed RBF policy, exponential reward), which the benchmark checks
before timing it.
"""
from __future__ import annotations

import numpy as np
import tensorflow as tf


def _gp_moments(m, s, X, Y, ell, sf2, sn2, deterministic):
    """Moments of E GPs at x ~ N(m, s), everything recomputed from the data.

    Shapes: m [1, D], s [D, D], X [n, D], Y [n, E], ell [E, D], sf2 [E], sn2 [E]
    -> M [1, E], S [E, E], V [D, E].
    """
    n, D = tf.shape(X)[0], X.shape[1]
    E = ell.shape[0]
    # factorisation, per call
    Xs = X[None] / ell[:, None, :]
    d2 = (tf.reduce_sum(Xs ** 2, -1)[:, :, None] + tf.reduce_sum(Xs ** 2, -1)[:, None, :]
          - 2.0 * tf.matmul(Xs, Xs, transpose_b=True))
    K = sf2[:, None, None] * tf.exp(-0.5 * d2) + sn2[:, None, None] * tf.eye(n, dtype=X.dtype)
    L = tf.linalg.cholesky(K)
    iK = tf.linalg.cholesky_solve(L, tf.eye(n, batch_shape=[E], dtype=X.dtype))
    beta = tf.linalg.cholesky_solve(L, tf.transpose(Y)[:, :, None])[:, :, 0]  # [E, n]

    # mean and input-output covariance
    inp = tf.tile((X - m)[None], [E, 1, 1])  # [E, n, D]
    iL = tf.linalg.diag(1.0 / ell)  # [E, D, D]
    iN = tf.matmul(inp, iL)
    B = tf.matmul(iL, tf.matmul(tf.tile(s[None], [E, 1, 1]), iL)) + tf.eye(D, dtype=X.dtype)
    t = tf.linalg.matrix_transpose(tf.linalg.solve(B, tf.linalg.matrix_transpose(iN)))
    lb = tf.exp(-0.5 * tf.reduce_sum(iN * t, -1)) * beta  # [E, n]
    tiL = tf.matmul(t, iL)
    c = sf2 / tf.sqrt(tf.linalg.det(B))
    M = (tf.reduce_sum(lb, -1) * c)[None, :]
    V = tf.transpose(tf.einsum("end,en->ed", tiL, lb) * c[:, None])  # [D, E]

    # covariance on all E x E pairs, tiled
    iL2 = 1.0 / tf.square(ell)  # [E, D]
    P = iL2[:, None, :] + iL2[None, :, :]  # [E, E, D]
    R = (tf.matmul(tf.tile(s[None, None], [E, E, 1, 1]), tf.linalg.diag(P))
         + tf.eye(D, dtype=X.dtype))
    detR = tf.linalg.det(R)
    ii = inp * iL2[:, None, :]  # (x - m) / l^2, [E, n, D]
    Rs = 0.5 * tf.linalg.solve(R, tf.tile(s[None, None], [E, E, 1, 1]))  # R^-1 s / 2
    a = tf.tile(ii[:, None], [1, E, 1, 1])  # [E, E, n, D]
    b = tf.tile(ii[None, :], [E, 1, 1, 1])
    aQ, bQ = tf.matmul(a, Rs), tf.matmul(b, Rs)
    maha = (tf.reduce_sum(aQ * a, -1)[..., :, None] + tf.reduce_sum(bQ * b, -1)[..., None, :]
            + 2.0 * tf.matmul(aQ, b, transpose_b=True))  # (a_i + b_j)^T R^-1 s (a_i + b_j) / 2
    k = tf.math.log(sf2)[:, None] - 0.5 * tf.reduce_sum(iN ** 2, -1)  # [E, n]
    Q = tf.exp(k[:, None, :, None] + k[None, :, None, :] + maha)
    S = tf.einsum("an,abnm,bm->ab", beta, Q, beta)
    if not deterministic:
        Qdiag = tf.gather_nd(Q, tf.stack([tf.range(E), tf.range(E)], axis=1))  # [E, n, n]
        S -= tf.linalg.diag(tf.reduce_sum(iK * Qdiag, [1, 2]))
    S = S / tf.sqrt(detR) - tf.transpose(M) @ M
    S += tf.linalg.diag(1e-6 * tf.ones_like(sf2) if deterministic else sf2)
    return M, S, V


def _sin_squash(m, s, e):
    """Moments of e * sin(u) for u ~ N(m, s): M [1, U], S [U, U], C [U, U]."""
    mi, vii = m[0], tf.linalg.diag_part(s)
    M = e * tf.exp(-0.5 * vii) * tf.sin(mi)
    lq = -0.5 * (vii[:, None] + vii[None, :])
    q = tf.exp(lq)
    S = ((tf.exp(lq + s) - q) * tf.cos(mi[:, None] - mi[None, :])
         - (tf.exp(lq - s) - q) * tf.cos(mi[:, None] + mi[None, :]))
    S = 0.5 * e[:, None] * e[None, :] * S
    C = tf.linalg.diag(e * tf.exp(-0.5 * vii) * tf.cos(mi))
    return M[None, :], S, C


def _problem(agent):
    """The agent's problem as constants and closures: (H, step(m, s) -> (m, s, reward))."""
    if agent.angle_indices:
        raise ValueError("the naive baseline handles problems without angles only")
    from pilco.rewards import ExponentialReward

    if not isinstance(agent.reward, ExponentialReward):
        raise TypeError("the naive baseline handles an ExponentialReward only")
    ctrl = agent.controller
    D = agent.state_dim
    e = tf.constant(np.broadcast_to(np.asarray(ctrl.max_action, float), (ctrl.control_dim,)))
    Wr = tf.constant(np.asarray(agent.reward.W.numpy()))
    tr = tf.constant(np.asarray(agent.reward.t.numpy()).reshape(1, D))

    def reward(m, s):
        SW = s @ Wr
        iSpW = Wr @ tf.linalg.inv(tf.eye(D, dtype=m.dtype) + SW)
        return tf.exp(-0.5 * (m - tr) @ iSpW @ tf.transpose(m - tr)) / tf.sqrt(
            tf.linalg.det(tf.eye(D, dtype=m.dtype) + SW))

    def step(m, s):
        X, Y = agent.mgpr.X, agent.mgpr.Y
        ell, sf2, sn2 = agent.mgpr.hyperparameters()
        cell, csf2, csn2 = ctrl.hyperparameters()
        centers = tf.convert_to_tensor(ctrl.centers)
        targets = tf.convert_to_tensor(ctrl.targets)
        Mu, Su, Cu = _gp_moments(m, s, centers, targets, cell, csf2, csn2, True)
        Mu, Su, Cs = _sin_squash(Mu, Su, e)
        Cu = Cu @ Cs
        q = s @ Cu
        m_in = tf.concat([m, Mu], 1)
        s_in = tf.concat([tf.concat([s, q], 1), tf.concat([tf.transpose(q), Su], 1)], 0)
        Md, Sd, Vd = _gp_moments(m_in, s_in, X, Y, ell, sf2, sn2, False)
        cxd = tf.concat([s, q], 1) @ Vd
        m = m + Md
        s = s + Sd + cxd + tf.transpose(cxd)
        s = 0.5 * (s + tf.transpose(s))
        return m, s, reward(m, s)

    return agent.horizon, step


def make_objective(agent):
    """``f() -> loss`` (compiled) computing ``-sum of expected rewards`` the naive way,
    reading the agent's data, hyperparameters, policy and reward."""
    H, step = _problem(agent)
    m_init, S_init = agent.m_init, agent.S_init

    @tf.function
    def loss():
        m0 = tf.constant(m_init)  # the agent's start
        s0 = tf.constant(S_init)

        def body(t, m, s, total):
            m, s, r = step(m, s)
            return t + 1, m, s, total + r

        _, _, _, total = tf.while_loop(
            lambda t, *_: t < H, body, (tf.constant(0), m0, s0, tf.zeros([1, 1], tf.float64)))
        return -total[0, 0]

    return loss
