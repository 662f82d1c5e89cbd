"""The verdict rules: did a learned episode fail because of the model, the optimiser or
the objective?

:func:`verdict` applies the rules below to the facts that :func:`pilco.diagnose.diagnose`
gathers about learned episode K from the checks (:mod:`pilco.diagnose.checks`);
:func:`notes` words the further evidence.

Verdict rules, in this order (the first that holds decides; thresholds in
:class:`~pilco.diagnose.thresholds.Thresholds`). "Model wrong" means a one-step coverage
below 0.90 over all state dimensions or below 0.70 in some dimension, or an open-loop error
above the task's success distance at the step of the real closest approach (the model
cannot tell reaching from missing there); "clearly better" means a predicted cost lower by
at least ``max(1, 0.1 * the run's predicted cost)`` (one step at full cost, or a tenth).

1. ``solved``: episode K meets the task's solved rule; nothing failed.
2. ``objective: cost flat``: d0 > 3 σ_c, i.e. the cost's slope at the start is below
   3 e^-4 = 5.5 % of its maximum: the optimiser gets almost no gradient. (The slope is
   that of the cost at the start distribution's mean; a wide predicted spread, as in the
   cart-pole's swing-up from 4 σ_c, still gives the expected cost some slope.) Only when
   the search stayed on the plateau: the run's predicted cost is at least ``plateau``
   (0.9) of the horizon's largest cost; a policy predicted well below it has left the
   flat start behind (the cart-pole starts 4 σ_c away in every episode, and its learned
   episodes are predicted far below the plateau). Not when rule 4's evidence holds: a
   clearly better candidate of the same objective solves the task on the real system, so
   the flat start did not stop the search from succeeding.
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

Further evidence goes to ``notes`` (:func:`notes`): whether the best candidate solves the
task on the real system, whether continuing the run's policy (a larger iteration budget)
already helps, and how the run was reconstructed.
"""
from __future__ import annotations

from typing import Any, Dict, List, Tuple

from .geometry import slope_ratio
from .thresholds import Thresholds

__all__ = ["VERDICTS", "verdict", "notes"]

#: every verdict label :func:`verdict` can give
VERDICTS = ("solved", "objective: cost flat", "model", "objective", "optimiser",
            "objective: optimum short of the target")


