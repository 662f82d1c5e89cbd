"""The diagnosis as text: the report ``python -m pilco.diagnose`` prints, from the result
of :func:`pilco.diagnose.diagnose` (the same dict as ``diagnosis.json``)."""
from __future__ import annotations

from typing import Any, Dict, List, Optional

__all__ = ["format_report"]


def _f(value, fmt: str = ".3f") -> str:
    """``value`` formatted with ``fmt``, or "-" when it was not measured (None)."""
    return "-" if value is None else format(value, fmt)


def _range(values) -> str:
    """``min-max`` of ``values`` (3 decimals), or "-" when there are none."""
    return f"{min(values):.3f}-{max(values):.3f}" if len(values) else "-"


def _one_step_lines(one: Dict[str, Any]) -> List[str]:
    """The model's one-step predictions along the real episode."""
    cov_dims = one["coverage_per_dim"]
    k = one["worst_dim"]
    return ["Model, one step along the real episode (errors within ±2 predicted std):",
            f"  all dims {one['coverage']:.0%}"
            + (f", cost dims {one['cost_dims']} {one['coverage_cost_dims']:.0%}"
               if one["cost_dims"] else "")
            + "; per dim " + " ".join(f"{c:.0%}" for c in cov_dims),
            "  rms z per dim " + " ".join(f"{z:.2f}" for z in one["rms_z_per_dim"]),
            f"  worst dim {k}: first outside ±2 std at step "
            f"{one['first_outside_per_dim'][k]}; model wrong one step ahead: "
            f"{'yes' if one['wrong'] else 'no'}"]


def _open_loop_lines(loop: Dict[str, Any]) -> List[str]:
    """The episode's actions on the model's mean (none when it was not measured)."""
    if loop.get("error") is None:
        return []
    return ["", "Model, open loop (the episode's actions on the model's mean from the real "
                "start):",
            f"  off by {loop['error_at_closest']:.3f} at the real closest approach (step "
            f"{loop['closest_step']}; success distance {loop['threshold']:g}), "
            f"{loop['max_error']:.3f} at most; model distance at the end "
            f"{loop['distance'][-1]:.3f}; model wrong there: "
            f"{'yes' if loop['wrong'] else 'no'}"]


def _multi_step_lines(multi: Dict[str, Any], open_d, every: int) -> List[str]:
    """The multi-step prediction against the real episode, a row every ``every`` steps
    (none when it was not measured); ``open_d``: the open-loop distances or None."""
    if "pred_distance_mean" not in multi:
        return []
    lines = ["", "Model, multi-step from the start distribution under the episode's policy:",
             "  (at each row's step; the ranges and the cost sums span the steps since "
             "the row before)",
             f"  {'step':>4} {'pred d':>8} {'± std':>7} {'real d':>8} {'open-loop d':>12} "
             f"{'pred d range':>14} {'real d range':>14} {'pred cost':>10} "
             f"{'real cost':>10}"]
    pm, ps, rd = multi["pred_distance_mean"], multi["pred_distance_std"], multi["real_distance"]
    pc, rc = multi["pred_cost"], multi["real_cost"]
    previous = 0
    for t in sorted(set(range(0, len(pm), every)) | {len(pm) - 1}):
        # a row alone would alias a motion whose period divides ``every`` (a pole
        # spinning through the top every 5 steps reads as held): the block's range shows it
        block = range(previous + 1 if t else 0, t + 1)
        real = t < len(rd)
        real_block = [rd[i] for i in block if i < len(rd)]
        lines.append(f"  {t:>4} {pm[t]:>8.3f} {ps[t]:>7.3f} "
                     f"{_f(rd[t] if real else None):>8} "
                     f"{_f(open_d[t] if real and open_d is not None else None):>12} "
                     f"{_range([pm[i] for i in block]):>14} {_range(real_block):>14} "
                     f"{sum(pc[i] for i in block):>10.3f} "
                     f"{_f(sum(rc[i] for i in block if i < len(rc)) if real else None):>10}")
        previous = t
    lines.append(f"  final distance: predicted {multi['pred_final_distance']:.3f} ± "
                 f"{multi['pred_final_std']:.3f}, real {multi['real_final_distance']:.3f} "
                 f"({'inside' if multi['final_inside'] else 'outside'} ±2 std); closest: "
                 f"predicted {multi['pred_min_distance']:.3f}, real "
                 f"{multi['real_min_distance']:.3f}; predicted to solve: "
                 f"{ {True: 'yes', False: 'no'}.get(multi['pred_solved'], 'not predicted')}")
    lines.append(f"  cost over the episode's steps: predicted {multi['pred_cost_sum']:.2f}, "
                 f"real {multi['real_cost_sum']:.2f} (real - predicted "
                 f"{multi['optimism']:.2f})")
    return lines


