"""Why did a learned episode fail: the model, the optimiser or the objective?

:func:`diagnose` looks at one learned episode K of a run (default the last) with the
dynamics model and the policy exactly as they were when episode K ran (see
:func:`agent_of_episode`) and measures:

Model
    - one step: the predicted state change ``x_{t+1} - x_t`` at every real transition of
      episode K against the real one, standardised per state dimension (``z = (Δ - mean)
      / std``, the noise variance included). *Coverage* is the fraction of ``|z| <= 2``
      (0.95 for a calibrated Gaussian), over all dimensions and over those the cost reads.
    - open loop: the episode's own actions applied to the model's mean from the real
      start; the error is the distance between the model's and the real point the cost
      measures (the gripper), per step.
    - multi-step: the task distance predicted from the start distribution under episode
      K's policy (mean and std per step, from samples of the moment-matched state
      Gaussians) against the real distance trace, and the predicted against the real cost
      per step.
Optimiser
    the policy objective of the same model (the predicted cost summed over the planning
    horizon: what the policy optimiser minimises) of the run's policy, against
    ``restarts`` policy optimisations started from ``controller.randomize`` and one that
    continues from the run's policy, each with the run's settings for episode K
    (iterations, method, early stop). Each candidate policy is also run on the real
    system from episode K's start (unless ``rollouts=False``).
Objective
    the slope of the saturating cost ``1 - exp(-d² / 2σ_c²)`` at the start distance d0,
    relative to its maximum (at d = σ_c): ``(d0/σ_c) exp((1 - d0²/σ_c²) / 2)``.

Verdict rules, in this order (the first that holds decides; thresholds in
:class:`Thresholds`). "Model wrong" means a one-step coverage below 0.90 over all state
dimensions or below 0.70 in some dimension, or an open-loop error above the task's success
distance at the step of the real closest approach (the model cannot tell reaching from
missing there); "clearly better" means a predicted cost lower by at least
``max(1, 0.1 * the run's predicted cost)`` (one step at full cost, or a tenth).

1. ``solved``: episode K meets the task's solved rule; nothing failed.
2. ``objective: cost flat``: d0 > 3 σ_c, i.e. the cost's slope at the start is below
   3 e^-4 = 5.5 % of its maximum: the optimiser gets almost no gradient. (The slope is
   that of the cost at the start distribution's mean; a wide predicted spread, as in the
   cart-pole's swing-up from 4 σ_c, still gives the expected cost some slope.) Not when
   rule 4's evidence holds: a clearly better candidate of the same objective solves the
   task on the real system, so the flat start did not stop the search from succeeding
   (the cart-pole's failures are of this kind).
3. The run's policy was predicted to solve the task (the mean predicted distance meets the
   task's solved rule: within the success threshold at some step, or for the last
   ``hold_steps`` steps) but the real episode did not: ``model`` if model wrong (it is
   wrong where the system went), else ``objective`` (the model is right about the
   episode's actions, yet the objective, the expected cost of the moment-matched
   closed-loop prediction from the start distribution, favoured a policy that does not
   solve the task).
4. ``optimiser``, confirmed: the candidates ran on the real system and a clearly better
   one solves the task: the same model with a better policy search solves this episode.
5. The model misled the optimiser: the episode's real cost exceeds its predicted cost by
   the clear margin (``max(1, 0.1 * predicted)``) and by more than the best candidate's
   gain, so the model's error about the run's own policy outweighs anything re-optimising
   gains on it: ``model`` if model wrong, else ``objective`` (as in rule 3).
6. ``optimiser``: a clearly better candidate exists. When the candidates ran on the real
   system and none of the clearly better ones solves the task, the verdict carries a
   caveat: the model is optimistic about them too, so a better policy search alone would
   not have solved this episode.
7. Otherwise the model predicts the failure and no clearly better policy was found:
   ``model`` if model wrong or the real final distance lies outside the predicted
   mean ± 2 std at that step, else ``objective: optimum short of the target`` (the model
   is right and the best policy of this objective stops short).

Further evidence goes to ``notes``: whether the best candidate solves the task on the real
system, whether continuing the run's policy (a larger iteration budget) already helps, and
how the run was reconstructed.

The measurements live in :mod:`pilco.experiment.diagnostics`, the reconstruction of the
episode's agent in :mod:`pilco.experiment.reconstruct`, the text report in
:func:`pilco.experiment.report.format_diagnosis`; ``python -m pilco.diagnose RUN_DIR`` is the
command line.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from typing import Any, Dict, List, Optional

import numpy as np

from .diagnostics import (Thresholds, cost_geometry, multi_step_check, objective_check,
                          one_step_check, open_loop_check, optimiser_check, slope_ratio)
from .reconstruct import agent_of_episode

__all__ = ["Thresholds", "diagnose", "verdict", "write_diagnosis", "VERDICTS"]

logger = logging.getLogger(__name__)

#: every verdict label :func:`verdict` can give
VERDICTS = ("solved", "objective: cost flat", "model", "objective", "optimiser",
            "objective: optimum short of the target")


def verdict(facts: Dict[str, Any], thresholds: Thresholds = Thresholds()) -> Dict[str, Any]:
    """Apply the verdict rules of the module docstring to ``facts``:

    - ``solved``: the real episode met the task's solved rule;
    - ``start_widths``: start distance in cost widths (None: unknown cost geometry);
    - ``pred_solved``: the run's policy was predicted to solve the task (None: unknown);
    - ``coverage``, ``worst_dim_coverage``: one-step coverage (fraction of errors within
      ``z`` predicted std) over all state dimensions and in the worst one;
    - ``open_loop_wrong``: the open-loop error at the real closest approach exceeds the
      success distance (None: unknown);
    - ``final_inside``: the real final distance lies within the predicted ``z`` std;
    - ``optimism``, ``episode_pred_cost``: the episode's real cost minus its predicted
      cost, and the predicted cost (over the episode's steps; None: unknown);
    - ``run_cost``, ``gain``: the run's predicted cost and the best candidate's decrease
      of it (None: no candidates);
    - ``better_solves_real``: whether a clearly better candidate solved the task on the
      real system (None: not run).

    Returns ``{"label", "rule", "reason"}`` (and ``caveat`` for rule 6); ``label`` is one
    of :data:`VERDICTS`.
    """
    t = thresholds
    cov, worst = float(facts["coverage"]), float(facts["worst_dim_coverage"])
    one_step_wrong = t.one_step_wrong(cov, worst)
    open_loop_wrong = bool(facts.get("open_loop_wrong"))
    wrong = one_step_wrong or open_loop_wrong
    cov_text = (f"one-step coverage {cov:.0%} overall, {worst:.0%} in the worst dimension "
                f"({'below' if one_step_wrong else 'not below'} {t.coverage:.0%} / "
                f"{t.coverage_dim:.0%})")
    if facts.get("open_loop_wrong") is not None:
        cov_text += ("; the open loop is off by " + ("more" if open_loop_wrong else "less")
                     + " than the success distance at the real closest approach")
    model_or_objective = "model" if wrong else "objective"
    gain, run_cost = facts.get("gain"), facts.get("run_cost")
    better = gain is not None and gain >= t.gain_needed(run_cost)
    gain_text = (f"a re-optimised policy lowers the predicted cost by {gain:.2f} >= "
                 f"{t.gain_needed(run_cost):.2f}" if better else "")
    if facts["solved"]:
        return {"label": "solved", "rule": 1, "reason": "the episode solved the task"}
    widths = facts.get("start_widths")
    confirmed = better and bool(facts.get("better_solves_real"))
    if widths is not None and widths > t.flat_widths and not confirmed:
        return {"label": "objective: cost flat", "rule": 2,
                "reason": f"start distance {widths:.2f} cost widths > {t.flat_widths:g}: the "
                          f"cost's slope there is {slope_ratio(widths):.1%} of its maximum"}
    if facts.get("pred_solved"):
        return {"label": model_or_objective, "rule": 3,
                "reason": "the run's policy was predicted to solve the task but did not; "
                          + cov_text}
    if confirmed:
        return {"label": "optimiser", "rule": 4,
                "reason": gain_text + ", and a clearly better policy solves the task on "
                                      "the real system"}
    optimism = facts.get("optimism")
    if (optimism is not None and optimism >= t.gain_needed(facts["episode_pred_cost"])
            and optimism > (gain or 0.0)):
        return {"label": model_or_objective, "rule": 5,
                "reason": f"the episode cost {optimism:.2f} more than predicted, more than "
                          f"re-optimising gains ({gain or 0.0:.2f}); " + cov_text}
    if better:
        out = {"label": "optimiser", "rule": 6, "reason": gain_text}
        if facts.get("better_solves_real") is False:
            out["caveat"] = ("no clearly better policy solves the task on the real system: "
                             "the model is optimistic about them too")
        return out
    inside = facts.get("final_inside")
    if wrong or inside is False:
        reasons = [cov_text] if wrong else []
        if inside is False:
            reasons.append(f"the real final distance lies outside the predicted ±{t.z:g} std")
        return {"label": "model", "rule": 7,
                "reason": "the model predicts the failure, no clearly better policy was "
                          "found; " + "; ".join(reasons)}
    return {"label": "objective: optimum short of the target", "rule": 7,
            "reason": "the model predicts the failure correctly (" + cov_text + "; the real "
                      "final distance within the prediction) and no clearly better policy "
                      "was found"}


def _notes(model, optimiser, reconstruction, rerun_error) -> List[str]:
    notes = [f"model and policy from {reconstruction['source']} (they reproduce the episode's "
             f"actions to {reconstruction['action_error']:.2g})"]
    if rerun_error is not None:
        notes.append(f"the run's policy rerun on the real system: distances differ from the "
                     f"episode's by up to {rerun_error:.2g}")
    cands = optimiser["candidates"]
    if len(cands) > 1:
        cont = next((c for c in cands if c["start"] == "continued"), None)
        if cont is not None:
            notes.append(f"{optimiser['iterations']} more iterations from the run's policy: "
                         f"predicted cost {cont['pred_cost']:.2f} (run's "
                         f"{optimiser['run_pred_cost']:.2f})")
        best = cands[optimiser["best"]]
        if "real_solved" in best:
            solves = "solves" if best["real_solved"] else "does not solve"
            notes.append(f"the best candidate ({best['start']}, predicted cost "
                         f"{best['pred_cost']:.2f}) {solves} the task on the real system "
                         f"(final distance {best['real_final_distance']:.3f}, closest "
                         f"{best['real_min_distance']:.3f})")
        solving = [i for i, c in enumerate(cands[1:], 1) if c.get("real_solved")]
        if solving:
            notes.append(f"candidates that solve the task on the real system: {solving}")
    one = model["one_step"]
    k = one["worst_dim"]
    notes.append(f"worst one-step dimension: {k} (coverage {one['worst_dim_coverage']:.0%}, "
                 f"rms z {one['rms_z_per_dim'][k]:.2f}, first outside ±2 std at step "
                 f"{one['first_outside_per_dim'][k]})")
    for i, n in enumerate(one["still_but_predicted_moving_per_dim"]):
        if n:
            notes.append(f"dimension {i} did not move on {n} steps where the model predicts it "
                         f"moves (a limit or a saturation the model does not know)")
    loop = model["open_loop"]
    if loop.get("error") is not None:
        notes.append(f"open loop (the episode's actions on the model's mean): off by "
                     f"{loop['error_at_closest']:.3f} at the real closest approach (step "
                     f"{loop['closest_step']}), {loop['max_error']:.3f} at most; above the "
                     f"success distance from step {loop['first_step_above_threshold']}")
    multi = model["multi_step"]
    if multi.get("optimism") is not None:
        notes.append(f"the episode's real cost exceeds its predicted cost by "
                     f"{multi['optimism']:.2f} (predicted {multi['pred_cost_sum']:.2f})")
    if multi.get("coverage") is not None:
        notes.append(f"the real distance lies within the predicted ±2 std on "
                     f"{multi['coverage']:.0%} of the steps")
    return notes


def diagnose(exp, episode: Optional[int] = None, restarts: int = 3, seed: int = 0,
             rollouts: bool = True, replay: bool = False,
             thresholds: Thresholds = Thresholds()) -> Dict[str, Any]:
    """Diagnose learned episode ``episode`` (1-based, default the last) of the run ``exp``
    (an :class:`~pilco.experiment.Experiment` resumed from its directory): model,
    optimiser and objective checks and the verdict (module docstring). ``restarts``:
    policy optimisations from random policies; ``rollouts``: run every candidate policy
    on the real system; ``replay``: rebuild the agent by replaying the run's learning even
    for the last episode. Returns a JSON-ready dict (NumPy arrays as arrays)."""
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
        except Exception as err:  # noqa: BLE001 - the rollouts are optional evidence
            logger.warning("the run's environment cannot be made (%s): the candidate "
                           "policies are not run on the real system", err)
    optimiser = optimiser_check(view, number, geometry, restarts, seed, env, thresholds)
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
             "run_cost": optimiser["run_pred_cost"], "gain": optimiser["gain"],
             "better_solves_real": optimiser["better_solves_real"]}
    result = {
        "directory": exp.directory, "task": exp.config.task, "seed": int(exp.config.seed),
        "episode": number, "episodes": len(exp.episodes),
        "success_threshold": exp.config.success_threshold,
        "reconstruction": {**reconstruction, "rerun_distance_error": rerun_error},
        "model": model, "optimiser": optimiser, "objective": objective,
        "facts": facts, "verdict": verdict(facts, thresholds),
        "notes": _notes(model, optimiser, reconstruction, rerun_error),
        "thresholds": dataclasses.asdict(thresholds),
        "seconds": time.perf_counter() - t_start,
    }
    logger.info("episode %d of %s: verdict %s (rule %d: %s)", number, exp.directory,
                result["verdict"]["label"], result["verdict"]["rule"],
                result["verdict"]["reason"])
    return result


def write_diagnosis(result: Dict[str, Any], path: str) -> str:
    """Write :func:`diagnose`'s result as JSON (atomically); returns the path."""
    from ..files import write_json_atomic

    return write_json_atomic(path, result)
