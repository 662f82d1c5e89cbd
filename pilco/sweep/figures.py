"""The sweep's figures (matplotlib, Agg backend).

* ``success_rate.png``: fraction of a setting's finished runs solved by episode k, one
  line per setting;
* ``distance_bands.png``: per step, the median and the quartile band over runs of the
  distance to the target, one colour per episode, one panel per setting. It needs the
  per-step ``distances`` of the run summaries and is skipped (with a log line) without;
* ``risk_calibration.png``: for runs on a constraint whose episodes record their
  policy's predicted risk (:mod:`pilco.experiment.safety`), the share of the executed
  learned episodes that broke it against their predicted risk, binned, one panel per
  combination rule (drawn only for such runs).
"""
from __future__ import annotations

import logging
import os
import sys
from typing import Any, List, Mapping, Optional, Sequence

import numpy as np

from .aggregate import RISK_RULES, risk_calibration, solved_by_episode, solved_in_episode

__all__ = ["success_rate_figure", "distance_bands_figure", "distance_quartiles",
           "risk_calibration_figure", "draw_figures"]

logger = logging.getLogger(__name__)


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save_and_close(plt, fig, path: str) -> None:
    """Write ``fig`` to ``path`` unless drawing it failed; always close it."""
    try:
        if sys.exc_info()[0] is None:
            fig.tight_layout()
            fig.savefig(path, dpi=120)
    finally:
        plt.close(fig)


def success_rate_figure(summaries: Mapping[str, Sequence[Mapping[str, Any]]], path: str,
                        title: str = "") -> Optional[str]:
    """Draw the fraction solved by episode k for ``{setting: [summary, ...]}`` into
    ``path``, and the fraction solved *in* episode k (dashed) where the summaries list
    their ``solved_episodes`` (runs that drop what they learned pull it down); returns
    ``path``, or None when no setting has a finished run."""
    settings = {k: v for k, v in summaries.items() if v}
    if not settings:
        logger.info("no finished run: %s not drawn", os.path.basename(path))
        return None
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    try:
        for label, runs in settings.items():
            episodes = max(len(s.get("episodes") or []) for s in runs)
            fractions = solved_by_episode(runs, max(episodes, 1))
            line, = ax.plot(range(1, len(fractions) + 1), fractions, marker="o",
                            label=f"{label} ({len(runs)} runs): solved by episode k")
            within = solved_in_episode(runs, max(episodes, 1))
            if within is not None:
                ax.plot(range(1, len(within) + 1), within, marker="s", linestyle="--",
                        color=line.get_color(), label=f"{label}: solved in episode k")
        from matplotlib.ticker import MaxNLocator

        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel("episode k")
        ax.set_ylabel("fraction of runs")
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
        if title:
            ax.set_title(title)
    finally:
        _save_and_close(plt, fig, path)
    return path


def distance_quartiles(summaries: Sequence[Mapping[str, Any]], episode: int) -> np.ndarray:
    """Quartiles over runs of episode ``episode``'s per-step distance: ``[3, T+1]`` (rows
    q1, median, q3; T the longest episode; a step only over the runs that reached it).
    Runs without that episode are left out; ``[3, 0]`` when none has it."""
    rows: List[np.ndarray] = []
    for s in summaries:
        distances = s.get("distances") or []
        if len(distances) >= episode:
            rows.append(np.asarray(distances[episode - 1], dtype=np.float64))
    if not rows:
        return np.zeros((3, 0), dtype=np.float64)
    length = max(len(r) for r in rows)
    padded = np.full((len(rows), length), np.nan, dtype=np.float64)
    for i, r in enumerate(rows):
        padded[i, :len(r)] = r
    return np.nanpercentile(padded, [25.0, 50.0, 75.0], axis=0)


