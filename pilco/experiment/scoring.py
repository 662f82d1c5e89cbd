"""How an episode is scored: the saturating cost of the task distance, the solved
rule, and the per-episode record written to ``summary.json``."""
from __future__ import annotations

from typing import Any, Callable, Dict, List

import numpy as np

from .config import ExperimentConfig
from .episode import Episode
from .provenance import provenance

__all__ = ["PHASES", "saturating_cost", "episode_costs", "distances_solved", "episode_solved",
           "solved_episodes", "held_for_good", "held_for_good_rule",
           "solved_in_last_episode", "episode_record", "summarise"]

#: the timed phases of a learned episode, as in the paper's timing table
PHASES = ("interaction", "model", "policy")


def saturating_cost(distance, width: float) -> np.ndarray:
    """PILCO's saturating cost ``1 - exp(-d^2 / (2 width^2))`` of distances ``[...]``."""
    d = np.asarray(distance, dtype=np.float64)
    return 1.0 - np.exp(-(d ** 2) / (2.0 * float(width) ** 2))


def episode_costs(episode: Episode, config: ExperimentConfig) -> np.ndarray:
    """The summary's cost of each state of ``episode``: the saturating cost of its task
    distance with the run's ``cost_width``, ``[T+1]`` (the record's ``cost`` sums steps
    1..T)."""
    return saturating_cost(episode.distances, config.cost_width)


def episode_solved(episode: Episode, config: ExperimentConfig) -> bool:
    """Whether an episode meets the task's rule (:func:`distances_solved`)."""
    return distances_solved(episode.distances, config)


def distances_solved(distances, config: ExperimentConfig) -> bool:
    """The task's rule on an episode's distances ``[T+1]`` (the start state is not
    counted): ``"reach"``, any state within ``success_threshold``; ``"hold"``, the last
    ``hold_steps`` states all within it; ``"survive"``, the episode lasted ``hold_steps``
    steps (an environment that terminates when it fails, e.g. a pole that falls)."""
    d = np.asarray(distances, dtype=np.float64)[1:]
    if len(d) == 0 or not np.all(np.isfinite(d)):
        return False
    thr = config.success_threshold
    if config.solved_rule == "survive":
        return bool(len(d) >= config.hold_steps)
    if config.solved_rule == "reach":
        return bool(np.any(d < thr))
    k = config.hold_steps
    return bool(len(d) >= k and np.all(d[-k:] < thr))


def solved_episodes(records, distances, config: ExperimentConfig) -> List[int]:
    """Numbers (1-based) of the learned episodes that meet the task's rule, given the
    summary's episode ``records`` and their ``distances``."""
    return [int(r["episode"]) for r, d in zip(records, distances)
            if not r["random"] and distances_solved(d, config)]


def held_for_good(records, distances, config: ExperimentConfig) -> bool:
    """Whether the task was solved in a learned episode and in every learned episode
    after it, to the run's last: a controller that, once it works, keeps working."""
    return _held_from_first(records, solved_episodes(records, distances, config))


def _held_from_first(records, solved: List[int]) -> bool:
    """:func:`held_for_good` given the run's ``solved`` learned episodes."""
    learned = [int(r["episode"]) for r in records if not r["random"]]
    return bool(solved) and solved == [e for e in learned if e >= solved[0]]


def held_for_good_rule(config: ExperimentConfig) -> Callable[[Dict[str, Any]], bool]:
    """``summary -> bool``: :func:`held_for_good` of the run (a success rule)."""

    def success(summary: Dict[str, Any]) -> bool:
        return held_for_good(summary["episodes"], summary["distances"], config)

    return success


def solved_in_last_episode(config: ExperimentConfig) -> Callable[[Dict[str, Any]], bool]:
    """``summary -> bool``: the run's last episode is a learned one that meets the
    solved rule (a success rule: the task is still solved at the end of the run)."""

    def success(summary: Dict[str, Any]) -> bool:
        episodes, distances = summary["episodes"], summary["distances"]
        return bool(episodes and not episodes[-1]["random"]
                    and distances_solved(distances[-1], config))

    return success


def episode_record(episode: Episode, number: int, seconds: Dict[str, float],
                   config: ExperimentConfig) -> Dict[str, Any]:
    """The summary's record of episode ``number`` (1-based): steps, saturating cost of
    the distances after the start, final and closest distance, first step within the
    threshold (or None), seconds per phase."""
    d = episode.distances
    within = np.nonzero(d[1:] < config.success_threshold)[0]
    cost = float(np.sum(episode_costs(episode, config)[1:]))
    return {
        "episode": int(number),
        "random": bool(episode.random),
        "steps": int(episode.steps),
        "cost": cost,
        "final_distance": float(d[-1]),
        "min_distance": float(np.min(d[1:])) if episode.steps else float(d[0]),
        "steps_to_target": int(within[0] + 1) if len(within) else None,
        "seconds": {p: float(seconds.get(p, 0.0)) for p in PHASES},
    }


def summarise(exp) -> Dict[str, Any]:
    """The summary (``summary.json``) of :class:`~pilco.experiment.Experiment` ``exp``:
    task, seed, ``solved``, ``solved_at_episode``, ``solved_episodes`` (the learned
    episodes that met the rule), ``held_for_good`` (:func:`held_for_good`), the episode
    records, ``seconds`` per phase and ``total`` wall time (all sessions; figures excluded),
    the task's ``summary_fields``, ``complete`` (the loop finished), ``distances`` per
    episode and ``success`` (the task's rule, default ``solved``) and ``provenance`` (code
    version, library versions, CPU, TensorFlow's arithmetic settings: :mod:`.provenance`)."""
    at = exp.solved_at_episode()
    summary = {
        "task": exp.config.task,
        "seed": int(exp.config.seed),
        "solved": at is not None,
        "solved_at_episode": at,
        "episodes": exp.records,
        "seconds": {**{p: float(exp.seconds[p]) for p in PHASES}, "total": float(exp.wall())},
        **exp.summary_fields,
        "complete": bool(exp.complete),
        "distances": [[float(v) for v in e.distances] for e in exp.episodes],
        "provenance": provenance(),
    }
    solved = solved_episodes(exp.records, summary["distances"], exp.config)
    summary["solved_episodes"] = solved
    summary["held_for_good"] = _held_from_first(exp.records, solved)
    summary["success"] = bool(exp.hooks.success(summary))
    return summary
