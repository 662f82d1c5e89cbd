"""The policy objective: each task's total from its start, start mixture, points and wide start.

The objective is the sum, over one or more start distributions (tasks), of the expected
rewards of ``horizon`` steps. With a start mixture (:meth:`PolicyObjective.set_start_mixture`)
each task's start distribution is split into 2D + 1 narrower Gaussians of the same mean and
covariance (:func:`pilco.models.starts.start_mixture`), each propagated on its own, and the
task's expected return is their mean. Without a mixture, a task's total can also be the
mean of its plain total and those of known start states followed through the policy and
the model's mean dynamics (:meth:`PolicyObjective.set_start_points`,
:meth:`pilco.models.rollout.Rollout.point_step`) and of a wider Gaussian start
(:meth:`PolicyObjective.set_start_scale`).

:class:`PolicyObjective` holds these methods of :class:`pilco.models.rollout.Rollout` (its
base class; they use its steps, horizon loops, compiled functions and the variables it
creates: ``m_init``, ``S_init``, ``horizon`` and the start variables set here).
"""
from __future__ import annotations

import logging
from typing import Optional

import tensorflow as tf
from gpflow.config import default_float

from .. import moments
from .starts import start_mixture

__all__ = ["PolicyObjective"]

# Rollout.set_starts logs under the rollout's name, as it did inside that module
logger = logging.getLogger("pilco.models.rollout")


def _sum(totals):
    """The sum of a list of [1, 1] tensors, added left to right."""
    total = totals[0]
    for t in totals[1:]:
        total = total + t
    return total


def _negative_sum(totals):
    """Minus the sum of the tasks' totals (a list of [1, 1] tensors), as a scalar."""
    return -_sum(totals)[0, 0]


