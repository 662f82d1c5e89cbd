"""What a task tells the loop: :class:`RunHooks`, the one object
:class:`~pilco.experiment.loop.Experiment` calls into.

Every method has a default, so a task overrides only what it changes. They fall in four
groups, in the order a run meets them:

=====================  ==============================================================
group                  methods
=====================  ==============================================================
building               :meth:`~RunHooks.make_env`, :meth:`~RunHooks.build_agent`,
                       :meth:`~RunHooks.opened`
the episode schedule   :meth:`~RunHooks.before_episode`, :meth:`~RunHooks.after_episode`,
                       :meth:`~RunHooks.finished`
one episode            :meth:`~RunHooks.reset_options`, :meth:`~RunHooks.watch`,
                       :meth:`~RunHooks.distance`, :meth:`~RunHooks.render`
learning               :meth:`~RunHooks.model_data`, :meth:`~RunHooks.after_model_fit`,
                       :meth:`~RunHooks.before_policy_search`,
                       :meth:`~RunHooks.after_policy_search`,
                       :meth:`~RunHooks.before_replayed_episode`
scoring                :meth:`~RunHooks.success`
=====================  ==============================================================

``run`` is always the :class:`~pilco.experiment.loop.Experiment` (or, in a replay of its
learning, a view of it: :func:`pilco.diagnose.replay.view_before`); what a task keeps
across a resume lives in ``run.summary_fields`` and ``run.task_state``, which the run saves.
"""
from __future__ import annotations

from typing import Any, Callable, ClassVar, Dict, List, Optional, Tuple

import numpy as np

from .episode import Episode, distance_from_info, make_env

__all__ = ["RunHooks", "FunctionHooks"]

Data = Tuple[np.ndarray, np.ndarray]


class RunHooks:
    """The loop's view of a task; subclass it and override what the task changes."""

    #: True when :meth:`render` draws the final episode (the env then never renders)
    draws_frames: ClassVar[bool] = False

    # -- building -------------------------------------------------------------------------
    def make_env(self, run) -> Any:
        """The run's environment, made once per run (default: ``gymnasium.make`` of the
        config's ``env_id`` and ``env_kwargs``)."""
        cfg = run.config
        return make_env(cfg.env_id, cfg.env_kwargs, render=cfg.render and not self.draws_frames)

    def build_agent(self, data: Data, start_states: np.ndarray) -> Any:
        """The agent for data ``(X [N, D+U], Y [N, D])`` and ``start_states`` [E, D] (the
        first state of every episode so far): called once the random episodes are in, on
        resume when no saved agent can be read, and by a replay of the run's learning."""
        raise NotImplementedError(
            f"{type(self).__name__} builds no agent: a run without its task's agent builder "
            f"continues only from its saved agent.npz, and its learning cannot be replayed")

    def opened(self, run) -> None:
        """A new run was opened, or a saved one was read back (its episodes, fields,
        task state and agent restored): set what the task keeps beside them."""

    # -- the episode schedule -------------------------------------------------------------
    def before_episode(self, run, number: int) -> bool:
        """Whether episode ``number`` (1-based) runs; False ends the run as complete.
        Before a learned episode a task may also change its system or agent here (the
        adaptation breaks the arm). Default: ``number <= config.episodes``."""
        return number <= run.config.episodes

    def after_episode(self, run, number: int) -> None:
        """Episode ``number`` ran and was saved."""

    def finished(self, run) -> None:
        """The schedule ended (the run is complete): e.g. test the final policy."""

    # -- one episode ----------------------------------------------------------------------
    def reset_options(self, number: int) -> Optional[dict]:
        """Options of ``env.reset`` for episode ``number`` (e.g. its target)."""
        return None

    def watch(self, run, number: int, policy: Callable) -> Callable:
        """The policy ``x [D] -> u [U]`` that learned episode ``number`` runs: ``policy``,
        or a wrapper that watches the states as they come (and may re-plan; seconds it
        notes in ``run.policy_notes["paused_seconds"]`` count as policy time)."""
        return policy

    def distance(self, env, info: Dict[str, Any]) -> float:
        """The task distance of a state from ``env.reset``'s or ``env.step``'s ``info``
        (default: ``info["distance"]`` or ``info["tip_distance"]``, checked at the first
        reset with an error that names the contract)."""
        return distance_from_info(env, info)

    def render(self, run, episode: Episode) -> List[np.ndarray]:
        """Frames of the final episode when :attr:`draws_frames` (e.g. a replay in another
        process); otherwise the env renders while it runs."""
        return []

    # -- learning -------------------------------------------------------------------------
    def model_data(self, run) -> Optional[Tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]]:
        """The transitions the model learns from and their noise-variance factors, before
        the ``max_data`` cap: ``(X [N, D+U], Y [N, D], factors [N] or [D, N] or None)``;
        None (the default): every episode's transitions, all factors 1."""
        return None

    def after_model_fit(self, run, number: int) -> None:
        """After episode ``number``'s model fit (``run.agent`` holds the fitted model)."""

    def before_policy_search(self, run, number: int) -> None:
        """Before episode ``number``'s policy search (e.g. a cost that changes with the
        episode)."""

    def after_policy_search(self, run, number: int, expected: float) -> None:
        """After episode ``number``'s policy search, whose policy predicts the return
        ``expected``: e.g. check it (Safe PILCO's risk) and search again, counted as the
        episode's policy time. What it notes in ``run.policy_notes`` goes into the
        episode's record (``extra_evaluations`` adds to its policy evaluations)."""

    def before_replayed_episode(self, run, view, number: int) -> None:
        """When the run's learning is replayed (:func:`pilco.diagnose.replay.replay_learning`),
        before episode ``number``'s model fit: redo on ``view.agent`` what the task changed
        in its agent during the run (the adaptation's damage)."""

    # -- scoring --------------------------------------------------------------------------
    def success(self, summary: Dict[str, Any]) -> bool:
        """The task's success rule on the run's summary (default: ``summary["solved"]``)."""
        return bool(summary["solved"])


class FunctionHooks(RunHooks):
    """:class:`RunHooks` from plain functions, for a script's own run: ``build_agent``
    ``(data, start_states) -> agent`` and optionally ``make_env`` ``() -> env``,
    ``distance`` ``(env, info) -> float`` and ``success`` ``summary -> bool``."""

    def __init__(self, build_agent: Optional[Callable[[Data, np.ndarray], Any]] = None,
                 make_env: Optional[Callable[[], Any]] = None,
                 distance: Optional[Callable[[Any, dict], float]] = None,
                 success: Optional[Callable[[Dict[str, Any]], bool]] = None):
        self._build, self._make_env = build_agent, make_env
        self._distance, self._success = distance, success

    def make_env(self, run) -> Any:
        return super().make_env(run) if self._make_env is None else self._make_env()

    def build_agent(self, data: Data, start_states: np.ndarray) -> Any:
        if self._build is None:
            return super().build_agent(data, start_states)
        return self._build(data, start_states)

    def distance(self, env, info: Dict[str, Any]) -> float:
        return super().distance(env, info) if self._distance is None else self._distance(
            env, info)

    def success(self, summary: Dict[str, Any]) -> bool:
        return super().success(summary) if self._success is None else bool(
            self._success(summary))
