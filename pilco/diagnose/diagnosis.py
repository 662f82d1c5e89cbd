"""Diagnose one learned episode of a run: rebuild its agent, run every check, give the
verdict, and write the result as JSON.

:func:`diagnose` puts the pieces together: the agent as it was when the episode ran
(:mod:`pilco.diagnose.replay`), the measurements (:mod:`pilco.diagnose.checks`), the facts
the verdict rules read and the verdict with its notes (:mod:`pilco.diagnose.rules`). Its
result is what ``python -m pilco.diagnose`` writes to ``diagnosis.json``
(:func:`write_diagnosis`) and prints (:func:`pilco.diagnose.report.format_report`).
"""
from __future__ import annotations

import dataclasses
import logging
import time
from typing import Any, Dict, Optional

import numpy as np

from ..files import write_json_atomic
from .checks import (episode_task, multi_step_check, objective_check, one_step_check,
                     open_loop_check, optimiser_check, start_check)
from .geometry import cost_geometry
from .replay import agent_of_episode
from .thresholds import Thresholds
from .rules import notes, verdict

__all__ = ["diagnose", "write_diagnosis"]

logger = logging.getLogger(__name__)


def diagnose(exp, episode: Optional[int] = None, restarts: int = 3, seed: int = 0,
             rollouts: bool = True, replay: bool = False,
             thresholds: Thresholds = Thresholds(), starts: int = 20) -> Dict[str, Any]:
    """Diagnose learned episode ``episode`` (1-based, default the last) of the run ``exp``
    (an :class:`~pilco.experiment.Experiment` resumed from its directory): model,
    optimiser and objective checks (:mod:`pilco.diagnose.checks`) and the verdict
    (:mod:`pilco.diagnose.rules`). ``restarts``: policy optimisations from random
    policies; ``rollouts``: run every candidate policy on the real system; ``replay``:
    rebuild the agent by replaying the run's learning even for the last episode;
    ``starts``: run the episode's policy from that many other start states
    (:func:`~pilco.diagnose.checks.start_check`, under ``"starts"``; 0: none). Returns a
    JSON-ready dict (NumPy arrays as arrays)."""
    t_start = time.perf_counter()
    number = len(exp.episodes) if episode is None else int(episode)
    view, reconstruction = agent_of_episode(exp, number, replay=replay)
    agent, ep = view.agent, exp.episodes[number - 1]
    geometry = cost_geometry(agent.reward)
    if geometry is None:
        logger.warning("%s has no known distance: distance and cost checks are skipped",
                       type(agent.reward).__name__)
    logger.info("episode %d: model checks", number)
    model = {"one_step": one_step_check(agent, ep, geometry, thresholds),
             "open_loop": open_loop_check(agent, ep, geometry, exp.config.success_threshold),
             "multi_step": multi_step_check(view, agent, ep, geometry, thresholds)}
    objective = objective_check(agent, ep, geometry, thresholds)
    env = None
    if rollouts:
        try:
            env = view.make_env()
            # the env contract, before any rollout: a run reopened from its saved agent
            # makes its env from the config's id, without the task's wrapper
            view.hooks.distance(env, env.reset()[1])
        except Exception as err:  # the rollouts are optional evidence
            env = None
            logger.warning("the run's environment cannot be made or reports no distance "
                           "(%s): the candidate policies are not run on the real system",
                           err)
    logger.info("episode %d: the policy from %d other starts", number, starts if env else 0)
    start = start_check(view, number, env, starts)
    optimiser = optimiser_check(view, number, geometry, restarts, seed, env, thresholds,
                                episode_task(agent, ep))
    rerun_error = None
    if env is not None:
        rerun = np.asarray(optimiser["candidates"][0]["real_distance"])
        n = min(len(rerun), len(ep.distances))
        rerun_error = float(np.max(np.abs(rerun[:n] - ep.distances[:n])))
        if len(rerun) != len(ep.distances):
            logger.warning("the run's policy rerun on the real system took %d steps, the "
                           "episode %d", len(rerun) - 1, ep.steps)
    multi = model["multi_step"]
    one = model["one_step"]
    facts = {"solved": view.episode_solved(ep), "start_widths": objective["start_widths"],
             "pred_solved": multi.get("pred_solved"), "coverage": one["coverage"],
             "worst_dim_coverage": one["worst_dim_coverage"],
             "open_loop_wrong": model["open_loop"]["wrong"],
             "final_inside": multi.get("final_inside"), "optimism": multi.get("optimism"),
             "episode_pred_cost": multi.get("pred_cost_sum"),
             "run_cost": optimiser["run_pred_cost"], "max_cost": optimiser["max_cost"],
             "gain": optimiser["gain"],
             "better_solves_real": optimiser["better_solves_real"]}
    result = {
        "directory": exp.directory, "task": exp.config.task, "seed": int(exp.config.seed),
        "episode": number, "episodes": len(exp.episodes),
        "success_threshold": exp.config.success_threshold,
        "reconstruction": {**reconstruction, "rerun_distance_error": rerun_error},
        "model": model, "optimiser": optimiser, "objective": objective, "starts": start,
        "facts": facts, "verdict": verdict(facts, thresholds),
        "notes": notes(model, optimiser, reconstruction, rerun_error),
        "thresholds": dataclasses.asdict(thresholds),
        "seconds": time.perf_counter() - t_start,
    }
    logger.info("episode %d of %s: verdict %s (rule %d: %s)", number, exp.directory,
                result["verdict"]["label"], result["verdict"]["rule"],
                result["verdict"]["reason"])
    return result


def write_diagnosis(result: Dict[str, Any], path: str) -> str:
    """Write :func:`diagnose`'s result as JSON (atomically); returns the path."""
    return write_json_atomic(path, result)