def _model_coverage(facts: Dict[str, Any], t: Thresholds) -> Tuple[bool, str]:
    """Whether the model's predictions were wrong (its one-step coverage below the
    thresholds, or the open loop off by more than the success distance at the real closest
    approach), and the sentence that says so."""
    cov, worst = float(facts["coverage"]), float(facts["worst_dim_coverage"])
    one_step_wrong = t.one_step_wrong(cov, worst)
    open_loop_wrong = bool(facts.get("open_loop_wrong"))
    text = (f"one-step coverage {cov:.0%} overall, {worst:.0%} in the worst dimension "
            f"({'below' if one_step_wrong else 'not below'} {t.coverage:.0%} / "
            f"{t.coverage_dim:.0%})")
    if facts.get("open_loop_wrong") is not None:
        text += ("; the open loop is off by " + ("more" if open_loop_wrong else "less")
                 + " than the success distance at the real closest approach")
    return one_step_wrong or open_loop_wrong, text


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
    - ``max_cost``: the largest predicted cost over the horizon (None: unknown; rule 2
      then does not ask whether the search stayed on the plateau);
    - ``better_solves_real``: whether a clearly better candidate solved the task on the
      real system (None: not run).

    Returns ``{"label", "rule", "reason"}`` (and ``caveat`` for rule 6); ``label`` is one
    of :data:`VERDICTS`.
    """
    t = thresholds
    wrong, cov_text = _model_coverage(facts, t)
    model_or_objective = "model" if wrong else "objective"
    gain, run_cost = facts.get("gain"), facts.get("run_cost")
    better = gain is not None and gain >= t.gain_needed(run_cost)
    gain_text = (f"a re-optimised policy lowers the predicted cost by {gain:.2f} >= "
                 f"{t.gain_needed(run_cost):.2f}" if better else "")
    if facts["solved"]:
        return {"label": "solved", "rule": 1, "reason": "the episode solved the task"}
    widths = facts.get("start_widths")
    confirmed = better and bool(facts.get("better_solves_real"))
    max_cost = facts.get("max_cost")
    on_plateau = (max_cost is None or run_cost is None
                  or run_cost >= t.plateau * float(max_cost))
    if widths is not None and widths > t.flat_widths and on_plateau and not confirmed:
        stayed = (f"; the run's policy is predicted at cost {run_cost:.2f} of at most "
                  f"{float(max_cost):.2f}" if max_cost is not None and run_cost is not None
                  else "")
        return {"label": "objective: cost flat", "rule": 2,
                "reason": f"start distance {widths:.2f} cost widths > {t.flat_widths:g}: the "
                          f"cost's slope there is {slope_ratio(widths):.1%} of its maximum"
                          + stayed}
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


def notes(model, optimiser, reconstruction, rerun_error) -> List[str]:
    """The further evidence, one sentence each, from the checks' results (``model``,
    ``optimiser``: :mod:`pilco.diagnose.checks`), the reconstruction's ``info``
    (:func:`~pilco.diagnose.replay.agent_of_episode`) and the largest distance error of
    the run's policy rerun on the real system (None: not rerun)."""
    lines = [f"model and policy from {reconstruction['source']} (they reproduce the episode's "
             f"actions to {reconstruction['action_error']:.2g})"]
    if rerun_error is not None:
        lines.append(f"the run's policy rerun on the real system: distances differ from the "
                     f"episode's by up to {rerun_error:.2g}")
    cands = optimiser["candidates"]
    if len(cands) > 1:
        cont = next((c for c in cands if c["start"] == "continued"), None)
        if cont is not None:
            lines.append(f"{optimiser['iterations']} more iterations from the run's policy: "
                         f"predicted cost {cont['pred_cost']:.2f} (run's "
                         f"{optimiser['run_pred_cost']:.2f})")
        best = cands[optimiser["best"]]
        if "real_solved" in best:
            solves = "solves" if best["real_solved"] else "does not solve"
            lines.append(f"the best candidate ({best['start']}, predicted cost "
                         f"{best['pred_cost']:.2f}) {solves} the task on the real system "
                         f"(final distance {best['real_final_distance']:.3f}, closest "
                         f"{best['real_min_distance']:.3f})")
        solving = [i for i, c in enumerate(cands[1:], 1) if c.get("real_solved")]
        if solving:
            lines.append(f"candidates that solve the task on the real system: {solving}")
    one = model["one_step"]
    k = one["worst_dim"]
    lines.append(f"worst one-step dimension: {k} (coverage {one['worst_dim_coverage']:.0%}, "
                 f"rms z {one['rms_z_per_dim'][k]:.2f}, first outside ±2 std at step "
                 f"{one['first_outside_per_dim'][k]})")
    for i, n in enumerate(one["still_but_predicted_moving_per_dim"]):
        if n:
            lines.append(f"dimension {i} did not move on {n} steps where the model predicts it "
                         f"moves (a limit or a saturation the model does not know)")
    loop = model["open_loop"]
    if loop.get("error") is not None:
        lines.append(f"open loop (the episode's actions on the model's mean): off by "
                     f"{loop['error_at_closest']:.3f} at the real closest approach (step "
                     f"{loop['closest_step']}), {loop['max_error']:.3f} at most; above the "
                     f"success distance from step {loop['first_step_above_threshold']}")
    multi = model["multi_step"]
    if multi.get("optimism") is not None:
        lines.append(f"the episode's real cost exceeds its predicted cost by "
                     f"{multi['optimism']:.2f} (predicted {multi['pred_cost_sum']:.2f})")
    if multi.get("coverage") is not None:
        lines.append(f"the real distance lies within the predicted ±2 std on "
                     f"{multi['coverage']:.0%} of the steps")
    return lines
