"""Text tables of a run: the paper's timing table and one line per episode."""
from __future__ import annotations

from typing import Any, Dict, Optional

__all__ = ["format_timing_table", "format_episode_table"]


def format_timing_table(seconds: Dict[str, float], title: str = "Timing",
                        reference: Optional[Dict[str, float]] = None) -> str:
    """The paper's timing table: interaction, model training, controller optimisation,
    whole program, in seconds (optionally next to a ``reference`` column)."""
    rows = [("Interaction", "interaction"), ("Model training", "model"),
            ("Controller optimisation", "policy"), ("Whole program", "total")]
    head = f"{'Phase':<26}{'this run [s]':>14}"
    if reference:
        head += f"{'paper [s]':>12}"
    lines = [title, head, "-" * len(head)]
    for label, key in rows:
        line = f"{label:<26}{seconds.get(key, float('nan')):>14.2f}"
        if reference:
            ref = reference.get(key)
            line += f"{ref:>12.2f}" if ref is not None else f"{'':>12}"
        lines.append(line)
    return "\n".join(lines)


def format_episode_table(summary: Dict[str, Any]) -> str:
    """One line per episode: steps, cost, final/min distance, steps to target, times."""
    head = (f"{'ep':>3} {'kind':<7}{'steps':>6}{'cost':>8}{'final d':>9}{'min d':>8}"
            f"{'to tgt':>7}{'inter':>7}{'model':>7}{'policy':>8}")
    lines = [head, "-" * len(head)]
    for r in summary["episodes"]:
        s = r["seconds"]
        lines.append(
            f"{r['episode']:>3} {'random' if r['random'] else 'learned':<7}{r['steps']:>6}"
            f"{r['cost']:>8.2f}{r['final_distance']:>9.3f}{r['min_distance']:>8.3f}"
            f"{str(r['steps_to_target']) if r['steps_to_target'] is not None else '-':>7}"
            f"{s['interaction']:>7.1f}{s['model']:>7.1f}{s['policy']:>8.1f}")
    return "\n".join(lines)
