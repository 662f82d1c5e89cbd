"""The compiled, moment-matched rollout of a policy through the GP dynamics model.

One step (MATLAB PILCO's ``propagate``) maps the state distribution ``x_t ~ N(m, s)`` to
``x_{t+1}``:

1. angles are replaced by (sin, cos) features, giving the GP/policy input ``z``;
2. the policy returns ``u ~ N(Mu, Su)`` for the state distribution (optionally it sees a
   noisy measurement ``s + diag(noise) / 2``, ``noise`` being the dynamics GPs'
   likelihood variances, as some MATLAB PILCO versions do);
3. the dynamics GPs predict the state difference ``Δ`` at ``[z, u]``;
4. ``x_{t+1} = x_t + Δ`` with every cross-covariance kept.

The whole horizon is one ``tf.while_loop`` inside a compiled function, traced once; the
dynamics GP's factorisation (Cholesky, ``beta`` and ``K^-1``) does not depend on the
policy: :meth:`Rollout.refresh` computes it once per policy optimisation and stores it
in non-trainable variables that the compiled functions read.
"""
from __future__ import annotations

from typing import Sequence

import gpflow
import tensorflow as tf
from gpflow.config import default_float

from .. import moments
from ..angles import augment_state
from ..protocols import Controller, Reward

__all__ = ["Rollout"]


