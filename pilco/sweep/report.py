"""The report of a sweep: every finished run on disk aggregated per setting into
``sweep.json``, with the figures."""
from __future__ import annotations

import argparse
import logging
import os
from typing import Any, Dict, List, Optional, Sequence

from pilco.files import write_json_atomic

from . import aggregate, figures, runs
from .runs import RunSpec

__all__ = ["write_report"]

logger = logging.getLogger("pilco.sweep")


def write_report(args: argparse.Namespace, specs: Sequence[RunSpec],
                 described: Sequence[Dict], outcome, output: str, wall: float,
                 ray_seconds: Optional[float], extra: Sequence[str]) -> Dict[str, Any]:
    """Aggregate every finished run on disk, write ``sweep.json`` and the figures."""
    failed = {spec: failure for spec, failure in outcome.failed}
    not_run = set(outcome.not_run)
    now = set(outcome.finished)
    per_setting: Dict[str, List[Dict[str, Any]]] = {d["label"]: [] for d in described}
    run_rows = []
    for spec in specs:
        row = {"setting": spec.label, "seed": spec.seed, "directory": spec.directory}
        summary = None
        if spec in failed:
            row.update(status="failed", error=failed[spec]["error"])
        elif spec in not_run:
            row["status"] = "not_run"
        else:
            summary = runs.finished_summary(spec)
        if summary is not None:
            per_setting[spec.label].append(summary)
            row.update(status="finished" if spec in now else "skipped",
                       success=aggregate.run_success(summary),
                       solved_at_episode=summary.get("solved_at_episode"))
        elif "status" not in row:
            row["status"] = "missing"
        run_rows.append(row)
    results = {}
    for d in described:
        label = d["label"]
        rows = [r for r in run_rows if r["setting"] == label]
        results[label] = aggregate.aggregate_setting(
            per_setting[label], runs=len(rows),
            failed=sum(r["status"] == "failed" for r in rows),
            not_run=sum(r["status"] in ("not_run", "missing") for r in rows))
        for field, what in (("commit", "code versions"), ("onednn", "oneDNN settings"),
                            ("cpu", "CPU models"), ("arithmetic", "arithmetics")):
            seen = results[label]["provenance"].get(field, {})
            if len(seen) > 1:
                logger.warning("%s: the runs mix %d %s (%s); their rate is not one "
                               "setting's", label, len(seen), what,
                               ", ".join(f"{k}: {v}" for k, v in sorted(seen.items())))
    report = {
        "task": args.task,
        "command": list(args.command),  # set by main: the command line that ran
        "seeds": sorted({s.seed for s in specs}),
        "settings": list(described),
        "extra_flags": list(extra),
        "wall_seconds": wall,
        "ray": {"address": args.address or "local", "start_seconds": ray_seconds,
                "cpus_per_run": args.cpus_per_run, "max_retries": args.max_retries},
        "interrupted": bool(outcome.interrupted),
        "results": results,
        "failures": [{"setting": spec.label, "seed": spec.seed, **failure}
                     for spec, failure in outcome.failed],
        "runs": run_rows,
    }
    write_json_atomic(os.path.join(output, "sweep.json"), report)
    if not args.no_figures:
        title = f"{args.task}, seeds {args.seeds}"
        figures.draw_figures(per_setting, output, title=title)
    logger.info("results in %s", os.path.join(output, "sweep.json"))
    return report
