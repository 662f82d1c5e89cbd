"""The compiled, moment-matched rollout of a policy through the GP dynamics model.

One step (MATLAB PILCO's ``propagate``) maps the state distribution ``x_t ~ N(m, s)`` to
``x_{t+1}``; which dimensions each part reads is the agent's
:class:`~pilco.models.layout.StateLayout` (MATLAB's ``poli``, ``dyni``, ``dyno``):

1. angles are replaced by (sin, cos) features ``z``; the policy reads the features
   ``z_p`` of its dimensions, the dynamics GPs those ``z_d`` of theirs;
2. the policy returns ``u ~ N(Mu, Su)`` for the distribution of ``z_p`` (optionally it
   sees a noisy measurement ``s + diag(noise) / 2``, ``noise`` being the dynamics GPs'
   likelihood variances, 0 for context dimensions, as some MATLAB PILCO versions do);
3. the dynamics GPs predict the difference ``Δ`` of the predicted dimensions at
   ``[z_d, u]``;
4. ``x_{t+1} = x_t + Δ`` (context dimensions unchanged) with every cross-covariance
   kept.

The policy objective, the sum over one or more start distributions (tasks) of the
expected rewards of ``horizon`` steps, with its start mixture, start points and wide
start, is :mod:`pilco.models.objective`, whose
:class:`~pilco.models.objective.PolicyObjective` is a base class of :class:`Rollout`.
Each horizon is one ``tf.while_loop`` inside a compiled function, traced once; the
dynamics GP's factorisation (Cholesky, ``beta`` and ``K^-1``) does not depend on the
policy: :meth:`Rollout.refresh` computes it once per policy optimisation and stores it
in non-trainable variables that the compiled functions read.

The objective can also be compiled whole by XLA (:meth:`Rollout.xla_policy_loss`): its
graph then avoids the operations XLA lacks on CPU, the horizon is a constant of the
trace, and :meth:`Rollout.refresh` with ``pad=True`` pads the factorisation to a few fixed
sizes (:func:`pilco.moments.bucket_size`), so that XLA compiles once per size bucket
rather than once per data size.
"""
from __future__ import annotations

import gpflow
import tensorflow as tf
from gpflow.config import default_float

from .. import moments
from ..angles import augment_state, point_features
from ..protocols import Controller, Reward
from .layout import StateLayout
from .objective import PolicyObjective

__all__ = ["Rollout"]


def _constant(pick):
    """A one-hot selection of :class:`StateLayout` as a constant, or None (identity)."""
    return None if pick is None else tf.constant(pick, dtype=default_float())


def _select(M, S, pick):
    """Moments of a selection ``z P`` of ``z ~ N(M, S)``: [1, F], [F, F], P [F, K] ->
    [1, K], [K, K] (unchanged when ``pick`` is None)."""
    if pick is None:
        return M, S
    return tf.matmul(M, pick), tf.matmul(pick, tf.matmul(S, pick), transpose_a=True)


def _right(A, pick):
    """``A P``: the columns of ``A`` that ``pick`` [F, K] selects (``A`` if None)."""
    return A if pick is None else tf.matmul(A, pick)