class Rollout(gpflow.base.Module):
    """Moment-matched multi-step prediction of a controller, dynamics model and reward.

    Args:
        controller: a :class:`pilco.protocols.Controller` reading the angle-augmented state.
        reward: a :class:`pilco.protocols.Reward` on the raw state.
        state_dim: D; ``control_dim``: U; ``angle_indices``: the angle dimensions.
        policy_input_noise: the policy sees ``s + diag(noise) / 2`` instead of ``s``.
        horizon, m_init [1, D], S_init [D, D]: the policy objective's horizon and start
            distribution, kept in the variables of the same names (checked by the caller).
    """

    def __init__(self, controller: Controller, reward: Reward, state_dim: int,
                 control_dim: int, angle_indices: Sequence[int], policy_input_noise: bool,
                 horizon: int, m_init, S_init):
        super().__init__()
        self.horizon = tf.Variable(horizon, trainable=False, dtype=tf.int32, name="horizon")
        self.m_init = tf.Variable(m_init, trainable=False, name="m_init")
        self.S_init = tf.Variable(S_init, trainable=False, name="S_init")
        self._controller = controller
        self._reward = reward
        self.state_dim = D = state_dim
        self.angle_indices = tuple(angle_indices)
        self.policy_input_noise = policy_input_noise
        inputs = D + len(self.angle_indices) + control_dim  # GP input size
        f = default_float()
        # The dynamics model as of the last refresh(): its centers [n, inputs], beta [D, n],
        # K^-1 [D, n, n], lengthscales [D, inputs], signal and noise variances [D].
        self._centers = tf.Variable(tf.zeros([0, inputs], f), shape=[None, inputs],
                                    trainable=False)
        self._beta = tf.Variable(tf.zeros([D, 0], f), shape=[D, None], trainable=False)
        self._inverse = tf.Variable(tf.zeros([D, 0, 0], f), shape=[D, None, None],
                                    trainable=False)
        self._lengthscales = tf.Variable(tf.ones([D, inputs], f), trainable=False)
        self._signal_variance = tf.Variable(tf.ones([D], f), trainable=False)
        self._noise_variance = tf.Variable(tf.ones([D], f), trainable=False)
        self.retrace()

    def retrace(self) -> None:
        """(Re)create the compiled functions. A trace captures the controller and the
        reward it was traced with, so replacing either must drop the old traces."""
        self.total_reward = tf.function(self._total_reward, autograph=False)
        self.trajectory = tf.function(self._trajectory, autograph=False)
        self.action = tf.function(self._action, autograph=False)

    @property
    def controller(self) -> Controller:
        """The policy; setting it drops the compiled traces of the previous one."""
        return self._controller

    @controller.setter
    def controller(self, value: Controller) -> None:
        self._controller = value
        self.retrace()

    @property
    def reward(self) -> Reward:
        """The reward; setting it drops the compiled traces of the previous one."""
        return self._reward

    @reward.setter
    def reward(self, value: Reward) -> None:
        self._reward = value
        self.retrace()

    def refresh(self, dynamics_model) -> None:
        """Factorise ``dynamics_model`` (an :class:`MGPR`) for the compiled functions."""
        factorization = dynamics_model.factorize()
        self._centers.assign(factorization.centers)
        self._beta.assign(factorization.beta)
        self._inverse.assign(factorization.iK)
        self._lengthscales.assign(factorization.lengthscales)
        self._signal_variance.assign(factorization.variance)
        self._noise_variance.assign(dynamics_model.noise_variance)

    def dynamics(self) -> moments.Predictor:
        """The dynamics model of the last :meth:`refresh`, as loop-invariant pieces."""
        factorization = moments.Factorization(
            tf.convert_to_tensor(self._centers), tf.convert_to_tensor(self._beta),
            tf.convert_to_tensor(self._inverse),
            tf.convert_to_tensor(self._lengthscales),
            tf.convert_to_tensor(self._signal_variance),
        )
        return moments.prepare(factorization, constant=True, deterministic=False)

    def step(self, m, s, dynamics: moments.Predictor, prepared):
        """One moment-matched step: m [1, D], s [D, D] -> m' [1, D], s' [D, D].

        ``dynamics`` is :meth:`dynamics`'s result, ``prepared`` the controller's
        ``prepare()`` result.
        """
        ang = self.angle_indices
        Mf, Sf, Cf = augment_state(m, s, ang)
        if self.policy_input_noise:
            noisy = s + tf.linalg.diag(0.5 * tf.convert_to_tensor(self._noise_variance))
            Mp, Sp, _ = augment_state(m, noisy, ang)
        else:
            Mp, Sp = Mf, Sf
        Mu, Su, Cu = self.controller.moments(Mp, Sp, True, prepared)
        cov_fu = tf.matmul(Sf, Cu)  # Cov[z, u], [F, U]
        m_in = tf.concat([Mf, Mu], axis=1)
        s_in = tf.concat(
            [tf.concat([Sf, cov_fu], 1), tf.concat([tf.transpose(cov_fu), Su], 1)], 0
        )
        Md, Sd, Vd = moments.predict(m_in, s_in, dynamics)
        sCf = tf.matmul(s, Cf)  # Cov[x, z], [D, F]
        cov_x_in = tf.concat([sCf, tf.matmul(sCf, Cu)], axis=1)  # Cov[x, (z, u)]
        cov_xd = tf.matmul(cov_x_in, Vd)  # Cov[x, Δ], [D, D]
        m_next = m + Md
        s_next = s + Sd + cov_xd + tf.transpose(cov_xd)
        return m_next, 0.5 * (s_next + tf.transpose(s_next))

    def _total_reward(self, m0, s0, horizon):
        """Sum of expected rewards of steps 1..H and the final state, in one graph.

        Shapes: m0 [1, D], s0 [D, D], horizon scalar int32 -> m_H [1, D], s_H [D, D],
        total [1, 1].
        """
        dynamics = self.dynamics()
        prepared = self.controller.prepare()
        D = self.state_dim

        def body(t, m, s, total):
            m, s = self.step(m, s, dynamics, prepared)
            r, _ = self.reward.moments(m, s)
            return t + 1, m, s, total + r

        _, m, s, total = tf.while_loop(
            lambda t, *_: t < horizon, body,
            (tf.constant(0), m0, s0, tf.zeros([1, 1], dtype=m0.dtype)),
            shape_invariants=(tf.TensorShape([]), tf.TensorShape([1, D]),
                              tf.TensorShape([D, D]), tf.TensorShape([1, 1])),
        )
        return m, s, total

    def policy_loss(self):
        """The policy objective: minus the total expected reward of ``horizon`` steps from
        ``N(m_init, S_init)`` (a scalar), with the dynamics model of the last refresh."""
        _, _, total = self.total_reward(
            tf.convert_to_tensor(self.m_init), tf.convert_to_tensor(self.S_init),
            tf.convert_to_tensor(self.horizon),
        )
        return -total[0, 0]

    def _trajectory(self, m0, s0, horizon):
        """States 0..H and their reward moments: M [H+1, D], S [H+1, D, D], R, Rv [H+1]."""
        dynamics = self.dynamics()
        prepared = self.controller.prepare()
        D = self.state_dim
        dtype = m0.dtype
        r0, v0 = self.reward.moments(m0, s0)
        arrays = tuple(tf.TensorArray(dtype, size=horizon + 1) for _ in range(4))
        arrays = tuple(a.write(0, x) for a, x in zip(arrays, (m0[0], s0, r0[0, 0], v0[0, 0])))

        def body(t, m, s, Ms, Ss, Rs, Vs):
            m, s = self.step(m, s, dynamics, prepared)
            r, v = self.reward.moments(m, s)
            return (t + 1, m, s, Ms.write(t, m[0]), Ss.write(t, s), Rs.write(t, r[0, 0]),
                    Vs.write(t, v[0, 0]))

        out = tf.while_loop(
            lambda t, *_: t <= horizon, body, (tf.constant(1), m0, s0) + arrays,
            shape_invariants=(tf.TensorShape([]), tf.TensorShape([1, D]),
                              tf.TensorShape([D, D])) + tuple(tf.TensorShape(None) for _ in arrays),
        )
        return tuple(a.stack() for a in out[3:])

    def _action(self, x):
        """The policy's action at a known state (zero covariance): x [1, D] -> u [1, U]."""
        f = default_float()
        D = self.state_dim
        Mf, _, _ = augment_state(x, tf.zeros([D, D], f), self.angle_indices)
        F = D + len(self.angle_indices)
        M, _, _ = self.controller.moments(Mf, tf.zeros([F, F], f), True)
        return M
