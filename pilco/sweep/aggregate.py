"""Statistics of a sweep: success rates with Wilson intervals, quartiles, the table.

Everything here works on run summaries (the parsed ``summary.json`` of each run) and
imports only the standard library, so the numbers can be recomputed from the
run directories without Ray or TensorFlow.

Conventions:

* a run *succeeded* when its summary says ``success`` (the task's own rule); summaries
  written before that field existed fall back to ``solved``;
* the success rate is over the runs that finished; runs whose process failed are
  counted apart (``failed``) and not in the rate;
* "episodes to solve" is the summary's ``solved_at_episode``; a run that never solved
  counts as solving after infinitely many episodes, so a quantile is ``None`` when more
  than that fraction of the runs did not solve.
"""
from __future__ import annotations

import bisect
import math
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence

__all__ = ["WILSON_Z95", "wilson_interval", "quantile", "quartiles", "run_success",
           "solved_in_episode", "RISK_BINS", "RISK_RULES", "risk_calibration",
           "aggregate_setting", "provenance_counts", "solved_by_episode", "format_table"]

#: the standard normal's 97.5 % quantile: a two-sided 95 % interval
WILSON_Z95 = 1.959963984540054


def wilson_interval(successes: int, runs: int, z: float = WILSON_Z95) -> tuple:
    """Wilson score interval ``(low, high)`` of a success probability.

    ``successes`` of ``runs`` Bernoulli trials; ``z`` the normal quantile (95 %:
    1.96). Unlike the normal approximation it stays inside [0, 1] and is not empty at
    0 or ``runs`` successes. ``(nan, nan)`` for ``runs == 0``.
    """
    if isinstance(successes, bool) or isinstance(runs, bool):
        raise TypeError("successes and runs must be integers, not booleans")
    successes, runs = int(successes), int(runs)
    if runs < 0 or successes < 0 or successes > runs:
        raise ValueError(f"need 0 <= successes <= runs, got {successes} of {runs}")
    if not z > 0:
        raise ValueError(f"z must be positive, got {z}")
    if runs == 0:
        return (math.nan, math.nan)
    p = successes / runs
    z2 = z * z
    centre = (p + z2 / (2 * runs)) / (1 + z2 / runs)
    half = z / (1 + z2 / runs) * math.sqrt(p * (1 - p) / runs + z2 / (4 * runs * runs))
    # at 0 or runs successes the bound is exactly 0 or 1; rounding must not move it
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == runs else min(1.0, centre + half)
    return (low, high)


def quantile(values: Iterable[float], q: float) -> Optional[float]:
    """The ``q`` quantile (0 <= q <= 1) of ``values`` by linear interpolation between
    order statistics (NumPy's default rule). ``inf`` values are allowed (runs that never
    solved): the result is ``inf`` as soon as an ``inf`` has a non-zero weight in it.
    ``None`` for no values."""
    if not 0.0 <= q <= 1.0:
        raise ValueError(f"quantile q must be in [0, 1], got {q}")
    xs = sorted(float(v) for v in values)
    if any(math.isnan(v) for v in xs):
        raise ValueError("quantile of values containing NaN")
    if not xs:
        return None
    position = q * (len(xs) - 1)
    below = int(math.floor(position))
    weight = position - below
    if weight == 0.0:
        return xs[below]
    lo, hi = xs[below], xs[below + 1]
    if math.isinf(hi) or math.isinf(lo):
        return hi if math.isinf(hi) else lo
    return lo + weight * (hi - lo)


def quartiles(values: Iterable[float]) -> Dict[str, Optional[float]]:
    """``{"q1", "median", "q3"}`` of ``values`` (``None`` for no values; an infinite
    quartile becomes ``None`` as well, JSON has no infinity)."""
    xs = list(values)

    def finite(v):
        return None if v is None or math.isinf(v) else v

    return {"q1": finite(quantile(xs, 0.25)), "median": finite(quantile(xs, 0.5)),
            "q3": finite(quantile(xs, 0.75))}