class Rollout(PolicyObjective, gpflow.base.Module):
    """Moment-matched multi-step prediction of a controller, dynamics model and reward.

    Args:
        controller: a :class:`pilco.protocols.Controller` reading the policy features
            (``state_dim == layout.policy_dim``).
        reward: a :class:`pilco.protocols.Reward` on the raw state (D dimensions).
        layout: the :class:`StateLayout` (state size D, angles, context and index sets).
        control_dim: U.
        policy_input_noise: the policy sees ``s + diag(noise) / 2`` instead of ``s``.
        horizon: the policy objective's horizon.
        m_init [T, D], S_init [T, D, D]: the T start distributions (tasks) of the policy
            objective, kept in the variables of the same names (checked by the caller).
    """

    def __init__(self, controller: Controller, reward: Reward, layout: StateLayout,
                 control_dim: int, policy_input_noise: bool, horizon: int, m_init, S_init):
        super().__init__()
        self.horizon = tf.Variable(horizon, trainable=False, dtype=tf.int32, name="horizon")
        self._horizon = int(horizon)  # the same, for traces that need it as a constant
        self.layout = layout
        self.state_dim = D = layout.state_dim
        self.m_init = tf.Variable(m_init, shape=[None, D], trainable=False, name="m_init")
        self.S_init = tf.Variable(S_init, shape=[None, D, D], trainable=False, name="S_init")
        self.num_tasks = int(m_init.shape[0])
        self.start_spread = None  # no start mixture (set_start_mixture)
        self._mixture_means = None  # [T, K, D] and [T, D, D] variables once a mixture is set
        self._mixture_covariances = None
        self.start_points = None  # [T, P, D] known start states (set_start_points)
        self.start_scale = None  # no wide start (set_start_scale)
        self._points = None  # their variable once set
        self._controller = controller
        self._reward = reward
        self.angle_indices = layout.angle_indices
        self.policy_input_noise = policy_input_noise
        E = layout.num_outputs
        inputs = layout.gp_state_dim + control_dim  # GP input size
        f = default_float()
        # The dynamics model as of the last refresh(): its centers [n, inputs], beta [E, n],
        # K^-1 [E, n, n], lengthscales [E, inputs], signal and noise variances [E].
        self._centers = tf.Variable(tf.zeros([0, inputs], f), shape=[None, inputs],
                                    trainable=False)
        self._beta = tf.Variable(tf.zeros([E, 0], f), shape=[E, None], trainable=False)
        self._inverse = tf.Variable(tf.zeros([E, 0, 0], f), shape=[E, None, None],
                                    trainable=False)
        self._lengthscales = tf.Variable(tf.ones([E, inputs], f), trainable=False)
        self._signal_variance = tf.Variable(tf.ones([E], f), trainable=False)
        self._noise_variance = tf.Variable(tf.ones([E], f), trainable=False)
        self.retrace()

    def retrace(self) -> None:
        """(Re)create the compiled functions. A trace captures the controller and the
        reward it was traced with, so replacing either must drop the old traces."""
        self.total_reward = tf.function(self._total_reward, autograph=False)
        self.mixture_total = tf.function(self._mixture_total, autograph=False)
        self.points_total = tf.function(self._points_total, autograph=False)
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

    def set_horizon(self, horizon: int) -> bool:
        """Set the objective's horizon (checked by the caller); True if it changed, which
        makes the XLA objective's trace stale (its horizon is a constant of the trace)."""
        self.horizon.assign(horizon)
        changed = int(horizon) != self._horizon
        self._horizon = int(horizon)
        return changed

    def refresh(self, dynamics_model, pad: bool = False) -> None:
        """Factorise ``dynamics_model`` (an :class:`MGPR`) for the compiled functions;
        with ``pad``, padded to :func:`pilco.moments.bucket_size` centres by points of
        zero weight (the predictions are the same; see :mod:`pilco.moments.compiled`)."""
        factorization = dynamics_model.factorize()
        if pad:
            n = int(factorization.centers.shape[0])
            factorization = moments.pad_factorization(factorization, moments.bucket_size(n))
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
        ``prepare()`` result. With the identity layout (no context, both the policy and
        the GP read every dimension) every selection below is skipped: the step is the
        plain agent's, operation for operation.
        """
        layout = self.layout
        ang = self.angle_indices
        policy_pick = _constant(layout.policy_pick)  # [F, Fp] or None
        dynamics_pick = _constant(layout.dynamics_pick)  # [F, Fd] or None
        place = _constant(layout.output_place)  # [E, D] or None
        Mf, Sf, Cf = augment_state(m, s, ang)  # z: [1, F], [F, F], inv(s) Cov[x, z] [D, F]
        if self.policy_input_noise:
            noise = 0.5 * tf.convert_to_tensor(self._noise_variance)  # [E]
            if place is not None:  # context dimensions are measured without noise
                noise = tf.linalg.matvec(place, noise, transpose_a=True)  # [D]
            noisy = s + tf.linalg.diag(noise)
            Mn, Sn, _ = augment_state(m, noisy, ang)
        else:
            Mn, Sn = Mf, Sf
        Mp, Sp = _select(Mn, Sn, policy_pick)
        Mu, Su, Cu = self.controller.moments(Mp, Sp, True, prepared)  # Cu [Fp, U]
        # Cov[z, u] = Cov[z, z_p] inv(S_p) Cov[z_p, u] (MATLAB propagate's S(j,i) * C)
        cov_fu = tf.matmul(_right(Sf, policy_pick), Cu)  # [F, U]
        Md_in, Sd_in = _select(Mf, Sf, dynamics_pick)  # z_d: [1, Fd], [Fd, Fd]
        cov_du = cov_fu if dynamics_pick is None else tf.matmul(
            dynamics_pick, cov_fu, transpose_a=True)  # Cov[z_d, u], [Fd, U]
        m_in = tf.concat([Md_in, Mu], axis=1)
        s_in = tf.concat(
            [tf.concat([Sd_in, cov_du], 1), tf.concat([tf.transpose(cov_du), Su], 1)], 0
        )
        Md, Sd, Vd = moments.predict(m_in, s_in, dynamics)  # [1, E], [E, E], [Fd + U, E]
        sCf = tf.matmul(s, Cf)  # Cov[x, z], [D, F]
        cov_xu = tf.matmul(_right(sCf, policy_pick), Cu)  # Cov[x, u], [D, U]
        cov_x_in = tf.concat([_right(sCf, dynamics_pick), cov_xu], axis=1)  # Cov[x, (z_d, u)]
        cov_xd = tf.matmul(cov_x_in, Vd)  # Cov[x, Δ], [D, E]
        if place is not None:
            # Δ of the predicted dimensions placed in the state, 0 in the context ones:
            # their mean, variance and covariance with each other stay as they were
            Md = tf.matmul(Md, place)  # [1, D]
            Sd = tf.matmul(place, tf.matmul(Sd, place), transpose_a=True)  # [D, D]
            cov_xd = tf.matmul(cov_xd, place)  # [D, D]
        m_next = m + Md
        s_next = s + Sd + cov_xd + tf.transpose(cov_xd)
        return m_next, 0.5 * (s_next + tf.transpose(s_next))

    def point_step(self, x, dynamics: moments.Predictor, prepared):
        """One step of P known states through the policy and the dynamics GPs' predictive
        means (no uncertainty is propagated): x [P, D] -> x' [P, D]. ``dynamics`` and
        ``prepared`` as in :meth:`step`."""
        layout = self.layout
        policy_pick = _constant(layout.policy_pick)
        dynamics_pick = _constant(layout.dynamics_pick)
        place = _constant(layout.output_place)
        z = point_features(x, self.angle_indices)  # [P, F]
        u = self._point_actions(_right(z, policy_pick), prepared)  # [P, U]
        delta = moments.point_means(tf.concat([_right(z, dynamics_pick), u], axis=1),
                                    dynamics)  # [P, E]
        return x + _right(delta, place)

    def _point_actions(self, z, prepared):
        """The policy's actions at P known inputs: z [P, F] -> [P, U], with the
        controller's ``point_actions`` when it has one, else the mean of its ``moments``
        at a zero covariance, row by row."""
        batched = getattr(self.controller, "point_actions", None)
        if batched is not None:
            return batched(z, prepared)
        F = int(z.shape[-1])
        zero = tf.zeros([F, F], z.dtype)
        return tf.concat([self.controller.moments(z[i:i + 1], zero, True, prepared)[0]
                          for i in range(int(z.shape[0]))], axis=0)

    def _total_reward(self, m0, s0, horizon, maximum_iterations=None):
        """Sum of expected rewards of steps 1..H and the final state, in one graph.

        Shapes: m0 [1, D], s0 [D, D], horizon scalar int32 (or a Python int, with
        ``maximum_iterations`` the same int for XLA) -> m_H [1, D], s_H [D, D],
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
            maximum_iterations=maximum_iterations,
        )
        return m, s, total

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
        pick = _constant(self.layout.policy_pick)
        if pick is not None:
            Mf = tf.matmul(Mf, pick)
        F = Mf.shape[-1]
        M, _, _ = self.controller.moments(Mf, tf.zeros([F, F], f), True)
        return M
