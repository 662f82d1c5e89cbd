"""What a run has collected and how it is saved and scored: :class:`RunRecord`, the
state half of :class:`~pilco.experiment.loop.Experiment`."""
from __future__ import annotations

import logging
import time
from typing import Any, Callable, Dict, List, Optional, Tuple, Union

import numpy as np

from .config import ExperimentConfig
from .episode import Episode, stack_transitions
from .scoring import PHASES, episode_record, episode_solved, summarise
from .store import RunStore, progress_record

__all__ = ["RunRecord"]

logger = logging.getLogger(__name__)

Data = Tuple[np.ndarray, np.ndarray]


class RunRecord:
    """The episodes, records, predictions, timings and task state of one run, the agent
    they trained, and the run directory they are saved to (see :class:`Experiment`).

    Task state that must survive a resume lives in typed attributes:
    ``train_from_episode`` (1-based: the model learns from this episode on),
    ``older_noise_scale`` and ``older_before_episode`` (the transitions of episodes before
    ``older_before_episode`` have their noise variance multiplied by ``older_noise_scale``
    in the model: a large factor down-weights them, e.g. the healthy arm's after a damage;
    a list gives each state dimension's GP its own factor),
    ``inert_actions`` and ``inert_from_episode`` (action dimensions that had no effect on
    the system from that episode on, e.g. a stuck joint's command: the model sees them as
    0 there, their effective value; the episodes keep what was sent)
    and ``summary_fields`` (extra fields of the summary, e.g. when a damage happened).
    """

    def __init__(self, config: ExperimentConfig, directory: str,
                 settings: Optional[Dict[str, Any]] = None,
                 success_fn: Optional[Callable[[Dict[str, Any]], bool]] = None):
        self.config = config
        self.store = RunStore(directory)
        #: the task's settings (JSON-ready), saved for ``--resume``
        self.settings = dict(settings or {})
        self.success_fn = success_fn
        self.agent = None
        self.episodes: List[Episode] = []
        self.records: List[Dict[str, Any]] = []
        #: the model's predictions for each episode (empty for random episodes)
        self.predictions: List[Dict[str, np.ndarray]] = []
        self.seconds = {p: 0.0 for p in PHASES}
        self.cpu_seconds: Dict[int, Dict[str, float]] = {}
        self.wall_seconds = 0.0
        self.train_from_episode = 1
        #: float, or one float per state dimension (its output GP's factor)
        self.older_noise_scale: Union[float, List[float]] = 1.0
        self.older_before_episode = 1
        #: action dimensions (0-based) the model sees as 0 from ``inert_from_episode`` on
        self.inert_actions: List[int] = []
        self.inert_from_episode = 1
        self.summary_fields: Dict[str, Any] = {}
        self.interrupted = False
        self.complete = False
        self._partial: Optional[Episode] = None
        self._t_start: Optional[float] = None
        #: the training data of the last model fit (``train_model`` skips an identical refit)
        self.model_trained_on: Optional[Data] = None

    @property
    def directory(self) -> str:
        return self.store.directory

    def episode_seed(self, number: int) -> int:
        """Seed of episode ``number``'s reset, random actions and optimiser restarts."""
        return int(self.config.seed) * 1000 + int(number)

    # -- data ---------------------------------------------------------------------------
    def all_transitions(self) -> Data:
        """Every collected transition: ``X [N, D+U]``, ``Y [N, D]``, episode order."""
        return stack_transitions(self.episodes)

    def _training_episodes(self) -> List[Tuple[int, Episode]]:
        """``(number, episode)`` of the episodes the model learns from: from
        ``train_from_episode`` on, at least the last one (numbers 1-based)."""
        first = min(self.train_from_episode, len(self.episodes))
        return list(enumerate(self.episodes[first - 1:], start=first))

    def training_data(self) -> Data:
        """The model's transitions: episodes from ``train_from_episode`` on (at least the
        last one), the first ``max_data`` of them; the ``inert_actions`` of episodes from
        ``inert_from_episode`` on are 0 (what reached the system)."""
        episodes = self._training_episodes()
        X, Y = stack_transitions([e for _, e in episodes])
        if self.inert_actions and len(X):
            inert = np.concatenate([np.full(e.steps, number >= self.inert_from_episode)
                                    for number, e in episodes])
            columns = Y.shape[1] + np.asarray(self.inert_actions, dtype=int)
            X[np.ix_(inert, columns)] = 0.0  # X is stack_transitions' own new array
        if self.config.max_data is not None:
            X, Y = X[: self.config.max_data], Y[: self.config.max_data]
        return X, Y

    def training_noise_scales(self) -> np.ndarray:
        """Noise-variance factor of each transition of :meth:`training_data`, [N] (or
        [D, N] when ``older_noise_scale`` is a list, one factor per output GP):
        ``older_noise_scale`` for the episodes before ``older_before_episode``, else 1;
        all ones while the data hold no transition of a later episode (older data are
        down-weighted against newer ones only: scaling every noise variance alike would
        only change the fit)."""
        older = np.asarray(self.older_noise_scale, dtype=float)
        old = np.concatenate([np.full(e.steps, number < self.older_before_episode)
                              for number, e in self._training_episodes()])
        if self.config.max_data is not None:
            old = old[: self.config.max_data]
        if np.all(old):
            old = np.zeros_like(old)
        return np.where(old, older[..., None] if older.ndim else older, 1.0)

    def give_agent_data(self, agent) -> None:
        """``agent.set_data`` with :meth:`training_data` and, when some differ from 1,
        :meth:`training_noise_scales`."""
        scales = self.training_noise_scales()
        agent.set_data(self.training_data(),
                       **({"noise_scales": scales} if np.any(scales != 1.0) else {}))

    def start_states(self) -> np.ndarray:
        """First state of every episode so far, ``[E, D]``."""
        return np.stack([e.states[0] for e in self.episodes])

    # -- saving and resuming ------------------------------------------------------------
    def wall(self) -> float:
        """Wall time of the run so far, all sessions."""
        return self.wall_seconds + (time.perf_counter() - self._t_start if self._t_start else 0)

    def save_progress(self) -> None:
        """Write ``progress.json`` and ``summary.json``."""
        self.store.save_progress(progress_record(self), self.summary())

    def save(self) -> None:
        """Save data first (never lose transitions), then the agent, then progress."""
        self.store.save_data(self.episodes, self.predictions, self._partial)
        if self.agent is not None:
            self.store.save_agent(self.agent)
        self.save_progress()

    # -- scores -------------------------------------------------------------------------
    def episode_solved(self, episode: Episode) -> bool:
        """Whether an episode meets the task's solved rule."""
        return episode_solved(episode, self.config)

    def solved_at_episode(self) -> Optional[int]:
        """Number of the first learned episode that solved the task, or None."""
        for rec, ep in zip(self.records, self.episodes):
            if not rec["random"] and self.episode_solved(ep):
                return int(rec["episode"])
        return None

    def summary(self) -> Dict[str, Any]:
        """The run's summary (``summary.json``, see :func:`~.scoring.summarise`)."""
        return summarise(self)

    def _add_episode(self, episode: Episode, seconds: Dict[str, float],
                     prediction: Dict[str, np.ndarray]) -> Dict[str, Any]:
        self.episodes.append(episode)
        self.predictions.append(prediction)
        rec = episode_record(episode, len(self.episodes), seconds, self.config)
        self.records.append(rec)
        for p in PHASES:
            self.seconds[p] += float(seconds.get(p, 0.0))
        self._partial = None
        if self.agent is not None:
            self.give_agent_data(self.agent)
        self.save()
        logger.info("episode %d (%s): %d steps, final distance %.4f, min %.4f, cost %.2f, "
                    "to target %s; %.1f s interaction, %.1f s model, %.1f s policy",
                    rec["episode"], "random" if rec["random"] else "learned", rec["steps"],
                    rec["final_distance"], rec["min_distance"], rec["cost"],
                    rec["steps_to_target"], *(rec["seconds"][p] for p in PHASES))
        return rec

    def last_frames(self) -> List[np.ndarray]:
        """Frames of the most recent episode that was rendered (may be empty)."""
        for ep in reversed(self.episodes):
            if ep.frames:
                return ep.frames
        return []