def run_success(summary: Mapping[str, Any]) -> bool:
    """The task's success verdict: ``summary["success"]`` when present, else
    ``summary["solved"]``."""
    if "success" in summary and summary["success"] is not None:
        return bool(summary["success"])
    if "solved" not in summary:
        raise ValueError("run summary has neither 'success' nor 'solved'")
    return bool(summary["solved"])


def _last_episode(summary: Mapping[str, Any]) -> Optional[Mapping[str, Any]]:
    episodes = summary.get("episodes") or []
    return episodes[-1] if episodes else None


def solved_by_episode(summaries: Sequence[Mapping[str, Any]], episodes: int) -> List[float]:
    """Fraction of ``summaries`` solved by episode k for k = 1..``episodes``: a list of
    length ``episodes`` (empty summaries: all NaN)."""
    n = len(summaries)
    at = [s.get("solved_at_episode") for s in summaries]
    return [(sum(1 for a in at if a is not None and a <= k) / n) if n else math.nan
            for k in range(1, episodes + 1)]


def solved_in_episode(summaries: Sequence[Mapping[str, Any]], episodes: int
                      ) -> Optional[List[float]]:
    """Fraction of ``summaries`` whose episode k met the task's rule (its
    ``solved_episodes``) for k = 1..``episodes``: unlike :func:`solved_by_episode` it falls
    when runs lose what they had learned. None when a summary does not say."""
    if not summaries or any("solved_episodes" not in s for s in summaries):
        return None
    n = len(summaries)
    return [sum(1 for s in summaries if k in s["solved_episodes"]) / n
            for k in range(1, episodes + 1)]


#: the edges of the predicted-risk bins of :func:`risk_calibration`: fine near 0, where a
#: threshold lies, and near 1
RISK_BINS = (0.0, 0.01, 0.05, 0.1, 0.2, 0.5, 0.8, 0.95, 1.0)

#: the combination rules an episode's ``predicted_risk`` records (``pilco.constraints.COMBINE``;
#: named here, where only the standard library is imported)
RISK_RULES = ("independent", "union")


def risk_calibration(summaries: Sequence[Mapping[str, Any]], rule: str = "independent",
                     edges: Sequence[float] = RISK_BINS) -> List[Dict[str, Any]]:
    """The predicted risk of the learned episodes whose policy ran against how often they
    really broke the constraint: the episodes' records with ``predicted_risk[rule]`` and
    ``violated`` (runs on a constraint, :mod:`pilco.experiment.safety`), binned by that
    risk (bin ``[low, high)``, the last one closed). One entry per non-empty bin:
    ``low``, ``high``, ``episodes``, ``violated``, ``rate`` (violated / episodes),
    ``ci95`` (Wilson) and ``mean_risk`` (the bin's mean predicted risk). A calibrated
    prediction has ``rate`` near ``mean_risk``; a conservative one below it."""
    edges = [float(e) for e in edges]
    if len(edges) < 2 or any(b <= a for a, b in zip(edges, edges[1:])):
        raise ValueError(f"edges must be at least two increasing numbers, got {edges}")
    bins: List[List[tuple]] = [[] for _ in edges[1:]]
    for summary in summaries:
        for record in summary.get("episodes") or ():
            risk = (record.get("predicted_risk") or {}).get(rule)
            if (record.get("random") or risk is None or "violated" not in record
                    or not record.get("safety", {}).get("executed", True)):
                continue
            if not edges[0] <= risk <= edges[-1]:
                continue
            k = min(bisect.bisect_right(edges, risk) - 1, len(bins) - 1)  # the last closed
            bins[k].append((float(risk), bool(record["violated"])))
    out = []
    for (low, high), members in zip(zip(edges, edges[1:]), bins):
        if not members:
            continue
        violated = sum(v for _, v in members)
        out.append({"low": low, "high": high, "episodes": len(members), "violated": violated,
                    "rate": violated / len(members),
                    "ci95": list(wilson_interval(violated, len(members))),
                    "mean_risk": sum(r for r, _ in members) / len(members)})
    return out