def _optimiser_lines(opt: Dict[str, Any]) -> List[str]:
    """The re-optimised candidate policies, a row each, and the best one's gain."""
    lines = ["", f"Optimiser: the policy objective (predicted cost over {opt['horizon']} "
                 f"steps) of the same model, {opt['iterations']} iterations of "
                 f"{opt['method']} per candidate:",
             f"  {'#':>2} {'start':<10}{'seed':>11} {'pred cost':>10} {'pred final':>11} "
             f"{'pred min':>9} {'real final':>11} {'real min':>9} {'solves':>7} {'s':>6}"]
    for i, c in enumerate(opt["candidates"]):
        solves = c.get("real_solved")
        lines.append(f"  {i:>2} {c['start']:<10}{_f(c['seed'], 'd'):>11} {c['pred_cost']:>10.3f} "
                     f"{_f(c.get('pred_final_distance')):>11} {_f(c.get('pred_min_distance')):>9} "
                     f"{_f(c.get('real_final_distance')):>11} {_f(c.get('real_min_distance')):>9} "
                     f"{'-' if solves is None else 'yes' if solves else 'no':>7} "
                     f"{c['seconds']:>6.1f}")
    if opt["gain"] is not None:
        lines.append(f"  best candidate #{opt['best']}: {opt['gain']:.2f} lower than the run's "
                     f"(clearly better from {opt['gain_needed']:.2f})")
    return lines


def _objective_lines(obj: Dict[str, Any], st: Optional[Dict[str, Any]]) -> List[str]:
    """The cost's slope at the start, and the policy from other starts (``st``, when
    measured)."""
    lines: List[str] = []
    if obj["start_widths"] is not None:
        lines += ["", f"Objective: start distance {obj['start_distance']:.3f} = "
                      f"{obj['start_widths']:.2f} cost widths (σ_c {obj['cost_width']:g}); the "
                      f"cost's slope there is {obj['slope_ratio']:.0%} of its maximum (flat "
                      f"below {obj['flat_slope_ratio']:.1%})"]
    if st:
        line = f"  expected return from the start distribution {st['plain_return']:.2f}"
        if st["mixture_return"] is not None:
            gap = st["plain_return"] - st["mixture_return"]
            line += (f", from its mixture (spread {st['spread']:g}) {st['mixture_return']:.2f}: "
                     + ("fragile, the policy fails from the start distribution's flanks"
                        if gap > 1.0 else "not fragile (a gap of 1 step at full cost or less)"))
        lines += ["", "The policy from other starts:", line]
        if st["solved"] is not None:
            lines.append(f"  meets the task's rule from {st['solved']} of {st['starts']} "
                         f"other start states ({st['solved_fraction']:.0%})")
    return lines


def _verdict_lines(v: Dict[str, Any], notes) -> List[str]:
    """The verdict, its caveat and the notes."""
    lines = ["", f"Verdict: {v['label']} (rule {v['rule']}): {v['reason']}"]
    if v.get("caveat"):
        lines.append(f"  caveat: {v['caveat']}")
    return lines + [f"  - {n}" for n in notes]


def format_report(result: Dict[str, Any], every: int = 5) -> str:
    """The diagnosis as text: model, optimiser, objective, verdict and notes, with the
    predicted and real distance every ``every`` steps, their ranges and the cost summed
    over the steps between two rows."""
    loop = result["model"]["open_loop"]
    lines = [f"Diagnosis of episode {result['episode']} of {result['episodes']} "
             f"({result['task']}, seed {result['seed']}): {result['directory']}", ""]
    lines += _one_step_lines(result["model"]["one_step"])
    lines += _open_loop_lines(loop)
    lines += _multi_step_lines(result["model"]["multi_step"], loop.get("distance"), every)
    lines += _optimiser_lines(result["optimiser"])
    lines += _objective_lines(result["objective"], result.get("starts"))
    lines += _verdict_lines(result["verdict"], result["notes"])
    return "\n".join(lines)
