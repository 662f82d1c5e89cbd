"""What a run has collected and how it is saved and scored: :class:`RunRecord`, the
state half of :class:`~pilco.experiment.loop.Experiment`."""
from __future__ import annotations

import logging
import time
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from .config import ExperimentConfig
from .episode import Episode, stack_transitions
from .hooks import RunHooks
from .scoring import PHASES, episode_record, episode_solved, summarise
from .store import RunStore, progress_record

__all__ = ["RunRecord"]

logger = logging.getLogger(__name__)

Data = Tuple[np.ndarray, np.ndarray]


class RunRecord:
    """The episodes, records, predictions, timings and task state of one run, the agent
    they trained, and the run directory they are saved to (see :class:`Experiment`).

    What a task keeps across a resume lives in ``task_state`` (a JSON-ready dict, saved
    in ``progress.json``) and ``summary_fields`` (extra fields of the summary, e.g. when a
    damage happened). Which transitions the model learns from, and the success rule, are
    the task's ``hooks`` (:meth:`~pilco.experiment.hooks.RunHooks.model_data`,
    :meth:`~pilco.experiment.hooks.RunHooks.success`).
    """

    def __init__(self, config: ExperimentConfig, directory: str,
                 settings: Optional[Dict[str, Any]] = None,
                 hooks: Optional[RunHooks] = None):
        self.config = config
        self.store = RunStore(directory)
        #: the task's settings (JSON-ready), saved for ``--resume``
        self.settings = dict(settings or {})
        #: what the task tells the loop (:class:`~pilco.experiment.hooks.RunHooks`)
        self.hooks = RunHooks() if hooks is None else hooks
        self.agent = None
        self.episodes: List[Episode] = []
        self.records: List[Dict[str, Any]] = []
        #: the model's predictions for each episode (empty for random episodes)
        self.predictions: List[Dict[str, np.ndarray]] = []
        self.seconds = {p: 0.0 for p in PHASES}
        self.cpu_seconds: Dict[int, Dict[str, float]] = {}
        self.wall_seconds = 0.0
        #: what the task keeps across a resume (JSON-ready; saved in progress.json)
        self.task_state: Dict[str, Any] = {}
        self.summary_fields: Dict[str, Any] = {}
        self.interrupted = False
        self.complete = False
        self._partial: Optional[Episode] = None
        #: True while a learned episode's model fit and policy search change the agent:
        #: an interrupt then keeps ``agent.npz`` as the last finished episode left it
        self._learning = False
        self._t_start: Optional[float] = None
        #: the training data of the last model fit (``train_model`` skips an identical refit)
        self.model_trained_on: Optional[Data] = None
        #: what the coming learned episode's policy phase adds to its record (the start
        #: mixture's fragility check, ``start_mixture``) and its further objective
        #: evaluations (``extra_evaluations``), set by :func:`~.learning.improve_policy`
        self.policy_notes: Dict[str, Any] = {}

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

    def _model_data(self) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The hooks' :meth:`~pilco.experiment.hooks.RunHooks.model_data` transitions and
        factors (default: every episode, factors 1), the first ``max_data`` of them."""
        chosen = self.hooks.model_data(self)
        if chosen is None:
            X, Y = stack_transitions(self.episodes)
            scales = None
        else:
            X, Y, scales = chosen
        scales = np.ones(len(X)) if scales is None else np.asarray(scales, dtype=float)
        cap = self.config.max_data
        if cap is not None:
            X, Y, scales = X[:cap], Y[:cap], scales[..., :cap]
        return X, Y, scales

    def training_data(self) -> Data:
        """The model's transitions ``X [N, D+U]``, ``Y [N, D]``: those of
        the hooks' ``model_data`` (default: every episode's), the first ``max_data`` of them."""
        X, Y, _ = self._model_data()
        return X, Y

    def training_noise_scales(self) -> np.ndarray:
        """Noise-variance factor of each transition of :meth:`training_data`, [N] (or
        [D, N], one row per output GP): the hooks' ``model_data``'s, default all 1."""
        return self._model_data()[2]

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
        """Save data first (never lose transitions), then the agent, then progress. The
        agent is not saved while a learned episode's model fit or policy search is under
        way (an interrupt there): ``agent.npz`` stays as the last finished episode left it,
        so that ``--resume`` redoes that episode from the same state as the run would
        have, and the resumed run is the uninterrupted one."""
        self.store.save_data(self.episodes, self.predictions, self._partial)
        if self.agent is not None and not self._learning:
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
                     prediction: Dict[str, np.ndarray],
                     policy_evaluations: Optional[int] = None) -> Dict[str, Any]:
        self.episodes.append(episode)
        self.predictions.append(prediction)
        rec = episode_record(episode, len(self.episodes), seconds, self.config)
        # objective + gradient evaluations of the episode's policy search (0 for a random
        # episode; None when the agent does not count them)
        rec["policy_evaluations"] = (0 if episode.random else None) \
            if policy_evaluations is None else int(policy_evaluations)
        if not episode.random and self.policy_notes:
            notes = dict(self.policy_notes)
            extra = int(notes.pop("extra_evaluations", 0))
            if rec["policy_evaluations"] is not None:
                rec["policy_evaluations"] += extra
            rec.update(notes)
        self.policy_notes = {}
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