class PolicyObjective:
    """The policy objective of :class:`~pilco.models.rollout.Rollout`: its starts, the
    totals of start mixtures and start points, each task's total and the losses."""

    # -- the starts -------------------------------------------------------------------------
    def set_starts(self, m_init, S_init) -> bool:
        """Assign the start distributions m_init [T, D], S_init [T, D, D] (checked by the
        caller); returns True if the number of tasks T changed, which drops the compiled
        functions (the objective's sum over tasks is unrolled in its trace)."""
        self.m_init.assign(m_init)
        self.S_init.assign(S_init)
        changed = int(m_init.shape[0]) != self.num_tasks
        self.num_tasks = int(m_init.shape[0])
        if self.start_spread is not None:
            self._assign_mixture()
        if changed and self.start_points is not None:
            logger.info("the number of tasks changed: the policy objective's start points "
                        "are dropped")
            self.start_points = None
        if changed:
            self.retrace()
        return changed

    def set_start_mixture(self, spread) -> None:
        """Split every task's start distribution into :func:`~pilco.models.starts.start_mixture`'s
        2D + 1 components of this ``spread`` (checked by the caller; None: one Gaussian per
        task, the plain objective). The plain and the mixture objectives are functions of
        their own (:meth:`plain_policy_loss`, :meth:`mixture_policy_loss`): switching
        between them retraces neither."""
        self.start_spread = None if spread is None else float(spread)
        if self.start_spread is not None:
            self._assign_mixture()

    def _assign_mixture(self) -> None:
        """The mixture components of the current starts, into their variables."""
        m0, S0 = self.m_init.numpy(), self.S_init.numpy()
        parts = [start_mixture(m, S, self.start_spread) for m, S in zip(m0, S0)]
        means = tf.constant([p[0] for p in parts], dtype=default_float())  # [T, K, D]
        covs = tf.constant([p[1] for p in parts], dtype=default_float())  # [T, D, D]
        if self._mixture_means is None:
            self._mixture_means = tf.Variable(means, shape=[None, None, self.state_dim],
                                              trainable=False, name="mixture_means")
            self._mixture_covariances = tf.Variable(
                covs, shape=[None, self.state_dim, self.state_dim], trainable=False,
                name="mixture_covariances")
        else:
            self._mixture_means.assign(means)
            self._mixture_covariances.assign(covs)

    def set_start_points(self, points) -> bool:
        """Known start states [T, P, D] followed through the policy and the model's mean
        dynamics beside each task's start distribution (checked by the caller; None: none,
        the plain objective). Returns True if the number of points P changed, which drops
        the compiled functions (P is a constant of their traces)."""
        if points is None:
            self.start_points = None
            return False
        points = tf.constant(points, dtype=default_float())
        if self._points is None:
            self._points = tf.Variable(points, shape=[None, None, self.state_dim],
                                       trainable=False, name="start_points")
        else:
            self._points.assign(points)
        count = int(points.shape[1])
        changed = self.start_points is not None and count != self.start_points.shape[1]
        self.start_points = points.numpy()
        if changed:
            self.retrace()
        return changed

    def set_start_scale(self, scale) -> None:
        """Beside each task's start distribution ``N(m, S)``, propagate the wide start
        ``N(m, scale² S)`` (``scale`` checked by the caller; None: none). The same traced
        function serves both (the shapes are the same)."""
        self.start_scale = None if scale is None else float(scale)

    # -- totals of start points and start mixtures -----------------------------------------
    def _point_rewards(self, x):
        """The reward at P known states: x [P, D] -> [P] (the reward's mean for a zero
        covariance, state by state)."""
        D = self.state_dim
        zero = tf.zeros([D, D], x.dtype)
        # one vectorised call (TensorFlow batches the reward's operations over the rows)
        return tf.vectorized_map(lambda row: self.reward.moments(row[None], zero)[0][0, 0], x)

    def _points_total(self, points, horizon, maximum_iterations=None):
        """Mean over P known start states of the reward of steps 1..H under the policy
        and the model's mean dynamics (:meth:`point_step`).

        Shapes: points [P, D], horizon scalar int32 (or a Python int, with
        ``maximum_iterations`` the same int for XLA) -> mean total [1, 1].
        """
        dynamics = self.dynamics()
        prepared = self.controller.prepare()
        P, D = int(points.shape[0]), self.state_dim

        def body(t, x, total):
            x = self.point_step(x, dynamics, prepared)
            return t + 1, x, total + self._point_rewards(x)

        _, _, total = tf.while_loop(
            lambda t, *_: t < horizon, body,
            (tf.constant(0), points, tf.zeros([P], dtype=points.dtype)),
            shape_invariants=(tf.TensorShape([]), tf.TensorShape([P, D]),
                              tf.TensorShape([P])),
            maximum_iterations=maximum_iterations,
        )
        return tf.reshape(tf.reduce_mean(total), [1, 1])

    def _mixture_total(self, means, cov, horizon, maximum_iterations=None):
        """Sum over K start distributions ``N(means[k], cov)`` of their total expected
        reward of steps 1..H, as one loop of K·H steps that restarts from the next start
        every H steps (one trace and one loop whatever K).

        Shapes: means [K, 1, D], cov [D, D], horizon scalar int32 (or a Python int, with
        ``maximum_iterations`` K·H for XLA) -> total [1, 1].
        """
        dynamics = self.dynamics()
        prepared = self.controller.prepare()
        D = self.state_dim
        K = int(means.shape[0])

        def body(t, m, s, total):
            restart = tf.equal(t % horizon, 0)
            m = tf.where(restart, tf.gather(means, tf.minimum(t // horizon, K - 1)), m)
            s = tf.where(restart, cov, s)
            m, s = self.step(m, s, dynamics, prepared)
            r, _ = self.reward.moments(m, s)
            return t + 1, m, s, total + r

        _, _, _, total = tf.while_loop(
            lambda t, *_: t < K * horizon, body,
            (tf.constant(0), means[0], cov, tf.zeros([1, 1], dtype=means.dtype)),
            shape_invariants=(tf.TensorShape([]), tf.TensorShape([1, D]),
                              tf.TensorShape([D, D]), tf.TensorShape([1, 1])),
            maximum_iterations=maximum_iterations,
        )
        return total

    def task_totals(self, xla: bool = False, mixture: Optional[bool] = None,
                    points: Optional[bool] = None, wide: Optional[bool] = None):
        """Total expected reward of ``horizon`` steps from each start distribution
        ``N(m_init[i], S_init[i])``, with the dynamics model of the last refresh: a list
        of T tensors [1, 1]. Each task's horizon is its own call of the compiled
        :meth:`total_reward` (one trace serves all, the tasks have the same shapes); with
        ``xla``, of :meth:`_total_reward` traced inside :func:`pilco.moments.xla_compatible`
        with the horizon as a constant trip count (see :meth:`xla_policy_loss`).
        ``mixture`` (default: whether a start mixture is set) makes each task's total the
        mean over its start mixture's components (:meth:`set_start_mixture`); ``points``
        (default: whether start points are set and no mixture) and ``wide`` (default:
        whether a wide start is set and no mixture) make it the mean of the plain total,
        the mean total of its start points (:meth:`set_start_points`) and the total from
        its wide start (:meth:`set_start_scale`)."""
        D = self.state_dim
        if mixture is None:
            mixture = self.start_spread is not None
        if points is None:
            points = self.start_points is not None and not mixture
        if wide is None:
            wide = self.start_scale is not None and not mixture
        if mixture:  # each task's 2D + 1 mixture components, their mean total
            if self._mixture_means is None:
                raise ValueError("no start mixture is set (set_start_mixture)")
            K = 2 * D + 1
            mm = tf.reshape(tf.convert_to_tensor(self._mixture_means), [-1, K, 1, D])
            ms = tf.convert_to_tensor(self._mixture_covariances)
            if xla:
                H = self._horizon
                with moments.xla_compatible():
                    return [self._mixture_total(mm[i], ms[i], H, maximum_iterations=K * H) / K
                            for i in range(self.num_tasks)]
            horizon = tf.convert_to_tensor(self.horizon)
            return [self.mixture_total(mm[i], ms[i], horizon) / K
                    for i in range(self.num_tasks)]
        m0 = tf.convert_to_tensor(self.m_init)
        s0 = tf.convert_to_tensor(self.S_init)
        starts = [(tf.reshape(m0[i], [1, D]), s0[i]) for i in range(self.num_tasks)]
        if points and self.start_points is None:
            raise ValueError("no start points are set (set_start_points)")
        if wide and self.start_scale is None:
            raise ValueError("no wide start is set (set_start_scale)")
        known = tf.reshape(tf.convert_to_tensor(self._points),
                           [-1, int(self.start_points.shape[1]), D]) if points else None
        scale2 = (self.start_scale ** 2) if wide else None
        if xla:
            H = self._horizon
            with moments.xla_compatible():
                return [self._task_total(m, s, None if known is None else known[i], scale2,
                                         lambda a, b: self._total_reward(
                                             a, b, H, maximum_iterations=H)[2],
                                         lambda x: self._points_total(x, H, H))
                        for i, (m, s) in enumerate(starts)]
        horizon = tf.convert_to_tensor(self.horizon)
        return [self._task_total(m, s, None if known is None else known[i], scale2,
                                 lambda a, b: self.total_reward(a, b, horizon)[2],
                                 lambda x: self.points_total(x, horizon))
                for i, (m, s) in enumerate(starts)]

    @staticmethod
    def _task_total(m, s, known, scale2, gaussian, points):
        """One task's total: the mean of its estimates in use, the expected return of
        ``N(m, s)`` (``gaussian``), its known start points' mean return (``points``, when
        ``known`` is given) and the expected return of ``N(m, scale2 s)`` (when
        ``scale2`` is given)."""
        estimates = [gaussian(m, s)]
        if known is not None:
            estimates.append(points(known))
        if scale2 is not None:
            estimates.append(gaussian(m, scale2 * s))
        return _sum(estimates) / float(len(estimates))

    def policy_loss(self):
        """The policy objective (a scalar): minus the sum over the T start distributions
        of the total expected reward of ``horizon`` steps (each task's the mean over its
        start mixture when one is set, else with its start points and wide start when
        set). Traced inside the optimiser's compiled function,
        the whole sum and its gradient are one graph."""
        return _negative_sum(self.task_totals())

    def plain_policy_loss(self):
        """:meth:`policy_loss` with one Gaussian start per task, whatever is set (a
        function of its own for the optimiser's compiled cache)."""
        return _negative_sum(self.task_totals(mixture=False, points=False, wide=False))

    def mixture_policy_loss(self):
        """:meth:`policy_loss` over the start mixture's components (one must be set)."""
        return _negative_sum(self.task_totals(mixture=True))

    def points_policy_loss(self):
        """:meth:`policy_loss` with each task's total the mean of its plain total and those
        of its start points and wide start, whichever are set (no mixture)."""
        return _negative_sum(self.task_totals(mixture=False))

    def xla_points_policy_loss(self):
        """:meth:`points_policy_loss` for a function compiled by XLA."""
        return _negative_sum(self.task_totals(xla=True, mixture=False))

    def xla_policy_loss(self):
        """:meth:`plain_policy_loss` for a function compiled by XLA (``jit_compile=True``):
        traced inside :func:`pilco.moments.xla_compatible`, the horizon loop with a
        constant trip count (the horizon at trace time: a new horizon needs a new trace,
        see :meth:`set_horizon`). The same value up to rounding."""
        return _negative_sum(self.task_totals(xla=True, mixture=False, points=False,
                                              wide=False))

    def xla_mixture_policy_loss(self):
        """:meth:`mixture_policy_loss` for a function compiled by XLA."""
        return _negative_sum(self.task_totals(xla=True, mixture=True))