def aggregate_setting(summaries: Sequence[Mapping[str, Any]], *, runs: Optional[int] = None,
                      failed: int = 0, not_run: int = 0) -> Dict[str, Any]:
    """The aggregate of one setting from its finished runs' ``summaries``.

    ``runs`` is the number of seeds asked for (default: ``len(summaries) + failed +
    not_run``); ``failed`` runs whose process failed; ``not_run`` runs left out by an
    interrupt. Returns a JSON-ready dict:

    ``runs``, ``finished``, ``failed``, ``not_run``, ``successes``, ``success_rate``
    (over finished runs; ``None`` without any), ``success_ci95`` ``[low, high]``
    (Wilson), ``episodes_to_solve`` ``{q1, median, q3, solved, unsolved}``,
    ``last_episode`` ``{steps_to_target: {median, reached, not_reached}, final_distance:
    {q1, median, q3}, min_distance: {q1, median, q3}}``, ``seconds_per_run`` ``{median,
    max}``, ``provenance`` (:func:`provenance_counts`), ``held_for_good`` (how many runs,
    when the summaries say it: solved and solved again in every later learned episode),
    ``episodes_to_recover`` like
    ``episodes_to_solve`` when the summaries have it (a task whose runs recover from a
    change, such as damage, report it), and ``safety`` when they have it (Safe PILCO's
    runs, :mod:`pilco.experiment.safety`): the learned episodes, those whose policy ran
    (``executed``), the executed ones that broke the constraint, the random ones that did,
    and the quartiles and maximum of the executed ones' predicted risks; with the records'
    ``predicted_risk``, their ``calibration`` per rule (:func:`risk_calibration`).
    """
    finished = len(summaries)
    if runs is None:
        runs = finished + failed + not_run
    successes = sum(run_success(s) for s in summaries)
    low, high = wilson_interval(successes, finished)
    solve = [math.inf if s.get("solved_at_episode") is None else float(s["solved_at_episode"])
             for s in summaries]
    last = [e for e in (_last_episode(s) for s in summaries) if e is not None]
    reached = [float(e["steps_to_target"]) for e in last if e.get("steps_to_target") is not None]
    seconds = [float(s["seconds"]["total"]) for s in summaries
               if isinstance(s.get("seconds"), Mapping) and "total" in s["seconds"]]
    result: Dict[str, Any] = {
        "runs": int(runs),
        "finished": finished,
        "failed": int(failed),
        "not_run": int(not_run),
        "successes": int(successes),
        "success_rate": successes / finished if finished else None,
        "success_ci95": [low, high] if finished else None,
        "episodes_to_solve": {**quartiles(solve),
                              "solved": sum(1 for v in solve if not math.isinf(v)),
                              "unsolved": sum(1 for v in solve if math.isinf(v))},
        "last_episode": {
            "steps_to_target": {"median": quantile(reached, 0.5), "reached": len(reached),
                                "not_reached": len(last) - len(reached)},
            "final_distance": quartiles(float(e["final_distance"]) for e in last),
            "min_distance": quartiles(float(e["min_distance"]) for e in last),
        },
        "seconds_per_run": {"median": quantile(seconds, 0.5),
                            "max": max(seconds) if seconds else None},
        "provenance": provenance_counts(summaries),
    }
    if any("held_for_good" in s for s in summaries):
        result["held_for_good"] = sum(1 for s in summaries if s.get("held_for_good"))
    counts = [s["safety"] for s in summaries if isinstance(s.get("safety"), Mapping)]
    if counts:
        risks = [float(r) for c in counts for r in c.get("executed_risks", ())]
        result["safety"] = {
            **{key: sum(int(c.get(key, 0)) for c in counts)
               for key in ("learned", "executed", "executed_violated", "random_violated")},
            "executed_risk": {**quartiles(risks), "max": max(risks) if risks else None}}
        calibration = {rule: risk_calibration(summaries, rule) for rule in RISK_RULES}
        if any(calibration.values()):
            result["safety"]["calibration"] = calibration
    if any("episodes_to_recover" in s for s in summaries):
        recover = [math.inf if s.get("episodes_to_recover") is None
                   else float(s["episodes_to_recover"]) for s in summaries]
        result["episodes_to_recover"] = {
            **quartiles(recover), "recovered": sum(1 for v in recover if not math.isinf(v)),
            "not_recovered": sum(1 for v in recover if math.isinf(v))}
    return result


