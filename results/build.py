"""Export seed sweeps into the small JSON files ``04_success_rates.ipynb`` reads.

    python notebooks/data/export.py SWEEP_DIR [SWEEP_DIR ...]

``SWEEP_DIR`` is the ``--output`` of ``python -m pilco.sweep TASK --seeds ...``: it holds
``SETTING/seed-S/summary.json`` per run and, once the sweep has finished, ``sweep.json``.
Each sweep becomes ``notebooks/data/<task>.json`` (next to this script), holding its
finished runs trimmed to what the notebook shows:

* ``task``, ``command`` (the sweep's command line from ``sweep.json``, its output
  directory written ``DIR``; ``null`` before ``sweep.json`` exists), ``seeds`` (the seeds
  asked for, from ``sweep.json``; ``null`` without it) and ``failed`` (``{setting:
  [seed, ...]}``: runs ``sweep.json`` records as failed that have no finished summary);
* ``runs``: one entry per finished run, by setting and seed: ``setting``, ``seed``,
  ``success``, ``solved``, ``solved_at_episode``, ``seconds`` (the run's total),
  ``episodes`` (per episode ``episode``, ``random``, ``steps``, ``min_distance``,
  ``final_distance``, ``steps_to_target``), ``distances`` (per episode, per step, rounded
  to 4 decimals) and, for the adaptation task, ``damage_at_episode`` and
  ``episodes_to_recover``.

A run counts as finished when its ``summary.json`` says ``complete: true``, has
episodes, and its ``sweep-run.json`` (if any) says ``finished``: a sweep still running
exports the runs done so far. A directory without a finished run is reported and
skipped (an existing export of it is left as it was). Only the standard library is used.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any, Dict, List, Optional

DATA_DIR = os.path.dirname(os.path.abspath(__file__))
DECIMALS = 4
#: a file above this size is reported (the notebook data is meant to stay small)
MAX_BYTES = 200_000

EPISODE_FIELDS = ("episode", "random", "steps", "min_distance", "final_distance",
                  "steps_to_target")
ADAPTATION_FIELDS = ("damage_at_episode", "episodes_to_recover")


def read_json(path: str) -> Optional[Any]:
    """The parsed file, or None when it is missing or not (yet) valid JSON."""
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def _round(value, decimals: int = DECIMALS):
    return None if value is None else round(float(value), decimals)


def finished_summary(run_dir: str) -> Optional[Dict[str, Any]]:
    """The run's summary if the run finished, else None."""
    summary = read_json(os.path.join(run_dir, "summary.json"))
    if not isinstance(summary, dict) or summary.get("complete") is not True \
            or not summary.get("episodes"):
        return None
    record = read_json(os.path.join(run_dir, "sweep-run.json"))
    if isinstance(record, dict) and record.get("status") != "finished":
        return None
    return summary


def trim_run(summary: Dict[str, Any], setting: str) -> Dict[str, Any]:
    """What the notebook needs of one run summary."""
    if "success" in summary and summary["success"] is not None:
        success = bool(summary["success"])
    else:
        success = bool(summary["solved"])
    seconds = summary.get("seconds")
    run = {
        "setting": setting,
        "seed": summary.get("seed"),
        "success": success,
        "solved": bool(summary.get("solved")),
        "solved_at_episode": summary.get("solved_at_episode"),
        "seconds": _round(seconds.get("total"), 1) if isinstance(seconds, dict) else None,
        "episodes": [{k: (_round(e.get(k)) if k.endswith("distance") else e.get(k))
                      for k in EPISODE_FIELDS} for e in summary["episodes"]],
        "distances": [[_round(d) for d in episode] for episode in summary.get("distances") or []],
    }
    for key in ADAPTATION_FIELDS:
        if key in summary:
            run[key] = summary[key]
    return run


def portable_command(command: List[str]) -> List[str]:
    """The sweep's command with its output directory written ``DIR``."""
    out = list(command)
    for i, arg in enumerate(out):
        if arg == "--output" and i + 1 < len(out):
            out[i + 1] = "DIR"
        elif arg.startswith("--output="):
            out[i] = "--output=DIR"
    return out


def _seed_of(name: str) -> Optional[int]:
    if not name.startswith("seed-"):
        return None
    try:
        return int(name[len("seed-"):])
    except ValueError:
        return None


def export_sweep(sweep_dir: str) -> Optional[Dict[str, Any]]:
    """The notebook data of one sweep directory (None without a finished run)."""
    runs, first_task = [], None
    for setting in sorted(os.listdir(sweep_dir)):
        setting_dir = os.path.join(sweep_dir, setting)
        if not os.path.isdir(setting_dir):
            continue
        seeds = sorted((s, name) for name in os.listdir(setting_dir)
                       if (s := _seed_of(name)) is not None)
        for _, name in seeds:
            summary = finished_summary(os.path.join(setting_dir, name))
            if summary is not None:
                first_task = first_task or summary.get("task")
                runs.append(trim_run(summary, setting))
    if not runs:
        return None
    report = read_json(os.path.join(sweep_dir, "sweep.json"))
    report = report if isinstance(report, dict) else {}
    task = report.get("task") or first_task or os.path.basename(os.path.normpath(sweep_dir))
    done = {(r["setting"], r["seed"]) for r in runs}
    failed: Dict[str, List[int]] = {}
    for row in report.get("runs", []):
        if row.get("status") == "failed" and (row.get("setting"), row.get("seed")) not in done:
            failed.setdefault(row.get("setting"), []).append(row.get("seed"))
    return {
        "task": task,
        "command": portable_command(report["command"]) if report.get("command") else None,
        "seeds": report.get("seeds"),
        "failed": failed,
        "runs": runs,
    }


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("sweeps", nargs="+", metavar="SWEEP_DIR",
                        help="a pilco.sweep --output directory")
    args = parser.parse_args(argv)
    status = 0
    for sweep_dir in args.sweeps:
        if not os.path.isdir(sweep_dir):
            print(f"{sweep_dir}: no such directory, skipped", file=sys.stderr)
            continue
        data = export_sweep(sweep_dir)
        if data is None:
            print(f"{sweep_dir}: no finished run yet, skipped", file=sys.stderr)
            continue
        path = os.path.join(DATA_DIR, f"{data['task']}.json")
        text = json.dumps(data, separators=(",", ":")) + "\n"
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
        size = len(text.encode("utf-8"))
        print(f"{os.path.relpath(path)}: {len(data['runs'])} finished runs, {size / 1e3:.0f} kB")
        if size > MAX_BYTES:
            print(f"{os.path.relpath(path)} is over {MAX_BYTES / 1e3:.0f} kB", file=sys.stderr)
            status = 1
    return status


if __name__ == "__main__":
    sys.exit(main())
