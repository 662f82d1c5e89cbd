"""The run directory: every file a run writes, and reading them back to resume.

- ``data.npz``: every transition so far (``X [N, D+U]``, ``Y [N, D]``, ``episode [N]``),
  every episode's ``states_k``, ``actions_k``, ``rewards_k``, ``distances_k`` and the
  model's predictions made for it (``pred_*_k``, ``onestep_*_k``); after an interrupt also
  the interrupted episode's complete transitions (``partial_*``);
- ``agent.npz``: the agent (``PILCO.save``);
- ``progress.json``: per-episode records, phase times, settings and task state, enough
  to continue with the next episode;
- ``summary.json``: the run's summary.

Each file is written atomically (:mod:`pilco.files`): ``progress.json`` (0 episodes)
when a run starts, then after every episode in the order data, agent, progress. A run
stopped at any moment (even by SIGKILL) leaves every file either in its old or its new
complete version; ``agent.npz`` is never older than what ``progress.json`` counts (unless
saving it failed, which is logged), and ``progress.json`` never counts an episode whose
data are not in ``data.npz`` (also after a failed data write). ``tests/test_hard_kill.py``
kills runs at every write.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import os
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..files import write_json_atomic, write_npz_atomic
from .episode import Episode, stack_transitions

__all__ = ["RunStore", "progress_record", "restore_progress"]

logger = logging.getLogger(__name__)

#: prefixes of the per-episode prediction arrays in ``data.npz``
PREDICTION_PREFIXES = ("pred_", "onestep_")


class RunStore:
    """The files of one run directory (created on construction)."""

    def __init__(self, directory: str):
        self.directory = os.path.abspath(directory)
        os.makedirs(self.directory, exist_ok=True)
        self.data_path, self.agent_path, self.progress_path, self.summary_path = (
            self.path(name) for name in ("data.npz", "agent.npz", "progress.json",
                                         "summary.json"))
        #: episodes in ``data.npz`` as last written or read by this store: what
        #: ``progress.json`` may count (a failed data write leaves the old file)
        self.saved_episodes = 0
        #: whether ``agent.npz`` holds the agent of the newest save: False after a failed
        #: agent write, which leaves an older agent file (or none) behind
        self.agent_current = os.path.exists(self.agent_path)

    def path(self, name: str) -> str:
        """Absolute path of ``name`` inside the run directory."""
        return os.path.join(self.directory, name)

    # -- writing ------------------------------------------------------------------------
    def save_data(self, episodes: Sequence[Episode],
                  predictions: Sequence[Dict[str, np.ndarray]],
                  partial: Optional[Episode] = None) -> None:
        """Rewrite ``data.npz`` with every episode (and the interrupted one's transitions)."""
        arrays: Dict[str, np.ndarray] = {}
        if episodes:
            arrays["X"], arrays["Y"] = stack_transitions(episodes)
            arrays["episode"] = np.concatenate(
                [np.full(e.steps, i + 1) for i, e in enumerate(episodes)])
        for i, (e, prediction) in enumerate(zip(episodes, predictions), start=1):
            arrays[f"states_{i}"] = e.states
            arrays[f"actions_{i}"] = e.actions
            arrays[f"rewards_{i}"] = e.rewards
            arrays[f"distances_{i}"] = e.distances
            for key, value in prediction.items():
                arrays[f"{key}_{i}"] = value
        if partial is not None and partial.steps > 0:
            X, Y = partial.transitions()
            arrays["partial_X"], arrays["partial_Y"] = X, Y
            arrays["partial_states"] = partial.states
            arrays["partial_actions"] = partial.actions
        write_npz_atomic(self.data_path, arrays)
        self.saved_episodes = len(episodes)

    def save_agent(self, agent) -> bool:
        """``agent.save(agent.npz)``; a failure is logged (the data are already safe)."""
        try:
            agent.save(self.agent_path)
        except Exception as err:  # keep running; data are on disk
            logger.warning("could not save the agent to %s: %s", self.agent_path, err)
            self.agent_current = False
            return False
        self.agent_current = True
        return True

    def save_progress(self, progress: Dict[str, Any], summary: Dict[str, Any]) -> None:
        """Write ``progress.json``, then ``summary.json``."""
        write_json_atomic(self.progress_path, progress)
        write_json_atomic(self.summary_path, summary)

    # -- reading ------------------------------------------------------------------------
    def load_progress(self) -> Dict[str, Any]:
        """The contents of ``progress.json`` (``FileNotFoundError`` when there is none)."""
        with open(self.progress_path, encoding="utf-8") as f:
            return json.load(f)

    def load_summary(self) -> Dict[str, Any]:
        """The contents of ``summary.json`` (``FileNotFoundError`` when there is none)."""
        with open(self.summary_path, encoding="utf-8") as f:
            return json.load(f)

    def load_episodes(self, records: Sequence[Dict[str, Any]]
                      ) -> Tuple[List[Episode], List[Dict[str, np.ndarray]]]:
        """The episodes counted in ``records`` (from ``progress.json``) and their
        predictions, read from ``data.npz``."""
        episodes, predictions = [], []
        if not records:  # progress written before the first episode's data
            return episodes, predictions
        with np.load(self.data_path) as data:
            for i, record in enumerate(records, start=1):
                missing = [k for k in ("states", "actions", "rewards", "distances")
                           if f"{k}_{i}" not in data.files]
                if missing:
                    raise ValueError(f"{self.data_path} lacks episode {i} "
                                     f"({', '.join(missing)}) that progress.json counts")
                episodes.append(Episode(
                    states=data[f"states_{i}"], actions=data[f"actions_{i}"],
                    rewards=data[f"rewards_{i}"], distances=data[f"distances_{i}"],
                    random=bool(record["random"])))
                predictions.append({
                    name: data[k] for k, (name, _, number) in
                    ((k, k.rpartition("_")) for k in data.files)
                    if number == str(i) and name.startswith(PREDICTION_PREFIXES)})
        self.saved_episodes = len(episodes)
        return episodes, predictions

    def load_agent(self):
        """The saved agent (``PILCO.load``), or None when there is none or it is unreadable."""
        if not os.path.exists(self.agent_path):
            return None
        try:
            from ..models import PILCO

            agent = PILCO.load(self.agent_path)
        except Exception as err:  # the caller rebuilds the agent
            logger.warning("could not load the agent from %s (%s); rebuilding it",
                           self.agent_path, err)
            return None
        logger.info("resumed the agent from %s", self.agent_path)
        return agent


def progress_record(exp) -> Dict[str, Any]:
    """What ``progress.json`` holds for :class:`~pilco.experiment.Experiment` ``exp``: it
    counts only the episodes whose data are in ``data.npz`` (after a failed data write,
    the newest episode is not counted)."""
    done = min(len(exp.episodes), exp.store.saved_episodes)
    return {
        "config": dataclasses.asdict(exp.config),
        "settings": exp.settings,
        "episodes_done": done,
        "records": exp.records[:done],
        "seconds": exp.seconds,
        # process CPU time of the model / policy phases per episode number: a check on
        # wall times measured on a busy machine
        "cpu_seconds": exp.cpu_seconds,
        "wall_seconds": exp.wall(),
        "task_state": exp.task_state,
        "summary_fields": exp.summary_fields,
        "interrupted": exp.interrupted,
        "complete": exp.complete,
        # False after a failed agent write: agent.npz (if any) is then older than the data
        "agent_saved": exp.store.agent_current and os.path.exists(exp.store.agent_path),
    }


#: the fields :func:`progress_record` writes (and ``extra``, where older versions kept
#: a task's fields and summary entries): any other field of a saved progress.json is a
#: task's state as versions before ``task_state`` wrote it, read into it on resume
PROGRESS_FIELDS = frozenset(("config", "settings", "episodes_done", "records", "seconds",
                             "cpu_seconds", "wall_seconds", "task_state", "summary_fields",
                             "interrupted", "complete", "agent_saved", "extra"))


def restore_progress(exp, progress: Dict[str, Any]) -> None:
    """Put a run's saved state (``progress.json`` and the episodes it counts in
    ``data.npz``) back into ``exp``; reads files written before the typed fields too."""
    records = list(progress["records"])[: int(progress["episodes_done"])]
    exp.episodes, exp.predictions = exp.store.load_episodes(records)
    exp.records = records
    exp.seconds = {p: float(progress["seconds"].get(p, 0.0)) for p in exp.seconds}
    exp.wall_seconds = float(progress.get("wall_seconds", 0.0))
    exp.cpu_seconds = {int(k): v for k, v in progress.get("cpu_seconds", {}).items()}
    legacy = progress.get("extra", {})
    exp.task_state = dict(progress.get("task_state", {}))
    # older versions kept a task's state in fields of their own, or under "extra"
    older = {k: v for k, v in progress.items() if k not in PROGRESS_FIELDS}
    older.update((k, v) for k, v in legacy.items() if k != "summary")
    for key, value in older.items():
        exp.task_state.setdefault(key, value)
    exp.summary_fields = dict(progress.get("summary_fields", legacy.get("summary", {})))