def provenance_counts(summaries: Sequence[Mapping[str, Any]]) -> Dict[str, Dict[str, int]]:
    """How many runs ran which code and arithmetic: ``{"commit": {sha[:12] (+ "-dirty"):
    runs}, "cpu": {model: runs}, "onednn": {TF_ENABLE_ONEDNN_OPTS or "default": runs},
    "arithmetic": {"portable" or "cpu's own": runs}}`` from the summaries' ``provenance``
    ("unknown" for summaries without it). ``arithmetic`` (:mod:`pilco.portable`) only
    when some run recorded it (runs before it was recorded count as "unknown"), so that
    the counts of older sweeps stay as they were."""
    counts: Dict[str, Dict[str, int]] = {"commit": {}, "cpu": {}, "onednn": {},
                                         "arithmetic": {}}
    for s in summaries:
        p = s.get("provenance")
        p = p if isinstance(p, Mapping) else {}
        git = p.get("git") if isinstance(p.get("git"), Mapping) else None
        commit = "unknown" if not p else "not a git checkout" if git is None else (
            str(git.get("commit", ""))[:12] + ("-dirty" if git.get("dirty") else ""))
        env = p.get("environment") if isinstance(p.get("environment"), Mapping) else {}
        keys = {"commit": commit, "cpu": str(p.get("cpu", "unknown")),
                "onednn": "unknown" if not p else str(env.get("TF_ENABLE_ONEDNN_OPTS",
                                                               "default")),
                "arithmetic": _arithmetic(p.get("arithmetic"))}
        for field, key in keys.items():
            counts[field][key] = counts[field].get(key, 0) + 1
    if set(counts["arithmetic"]) <= {"unknown"}:
        del counts["arithmetic"]
    return counts


def _arithmetic(state: Any) -> str:
    portable = state.get("portable") if isinstance(state, Mapping) else None
    return "unknown" if portable is None else "portable" if portable else "cpu's own"


def _num(value: Optional[float], fmt: str = ".3g") -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) \
        else format(value, fmt)


def format_table(results: Mapping[str, Mapping[str, Any]], title: str = "") -> str:
    """A plain-text table of ``{setting label: aggregate_setting(...)}``."""
    head = (f"{'setting':<28}{'runs':>5}{'done':>5}{'fail':>5}{'succ':>5}"
            f"{'rate [95% CI]':>21}{'ep. to solve q1/med/q3 (unsolved)':>36}"
            f"{'steps':>7}{'final dist':>12}{'s/run':>8}")
    lines = ([title] if title else []) + [head, "-" * len(head)]
    for label, r in results.items():
        if r["success_rate"] is None:
            rate = "-"
        else:
            lo, hi = r["success_ci95"]
            rate = f"{r['success_rate']:.2f} [{lo:.2f}, {hi:.2f}]"
        e = r["episodes_to_solve"]
        ep = (f"{_num(e['q1'], 'g')}/{_num(e['median'], 'g')}/{_num(e['q3'], 'g')}"
              f" ({e['unsolved']})")
        last = r["last_episode"]
        lines.append(
            f"{label[:27]:<28}{r['runs']:>5}{r['finished']:>5}{r['failed']:>5}"
            f"{r['successes']:>5}{rate:>21}{ep:>36}"
            f"{_num(last['steps_to_target']['median'], 'g'):>7}"
            f"{_num(last['final_distance']['median']):>12}"
            f"{_num(r['seconds_per_run']['median'], '.0f'):>8}")
        safety = r.get("safety")
        if safety:  # Safe PILCO's runs: which learned policies ran, which broke the constraint
            lines.append(
                f"{'':<28}safety: {safety['executed']} of {safety['learned']} learned "
                f"episodes ran, {safety['executed_violated']} of them broke the constraint "
                f"(random episodes: {safety['random_violated']}); predicted risk of those "
                f"that ran: median {_num(safety['executed_risk']['median'], '.3f')}, max "
                f"{_num(safety['executed_risk']['max'], '.3f')}")
    return "\n".join(lines)