def distance_bands_figure(summaries: Mapping[str, Sequence[Mapping[str, Any]]], path: str,
                          title: str = "", distance_label: str = "distance to target"
                          ) -> Optional[str]:
    """Draw the distance bands for ``{setting: [summary, ...]}`` into ``path``; returns
    ``path``, or None (logged) when no finished run has ``distances``."""
    settings = {k: [s for s in v if s.get("distances")] for k, v in summaries.items()}
    settings = {k: v for k, v in settings.items() if v}
    if not settings:
        logger.info("the run summaries have no per-step 'distances': %s not drawn",
                    os.path.basename(path))
        return None
    plt = _pyplot()
    fig, axes = plt.subplots(len(settings), 1, figsize=(6.4, 3.2 * len(settings)),
                             squeeze=False, sharex=True)
    try:
        for ax, (label, runs) in zip(axes[:, 0], settings.items()):
            episodes = max(len(s["distances"]) for s in runs)
            colours = plt.cm.viridis(np.linspace(0.0, 0.9, max(episodes, 1)))
            for k in range(1, episodes + 1):
                q = distance_quartiles(runs, k)
                steps = np.arange(q.shape[1])
                ax.fill_between(steps, q[0], q[2], color=colours[k - 1], alpha=0.2,
                                linewidth=0)
                ax.plot(steps, q[1], color=colours[k - 1], label=f"episode {k}")
            ax.set_title(f"{label} ({len(runs)} runs): median, quartile band", fontsize="medium")
            ax.set_ylabel(distance_label)
            ax.grid(alpha=0.3)
            ax.legend(fontsize="x-small", ncol=2)
        axes[-1, 0].set_xlabel("step")
        if title:
            fig.suptitle(title)
    finally:
        _save_and_close(plt, fig, path)
    return path


def risk_calibration_figure(summaries: Mapping[str, Sequence[Mapping[str, Any]]], path: str,
                            title: str = "") -> Optional[str]:
    """Draw, for ``{setting: [summary, ...]}``, the observed violation rate of the executed
    learned episodes (Wilson 95 % interval) against their mean predicted risk per bin of
    :func:`~pilco.sweep.aggregate.risk_calibration`, one panel per rule (Safe PILCO's
    ``independent`` product and the ``union`` bound), the diagonal for reference; points
    below it are conservative predictions. Returns ``path``, or None when no run records
    a predicted risk (nothing drawn, nothing logged: most tasks have no constraint)."""
    table = {label: {rule: risk_calibration(runs, rule) for rule in RISK_RULES}
             for label, runs in summaries.items()}
    table = {k: v for k, v in table.items() if any(v.values())}
    if not table:
        return None
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(RISK_RULES), figsize=(9.6, 4.2), squeeze=False, sharey=True)
    try:
        for ax, rule in zip(axes[0], RISK_RULES):
            ax.plot([0, 1], [0, 1], color="grey", linewidth=0.8, linestyle=":")
            for label, per_rule in table.items():
                bins = per_rule[rule]
                if not bins:
                    continue
                x = np.array([b["mean_risk"] for b in bins])
                y = np.array([b["rate"] for b in bins])
                ci = np.array([b["ci95"] for b in bins]).T
                n = sum(b["episodes"] for b in bins)
                ax.errorbar(x, y, yerr=np.abs(ci - y), marker="o", capsize=3,
                            label=f"{label} ({n} episodes)")
                for b in bins:
                    ax.annotate(str(b["episodes"]), (b["mean_risk"], b["rate"]),
                                textcoords="offset points", xytext=(4, 4), fontsize="x-small")
            ax.set_xlim(-0.02, 1.02)
            ax.set_ylim(-0.02, 1.02)
            ax.set_xlabel(f"predicted risk ({rule}), bin mean")
            ax.set_title(f"rule: {rule}", fontsize="medium")
            ax.grid(alpha=0.3)
        axes[0, 0].set_ylabel("episodes that broke the constraint")
        axes[0, 0].legend(fontsize="x-small")
        if title:
            fig.suptitle(title)
    finally:
        _save_and_close(plt, fig, path)
    return path


def draw_figures(summaries: Mapping[str, Sequence[Mapping[str, Any]]], directory: str,
                 prefix: str = "", title: str = "") -> List[str]:
    """Every figure of the module for ``{setting: [summary, ...]}`` into ``directory``,
    each file named ``prefix`` + its name (``success_rate.png``, ``distance_bands.png``,
    ``risk_calibration.png``); returns the paths drawn (a figure without its data is
    not)."""
    drawn = [draw(summaries, os.path.join(directory, f"{prefix}{name}.png"), title=title)
             for draw, name in ((success_rate_figure, "success_rate"),
                                (distance_bands_figure, "distance_bands"),
                                (risk_calibration_figure, "risk_calibration"))]
    return [p for p in drawn if p is not None]
