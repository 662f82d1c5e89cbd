"""The agent's start distributions: each task's start, the start mixture, points and wide start.

:class:`AgentStarts` holds these properties of :class:`pilco.models.pilco.PILCO` (its base
class): the policy objective's start of each task (``m_init``, ``S_init``), its start
mixture, start points and wide start. They check their values
(:mod:`pilco.models.starts`) and hand them to the agent's compiled
:class:`~pilco.models.rollout.Rollout`, whose traces they may drop.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from .starts import check_spread, check_start_points, check_starts

__all__ = ["AgentStarts"]


class AgentStarts:
    """The start-distribution properties of :class:`~pilco.models.pilco.PILCO` (it sets
    ``_rollout``, ``state_dim`` and ``_shared_S`` and defines ``_drop_compiled``)."""

    @property
    def m_init(self) -> np.ndarray:
        """Means of the start distributions, one row per task: [T, D] ([1, D] for one).

        Setting it keeps the covariance(s): a shared ``S_init [D, D]`` serves any number
        of rows; with one covariance per task the number of rows must stay T (use
        :meth:`set_initial` to change both)."""
        return self._rollout.m_init.numpy()

    @m_init.setter
    def m_init(self, value):
        if self._shared_S:
            S = self._rollout.S_init.numpy()[0]
        else:
            S = self._rollout.S_init.numpy()
            rows = np.shape(value)[0] if np.ndim(value) == 2 else 1
            if rows != self.num_tasks:
                raise ValueError(
                    f"m_init has {rows} start(s) but S_init holds one covariance per task "
                    f"for {self.num_tasks} tasks: set both with set_initial(m_init, S_init)")
        self.set_initial(value, S)

    @property
    def S_init(self) -> np.ndarray:
        """Covariance of the start distributions: [D, D] when one serves every task (and
        always with one task), [T, D, D] with one per task."""
        S = self._rollout.S_init.numpy()
        return S[0] if self._shared_S else S

    @S_init.setter
    def S_init(self, value):
        self.set_initial(self.m_init, value)  # [D, D]: shared; [T, D, D]: one per task

    @property
    def num_tasks(self) -> int:
        """T, the number of start distributions (tasks) the policy objective sums over."""
        return self._rollout.num_tasks

    def set_initial(self, m_init, S_init) -> None:
        """Replace the start distributions: ``m_init`` [D], [1, D] or [T, D] and
        ``S_init`` [D, D] (shared by all tasks) or [T, D, D] (one per task). A new number
        of tasks retraces the policy objective at its next use."""
        m, S, shared = check_starts(m_init, S_init, self.state_dim, "initial state")
        if self._rollout.set_starts(m, S):
            self._drop_compiled()  # its compiled objective is a trace
        self._shared_S = shared

    @property
    def start_spread(self) -> Optional[float]:
        """The policy objective's start mixture: None (each task's start distribution
        propagated as one Gaussian, the MATLAB objective) or the spread ``a`` of
        :func:`pilco.models.starts.start_mixture`: each start ``N(m, S)`` is split into
        2D + 1 Gaussians of covariance ``(1 - 2a² / (2D + 1)) S``, one at ``m`` and two at
        ``m ± a sqrt(λ_i) v_i`` along each eigenvector of ``S`` (the same mean and
        covariance), propagated one by one; a task's expected return is their mean. A
        policy that fails from the flanks of the start distribution is then seen to fail,
        at 2D + 1 times the objective's cost. Setting 0 or None switches it off."""
        return self._rollout.start_spread

    @start_spread.setter
    def start_spread(self, value) -> None:
        self._rollout.set_start_mixture(check_spread(value, self.state_dim))

    @property
    def start_points(self) -> Optional[np.ndarray]:
        """Known start states of the policy objective, [T, P, D], or None (the MATLAB
        objective). Each task's P points are rolled out through the policy and the
        model's mean dynamics (no uncertainty), and the task's total becomes the mean of
        the expected return of its start distribution, propagated as one moment-matched
        Gaussian, and the points' mean return (and the wide start's, :attr:`start_scale`,
        when set). Points on the flanks of the
        start distribution (:func:`pilco.models.starts.flank_points`) or drawn from it
        (:func:`pilco.models.starts.start_samples`) show the objective a policy that fails
        from part of the start distribution, which the one Gaussian averages away, at a
        fraction of its cost (one kernel row per point and step). Set [P, D] for one
        task, [T, P, D] for several; None switches them off. Ignored while a start
        mixture is set (:attr:`start_spread`)."""
        return self._rollout.start_points

    @start_points.setter
    def start_points(self, value) -> None:
        if self._rollout.set_start_points(
                check_start_points(value, self._rollout.num_tasks, self.state_dim)):
            self._drop_compiled()  # its compiled objective has the number of points

    @property
    def start_scale(self) -> Optional[float]:
        """A wide start beside the start distribution: None, or ``k``: each task's total
        becomes the mean of the expected returns from ``N(m, S)`` and from
        ``N(m, k² S)`` (and of its start points', :attr:`start_points`, when set), both
        moment-matched Gaussians, so that the objective sees what happens from the start
        distribution's flanks with the model's uncertainty there, at twice the cost.
        Ignored while a start mixture is set. Setting 0 or None switches it off."""
        return self._rollout.start_scale

    @start_scale.setter
    def start_scale(self, value) -> None:
        scale = check_spread(value, self.state_dim, "start scale", mixture=False)
        self._rollout.set_start_scale(scale)
