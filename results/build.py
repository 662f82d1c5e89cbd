"""The committed sweep results and everything generated from them.

    python results/build.py export SWEEP_DIR [SWEEP_DIR ...]
    python results/build.py render [--check] [--no-figures]

``export`` reads sweep directories and writes one small JSON file per task,
``results/<task>.json``. ``SWEEP_DIR`` is the ``--output`` of ``python -m pilco.sweep
TASK --seeds ...``: it holds ``SETTING/seed-S/summary.json`` per run and, once the sweep
has finished, ``sweep.json``. A file holds

* ``format`` (:data:`FORMAT`), ``task``, ``command`` (the sweep's command line from
  ``sweep.json``, its output directory written ``DIR``; ``null`` before ``sweep.json``
  exists), ``seeds`` (the seeds asked for, from ``sweep.json``; without it the seeds of
  the ``seed-S`` directories, which a sweep makes for every run it plans) and ``failed``
  (``{setting: [seed, ...]}``: runs ``sweep.json`` records as failed that have no finished
  summary);
* ``runs``: one entry per finished run, by setting and seed: ``setting``, ``seed``,
  ``success``, ``solved``, ``solved_at_episode``, ``seconds`` (the run's total),
  ``episodes`` (per episode ``episode``, ``random``, ``steps``, ``min_distance``,
  ``final_distance``, ``steps_to_target``), ``distances`` (per episode, per step, rounded
  to 4 decimals), ``provenance`` (the run's commit, CPU model and
  ``TF_ENABLE_ONEDNN_OPTS``, in the layout of ``summary.json``; absent when the summary
  has none) and, for the adaptation task, ``damage_at_episode`` and
  ``episodes_to_recover``;
* ``settings``: ``{setting: pilco.sweep.aggregate.aggregate_setting(...)}`` of those
  runs (counts, success rate and Wilson interval, episodes to solve, seconds per run,
  provenance counts), for a reader of the file. It is derived from ``runs``: loading a
  file whose ``settings`` disagree with its ``runs`` is an error.

A run counts as finished when its ``summary.json`` says ``complete: true``, has
episodes, and its ``sweep-run.json`` (if any) says ``finished``: a sweep still running
exports the runs done so far. A directory without a finished run is reported and
skipped (an existing export of it is left as it was).

``render`` writes what is generated from the exports:

* the README's success table, between the lines :data:`BEGIN` and :data:`END`, from
  ``results/<task>.json`` and the hand-edited ``results/table.json`` (see
  :func:`load_table`): the row's label, success rule, goal and "more seeds" note come from
  ``table.json``, its numbers (successes of finished runs, seeds, median episode solved,
  median seconds per run, CPU model) from the export. A row without an export must say
  so with a ``manual`` entry, and is rendered marked as typed in;
* ``docs/figures/<task>_success_rate.png`` and ``<task>_distance_bands.png`` for every
  export, drawn by :mod:`pilco.sweep.figures`.

``render --check`` writes nothing and exits with status 1 when the README's table is not
the one the data gives. ``notebooks/04_success_rates.ipynb`` reads the same exports.
Only the standard library, NumPy, Matplotlib and ``pilco`` are used.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))      # this checkout's pilco, also when run as a script

from pilco.sweep.aggregate import aggregate_setting, quantile  # noqa: E402

RESULTS_DIR = ROOT / "results"
TABLE_FILE = RESULTS_DIR / "table.json"
README = ROOT / "README.md"
FIGURE_DIR = ROOT / "docs" / "figures"

#: the version of the export layout described above
FORMAT = 2
DECIMALS = 4
#: a file above this size is reported (the exports are meant to stay small)
MAX_BYTES = 200_000

EPISODE_FIELDS = ("episode", "random", "steps", "min_distance", "final_distance",
                  "steps_to_target")
#: an episode's fields kept only when its record has them (runs on a constraint): the
#: policy's predicted risk and whether the real episode broke the constraint (whether the
#: policy ran, Safe PILCO's loop, is kept from its ``safety`` record by :func:`trim_episode`)
CONSTRAINT_FIELDS = ("predicted_risk", "violated")
#: summary fields kept per run when present: the adaptation's damage and recovery, the
#: multi-target reacher's held-out test (steps per test target, how many within the rule),
#: whether a run held its first success to the end and which learned episodes were solved,
#: Safe PILCO's counts of executed and violating episodes
TASK_FIELDS = ("healthy_reached_at_episode", "damage_at_episode", "episodes_to_recover",
               "test_steps", "test_reached", "held_for_good", "solved_episodes", "safety")
RUN_FIELDS = ("setting", "seed", "success", "solved", "solved_at_episode", "seconds",
              "episodes", "distances")

COMMAND = "python results/build.py render"
BEGIN_PREFIX = "<!-- results-table:"
BEGIN = (f"{BEGIN_PREFIX} generated by `{COMMAND}` from results/*.json and "
         "results/table.json; edit those, not this table -->")
END = "<!-- /results-table -->"
#: marks the cells of a row typed into table.json instead of computed from an export
MANUAL_MARK = "†"

TABLE_KEYS = {"task", "label", "rule", "goal", "more", "setting", "data", "manual",
              "scratch"}

#: separates a task from a variant's name in an export's file name: a task can have
#: several exports (e.g. the same sweep with oneDNN on and off), ``<task>--<variant>.json``
VARIANT_SEP = "--"
TABLE_REQUIRED = ("task", "label", "rule", "goal")
MANUAL_KEYS = {"seeds", "result", "per_run", "note"}


# ------------------------------------------------------------------------------ export
def read_json(path) -> Optional[Any]:
    """The parsed file, or None when it is missing or not (yet) valid JSON (a run may be
    writing it)."""
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def _round(value, decimals: int = DECIMALS):
    return None if value is None else round(float(value), decimals)


def finished_summary(run_dir) -> Optional[Dict[str, Any]]:
    """The run's summary if the run finished, else None."""
    summary = read_json(os.path.join(run_dir, "summary.json"))
    if not isinstance(summary, dict) or summary.get("complete") is not True \
            or not summary.get("episodes"):
        return None
    record = read_json(os.path.join(run_dir, "sweep-run.json"))
    if isinstance(record, dict) and record.get("status") != "finished":
        return None
    return summary


def trim_provenance(provenance: Any) -> Optional[Dict[str, Any]]:
    """What :func:`pilco.sweep.aggregate.provenance_counts` reads of a summary's
    ``provenance`` (commit and dirty flag, CPU model, whether the arithmetic was portable,
    ``TF_ENABLE_ONEDNN_OPTS``), in the same layout; None without provenance."""
    if not isinstance(provenance, Mapping) or not provenance:
        return None
    git = provenance.get("git")
    out: Dict[str, Any] = {
        "git": ({"commit": str(git.get("commit", "")), "dirty": bool(git.get("dirty"))}
                if isinstance(git, Mapping) else None),
        "cpu": str(provenance.get("cpu", "unknown")),
    }
    arithmetic = provenance.get("arithmetic")
    if isinstance(arithmetic, Mapping) and arithmetic.get("portable") is not None:
        out["arithmetic"] = {"portable": bool(arithmetic["portable"])}
    env = provenance.get("environment")
    if isinstance(env, Mapping) and "TF_ENABLE_ONEDNN_OPTS" in env:
        out["environment"] = {"TF_ENABLE_ONEDNN_OPTS": str(env["TF_ENABLE_ONEDNN_OPTS"])}
    return out


def trim_episode(record: Mapping[str, Any]) -> Dict[str, Any]:
    """What an export keeps of one episode's record: :data:`EPISODE_FIELDS` (distances
    rounded), and :data:`CONSTRAINT_FIELDS` and whether its policy ran when it has them."""
    out = {k: (_round(record.get(k)) if k.endswith("distance") else record.get(k))
           for k in EPISODE_FIELDS}
    out.update((k, record[k]) for k in CONSTRAINT_FIELDS if k in record)
    if isinstance(record.get("safety"), Mapping) and "executed" in record["safety"]:
        out["safety"] = {"executed": bool(record["safety"]["executed"])}
    return out


def trim_run(summary: Mapping[str, Any], setting: str) -> Dict[str, Any]:
    """What the table, the figures and the notebook need of one run summary."""
    if "success" in summary and summary["success"] is not None:
        success = bool(summary["success"])
    else:
        success = bool(summary["solved"])
    seconds = summary.get("seconds")
    run: Dict[str, Any] = {
        "setting": setting,
        "seed": summary.get("seed"),
        "success": success,
        "solved": bool(summary.get("solved")),
        "solved_at_episode": summary.get("solved_at_episode"),
        "seconds": _round(seconds.get("total"), 1) if isinstance(seconds, Mapping) else None,
        "episodes": [trim_episode(e) for e in summary["episodes"]],
        "distances": [[_round(d) for d in episode] for episode in summary.get("distances") or []],
    }
    provenance = trim_provenance(summary.get("provenance"))
    if provenance is not None:
        run["provenance"] = provenance
    for key in TASK_FIELDS:
        if key in summary:
            run[key] = summary[key]
    return run


def portable_command(command: Sequence[str]) -> List[str]:
    """The sweep's command with its output directory written ``DIR``."""
    out = [str(a) for a in command]
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


def as_summary(run: Mapping[str, Any]) -> Dict[str, Any]:
    """An exported run in the layout of a ``summary.json`` (seconds as ``{"total": s}``),
    as :mod:`pilco.sweep.aggregate` and :mod:`pilco.sweep.figures` read it."""
    out = dict(run)
    if run.get("seconds") is not None:
        out["seconds"] = {"total": run["seconds"]}
    else:
        out.pop("seconds", None)
    return out


def settings_of(data: Mapping[str, Any]) -> List[str]:
    """The settings of an export: those of its finished runs and of its failed ones."""
    return sorted({r["setting"] for r in data["runs"]} | set(data.get("failed") or {}))


def aggregates(data: Mapping[str, Any]) -> Dict[str, Dict[str, Any]]:
    """``{setting: aggregate_setting(...)}`` of an export's runs. The runs asked for per
    setting are its ``seeds`` (when the sweep said), else the finished and failed ones;
    those neither finished nor failed count as not run."""
    out = {}
    failed_by_setting = data.get("failed") or {}
    for setting in settings_of(data):
        runs = [as_summary(r) for r in data["runs"] if r["setting"] == setting]
        failed = len(failed_by_setting.get(setting, []))
        asked = len(data["seeds"]) if data.get("seeds") else len(runs) + failed
        aggregate = aggregate_setting(runs, runs=asked, failed=failed,
                                      not_run=max(asked - len(runs) - failed, 0))
        # through JSON, so that a fresh aggregate compares equal to a loaded one
        out[setting] = json.loads(json.dumps(aggregate))
    return out


def export_sweep(sweep_dir) -> Optional[Dict[str, Any]]:
    """The export of one sweep directory (None without a finished run)."""
    sweep_dir = os.fspath(sweep_dir)
    if not os.path.isdir(sweep_dir):
        raise ValueError(f"{sweep_dir}: not a directory")
    runs, first_task, seen = [], None, set()
    for setting in sorted(os.listdir(sweep_dir)):
        setting_dir = os.path.join(sweep_dir, setting)
        if not os.path.isdir(setting_dir):
            continue
        seeds = sorted((s, name) for name in os.listdir(setting_dir)
                       if (s := _seed_of(name)) is not None)
        seen.update(s for s, _ in seeds)
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
    data: Dict[str, Any] = {
        "format": FORMAT,
        "task": task,
        "command": portable_command(report["command"]) if report.get("command") else None,
        "seeds": report.get("seeds") or sorted(seen),
        "failed": failed,
    }
    data["settings"] = aggregates({**data, "runs": runs})
    data["runs"] = runs
    return data


def check_variant(variant: Any) -> None:
    """ValueError unless ``variant`` is a variant name: letters, digits, ``.``, ``_`` and
    ``-`` (not first)."""
    if not isinstance(variant, str) or not re.fullmatch(r"[A-Za-z0-9._-]+", variant) \
            or variant.startswith("-"):
        raise ValueError(f"bad variant name {variant!r}: use letters, digits, '.', '_' "
                         "and '-' (not first)")


def export_name(task: str, variant: Optional[str] = None) -> str:
    """The file stem of a task's export: ``task``, or ``task--variant`` for a variant
    (:func:`check_variant`)."""
    if variant is None:
        return task
    check_variant(variant)
    return f"{task}{VARIANT_SEP}{variant}"


def write_export(data: Mapping[str, Any], directory=RESULTS_DIR,
                 variant: Optional[str] = None) -> Path:
    """Write ``data`` to ``directory/<task>.json``, or ``<task>--<variant>.json`` for a
    variant (compact, one line); returns the path."""
    check_export(data, f"the export of task {data.get('task')!r}")
    path = Path(directory) / f"{export_name(data['task'], variant)}.json"
    path.write_text(json.dumps(data, separators=(",", ":")) + "\n", encoding="utf-8")
    return path


def check_export(data: Any, where: str) -> None:
    """Raise TypeError/ValueError, naming ``where``, unless ``data`` is an export of
    :data:`FORMAT` whose ``settings`` are the aggregates of its ``runs``."""
    if not isinstance(data, dict):
        raise TypeError(f"{where}: an export is a JSON object, not {type(data).__name__}")
    if data.get("format") != FORMAT:
        raise ValueError(f"{where}: format {data.get('format')!r}, this script reads format "
                         f"{FORMAT}; export the sweep again with `python results/build.py "
                         "export SWEEP_DIR`")
    if not isinstance(data.get("task"), str) or not data["task"]:
        raise ValueError(f"{where}: no 'task' name")
    if not isinstance(data.get("runs"), list) or not data["runs"]:
        raise ValueError(f"{where}: no finished 'runs'")
    for k, run in enumerate(data["runs"]):
        if not isinstance(run, dict):
            raise TypeError(f"{where}: runs[{k}] is not an object")
        missing = [f for f in RUN_FIELDS if f not in run]
        if missing:
            raise ValueError(f"{where}: runs[{k}] lacks {', '.join(missing)}")
    if not isinstance(data.get("failed"), dict):
        raise TypeError(f"{where}: 'failed' must be an object {{setting: [seed, ...]}}")
    if data.get("seeds") is not None and not isinstance(data["seeds"], list):
        raise TypeError(f"{where}: 'seeds' must be a list or null")
    if data.get("settings") != aggregates(data):
        raise ValueError(f"{where}: its 'settings' are not the aggregates of its 'runs' "
                         "(edited by hand?); export the sweep again")


def read_json_file(path) -> Any:
    """The parsed JSON file ``path``: FileNotFoundError when it is missing, ValueError
    when it is not JSON, each naming the file."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{_show(path)}: no such file")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except ValueError as e:
        raise ValueError(f"{_show(path)}: not valid JSON ({e})") from None


def load_export(path) -> Dict[str, Any]:
    """The checked export in ``path`` (FileNotFoundError naming it when it is missing)."""
    data = read_json_file(path)
    check_export(data, _show(path))
    return data


def load_exports(directory=RESULTS_DIR) -> Dict[str, Dict[str, Any]]:
    """``{file stem: export}`` of every ``<task>.json`` and ``<task>--<variant>.json`` in
    ``directory`` but ``table.json``."""
    exports = {}
    for path in sorted(Path(directory).glob("*.json")):
        if path.name == TABLE_FILE.name:
            continue
        data = load_export(path)
        task = path.stem.split(VARIANT_SEP, 1)[0]
        if task != data["task"]:
            raise ValueError(f"{_show(path)} holds task {data['task']!r}: name it "
                             f"{data['task']}.json or {data['task']}{VARIANT_SEP}VARIANT.json")
        exports[path.stem] = data
    return exports


def _show(path) -> str:
    """``path`` relative to the repository when it is inside it."""
    try:
        return str(Path(path).resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


# ------------------------------------------------------------------------------ the table
def load_table(path=TABLE_FILE) -> List[Dict[str, Any]]:
    """The rows of ``results/table.json``, in order, checked.

    The file is ``{"rows": [row, ...]}``; a row has ``task`` (its export is
    ``results/<task>.json``), ``label``, ``rule`` (the success rule), ``goal`` (Markdown
    text), optionally ``more`` (the "more seeds" note), ``data`` (another export of the
    task: ``results/<data>.json``, e.g. ``damaged_reacher--onednn-off``), ``setting``
    (which setting of the export; ``"default"`` unless given) and ``manual``: for a task
    without an export, the
    row's figures typed in, ``{"seeds", "result", "per_run", "note"}`` (``note`` says
    where they come from and why they are not data). Rows appear in the file's order.
    """
    path = Path(path)
    table = read_json_file(path)
    if not isinstance(table, dict) or not isinstance(table.get("rows"), list):
        raise TypeError(f"{_show(path)}: expected {{\"rows\": [...]}}")
    rows, seen = [], set()
    for k, row in enumerate(table["rows"]):
        where = f"{_show(path)}: rows[{k}]"
        if not isinstance(row, dict):
            raise TypeError(f"{where} is not an object")
        unknown = sorted(set(row) - TABLE_KEYS)
        if unknown:
            raise ValueError(f"{where}: unknown key(s) {', '.join(unknown)}")
        for key in TABLE_REQUIRED:
            if not isinstance(row.get(key), str) or not row[key].strip():
                raise ValueError(f"{where}: '{key}' must be a non-empty string")
        for key in ("more", "setting", "data"):
            if key in row and not isinstance(row[key], str):
                raise TypeError(f"{where}: '{key}' must be a string")
        if "data" in row and row["data"] != row["task"] \
                and not row["data"].startswith(row["task"] + VARIANT_SEP):
            raise ValueError(f"{where}: 'data' {row['data']!r} is not an export of task "
                             f"{row['task']!r} ({row['task']} or "
                             f"{row['task']}{VARIANT_SEP}VARIANT)")
        key = (data_name(row), row.get("setting", "default"))
        if key in seen:
            raise ValueError(f"{where}: {key[0]!r}, setting {key[1]!r} has a row already")
        seen.add(key)
        if "manual" in row:
            manual = row["manual"]
            if not isinstance(manual, dict) or set(manual) != MANUAL_KEYS or not all(
                    isinstance(v, str) and v.strip() for v in manual.values()):
                raise ValueError(f"{where}: 'manual' must have exactly the non-empty strings "
                                 f"{', '.join(sorted(MANUAL_KEYS))}")
        rows.append(row)
    return rows


def data_name(row: Mapping[str, Any]) -> str:
    """The stem of the export a table row reads: its ``data``, else its ``task``."""
    return row.get("data", row["task"])


def seed_ranges(seeds: Iterable[int]) -> str:
    """``[0, 1, 2, 5, 7, 8]`` -> ``"0-2, 5, 7-8"``."""
    values = sorted(set(int(s) for s in seeds))
    parts, start = [], None
    for i, s in enumerate(values):
        if start is None:
            start = s
        if i + 1 == len(values) or values[i + 1] != s + 1:
            parts.append(str(start) if start == s else f"{start}-{s}")
            start = None
    return ", ".join(parts)


def export_seeds(data: Mapping[str, Any], setting: str) -> List[int]:
    """The seeds a setting's sweep asked for (its finished and failed runs when the
    export does not say)."""
    if data.get("seeds"):
        return list(data["seeds"])
    return [r["seed"] for r in data["runs"] if r["setting"] == setting] \
        + list((data.get("failed") or {}).get(setting, []))


def _cell(text: str) -> str:
    """Text from the data made safe for a Markdown table cell."""
    return str(text).replace("|", "\\|").replace("\n", " ")


def count_label(counts: Mapping[str, int]) -> str:
    """One provenance field's counts (:func:`pilco.sweep.aggregate.provenance_counts`) in
    words: the value when all runs agree, else each value with its runs; "not recorded"
    for runs whose summary had no provenance."""
    if len(counts) == 1:
        value = next(iter(counts))
        return "not recorded" if value == "unknown" else _cell(value)
    return ", ".join(f"{'not recorded' if k == 'unknown' else _cell(k)} "
                     f"({n} run{'' if n == 1 else 's'})" for k, n in sorted(counts.items()))


def result_text(aggregate: Mapping[str, Any]) -> str:
    """The result cell: successes of the finished runs, the median episode solved and
    the runs that did not finish."""
    text = f"**{aggregate['successes']}/{aggregate['finished']}**"
    solve, recover = aggregate["episodes_to_solve"], aggregate.get("episodes_to_recover")
    if recover is not None and recover["median"] is not None:
        text += f", recovered after {recover['median']:g} damaged episode(s) median"
    elif solve["median"] is not None:
        text += f", solved at episode {solve['median']:g} median"
    elif solve["solved"] == 0:
        text += ", none solved"
    else:
        text += f", {solve['unsolved']} of {aggregate['finished']} never solved"
    missing = []
    if aggregate["failed"]:
        missing.append(f"{aggregate['failed']} failed")
    if aggregate["not_run"]:
        missing.append(f"{aggregate['not_run']} not finished")
    if missing:
        text += f" ({', '.join(missing)}, not counted)"
    return text


def per_run_text(aggregate: Mapping[str, Any]) -> str:
    """The per-run cell: the median seconds of a run and the CPU model(s)."""
    median = aggregate["seconds_per_run"]["median"]
    seconds = "–" if median is None else f"{median:.0f} s"
    cpus = aggregate["provenance"]["cpu"]
    if set(cpus) == {"unknown"}:
        return f"{seconds} (CPU not recorded)"
    return f"{seconds} on {count_label(cpus)}"


def table_row(row: Mapping[str, Any], exports: Mapping[str, Mapping[str, Any]],
              directory=RESULTS_DIR) -> List[str]:
    """The cells of one table row: experiment, success rule, seeds, result, more seeds,
    per run, goal."""
    task = data_name(row)
    path = Path(directory) / f"{task}.json"
    if "manual" in row:
        if task in exports:
            raise ValueError(f"results/table.json: the row of {task!r} is marked manual "
                             f"but {_show(path)} holds its data: drop its 'manual' entry")
        manual = row["manual"]
        return [row["label"], row["rule"], manual["seeds"],
                f"{manual['result']} {MANUAL_MARK}", row.get("more", ""),
                f"{manual['per_run']} {MANUAL_MARK}", row["goal"]]
    if task not in exports:
        raise FileNotFoundError(
            f"{_show(path)}: no such file, but results/table.json has a row for {task!r}; "
            f"export its sweep (`python results/build.py export SWEEP_DIR`) or give the "
            f"row a 'manual' entry")
    data = exports[task]
    setting = row.get("setting", "default")
    aggregate = (data.get("settings") or {}).get(setting)
    if aggregate is None:
        raise ValueError(f"{_show(path)} has no setting {setting!r} (it has "
                         f"{', '.join(settings_of(data))}); set the row's 'setting' in "
                         "results/table.json")
    more = row.get("more", "")
    if "scratch" in row:
        more = "; ".join(m for m in (more, scratch_text(data, exports, row["scratch"],
                                                         setting)) if m)
    return [row["label"], row["rule"], seed_ranges(export_seeds(data, setting)),
            result_text(aggregate), more, per_run_text(aggregate), row["goal"]]


def paired_recovery(data: Mapping[str, Any], scratch: Mapping[str, Any],
                    setting: str = "default") -> List[Dict[str, Any]]:
    """Per seed of the adaptation export ``data`` (its ``setting``) that the from-scratch
    export ``scratch`` (its default setting) also ran: ``seed``,
    ``healthy_reached_at_episode`` (:func:`_healthy_reached`),
    ``episodes_to_recover`` (damaged episodes, counting the
    one that reached; None: not within the run) and ``scratch_solved_at_episode`` (the
    from-scratch run's first solved episode, counting its random ones: the episodes it
    spent on the damaged arm; None: never)."""
    theirs = {r["seed"]: r for r in scratch["runs"] if r["setting"] == "default"}
    return [{"seed": r["seed"], "healthy_reached_at_episode": _healthy_reached(r),
             "episodes_to_recover": r.get("episodes_to_recover"),
             "scratch_solved_at_episode": theirs[r["seed"]]["solved_at_episode"]}
            for r in sorted(data["runs"], key=lambda r: r["seed"])
            if r["setting"] == setting and r["seed"] in theirs]


def _healthy_reached(run: Mapping[str, Any]) -> Any:
    """An adaptation run's first healthy episode that reached: its summary's field, else
    its first solved episode when that came before the damage (None: none did; "–" for
    a run exported without either field)."""
    if "healthy_reached_at_episode" in run:
        return run["healthy_reached_at_episode"]
    first, damage = run.get("solved_at_episode"), run.get("damage_at_episode")
    if damage is None:
        return "–"
    return first if first is not None and first < damage else None


def scratch_text(data: Mapping[str, Any], exports: Mapping[str, Mapping[str, Any]],
                 scratch: str, setting: str) -> str:
    """The adaptation's recovery against learning the damaged arm from scratch on the same
    seeds (a row's ``scratch`` export): episodes on the damaged arm, medians (a run that
    never reached counts as infinitely many)."""
    if scratch not in exports:
        raise FileNotFoundError(f"results/{scratch}.json: no such export, but a row of "
                                f"results/table.json compares with it ('scratch')")
    pairs = paired_recovery(data, exports[scratch], setting)
    if not pairs:
        return f"no seed in common with `{scratch}`"
    ours, theirs = (quantile([math.inf if p[k] is None else p[k] for p in pairs], 0.5)
                    for k in ("episodes_to_recover", "scratch_solved_at_episode"))
    return (f"on the damaged arm: {ours:g} episode(s) median to reach again, against "
            f"{theirs:g} learning from scratch (`{scratch}`, the same {len(pairs)} seeds)")


def pairs_table(data: Mapping[str, Any], scratch: Mapping[str, Any],
                setting: str = "default") -> str:
    """:func:`paired_recovery` as a Markdown table."""
    def cell(v):
        return "never" if v is None else str(v)

    lines = ["| seed | healthy arm reached in episode | damaged episodes to reach again | "
             "from scratch: solved in episode |", "|---|---|---|---|"]
    lines += [f"| {p['seed']} | {cell(p['healthy_reached_at_episode'])} | "
              f"{cell(p['episodes_to_recover'])} | {cell(p['scratch_solved_at_episode'])} |"
              for p in paired_recovery(data, scratch, setting)]
    return "\n".join(lines) + "\n"


def source_line(row: Mapping[str, Any], data: Mapping[str, Any]) -> str:
    """Where a data row comes from: file, sweep command, commit(s), oneDNN setting."""
    setting = row.get("setting", "default")
    provenance = data["settings"][setting]["provenance"]
    command = ("`" + " ".join(data["command"]) + "`" if data.get("command")
               else "a sweep exported before it wrote sweep.json")
    which = "" if setting == "default" else f", setting `{setting}`"
    return (f"- {row['label']}: `results/{data_name(row)}.json`{which}, {command}; "
            f"commit {count_label(provenance['commit'])}; "
            f"`TF_ENABLE_ONEDNN_OPTS`: {count_label(provenance['onednn'])}")


def render_table(rows: Sequence[Mapping[str, Any]],
                 exports: Mapping[str, Mapping[str, Any]], directory=RESULTS_DIR) -> str:
    """The Markdown between :data:`BEGIN` and :data:`END` (both excluded): the table, the
    source of each data row and the note of each manual row, then a blank line."""
    head = ["experiment", "success rule", "seeds", "result", "more seeds", "per run (median)",
            "goal"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows:
        lines.append("| " + " | ".join(table_row(row, exports, directory)) + " |")
    sources = [source_line(row, exports[data_name(row)]) for row in rows
               if "manual" not in row]
    if sources:
        lines += ["", "The data of each row (per run: median over the finished runs):", ""]
        lines += sources
    for row in rows:
        if "manual" in row:
            lines += ["", f"{MANUAL_MARK} {row['label']}: typed into results/table.json, not "
                          f"computed from committed data: {row['manual']['note']}"]
    return "\n".join(lines) + "\n\n"     # a blank line ends the table before END


def readme_block(text: str, where: str = "README.md") -> tuple:
    """``(start, end)`` offsets of the text between the marker lines in ``text``."""
    begins = [i for i, line in enumerate(text.splitlines(keepends=True))
              if line.startswith(BEGIN_PREFIX)]
    ends = [i for i, line in enumerate(text.splitlines(keepends=True)) if line.strip() == END]
    if len(begins) != 1 or len(ends) != 1 or begins[0] > ends[0]:
        raise ValueError(f"{where}: needs one line starting {BEGIN_PREFIX!r} and, after it, "
                         f"one line {END!r} around the success table")
    lines = text.splitlines(keepends=True)
    start = sum(len(line) for line in lines[:begins[0] + 1])
    end = sum(len(line) for line in lines[:ends[0]])
    return start, end


def with_table(text: str, table: str, where: str = "README.md") -> str:
    """``text`` with the table block replaced by ``table`` and the opening marker line
    rewritten to :data:`BEGIN`."""
    start, end = readme_block(text, where)
    lines = text[:start].splitlines(keepends=True)
    lines[-1] = BEGIN + "\n"
    return "".join(lines) + table + text[end:]


# ---------------------------------------------------------------------------- figures
def draw_figures(data: Mapping[str, Any], directory=FIGURE_DIR,
                 name: Optional[str] = None) -> List[str]:
    """``<name>_success_rate.png`` and ``<name>_distance_bands.png`` of one export (one
    line or panel per setting; ``name`` the export's file stem, default its task), and
    ``<name>_risk_calibration.png`` when its episodes record a predicted risk; returns
    the paths drawn."""
    from pilco.sweep.figures import draw_figures as draw_sweep_figures

    per_setting = {s: [as_summary(r) for r in data["runs"] if r["setting"] == s]
                   for s in settings_of(data)}
    seeds = sorted({r["seed"] for r in data["runs"]} if not data.get("seeds")
                   else data["seeds"])
    title = f"{data['task']}, seeds {seed_ranges(seeds)}"
    task = name or data["task"]
    return draw_sweep_figures(per_setting, str(directory), prefix=f"{task}_", title=title)


# ------------------------------------------------------------------------ command line
def export_main(sweeps: Sequence[str], directory=RESULTS_DIR,
                variant: Optional[str] = None) -> int:
    if variant is not None:
        check_variant(variant)   # a bad name fails before any file is read
        if len(sweeps) != 1:
            raise ValueError("--variant names the export of one sweep directory")
    status = 0
    for sweep_dir in sweeps:
        if not os.path.isdir(sweep_dir):
            print(f"{sweep_dir}: no such directory, skipped", file=sys.stderr)
            status = 1
            continue
        data = export_sweep(sweep_dir)
        if data is None:
            print(f"{sweep_dir}: no finished run yet, skipped", file=sys.stderr)
            continue
        path = write_export(data, directory, variant)
        size = path.stat().st_size
        print(f"{_show(path)}: {len(data['runs'])} finished runs, {size / 1e3:.0f} kB")
        if size > MAX_BYTES:
            print(f"{_show(path)} is over {MAX_BYTES / 1e3:.0f} kB", file=sys.stderr)
            status = 1
    return status


def render_main(check: bool, figures: bool) -> int:
    exports = load_exports()
    table = render_table(load_table(), exports)
    text = README.read_text(encoding="utf-8")
    new = with_table(text, table)
    if check:
        if new != text:
            print(f"README.md: the success table is not the one results/ gives; run "
                  f"`{COMMAND}`", file=sys.stderr)
            return 1
        print("README.md: the success table matches results/")
        return 0
    if new != text:
        README.write_text(new, encoding="utf-8")
        print("README.md: success table rewritten")
    else:
        print("README.md: success table unchanged")
    if figures:
        for name, data in exports.items():
            for path in draw_figures(data, name=name):
                print(f"{_show(path)} drawn")
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    export = commands.add_parser("export", help="write results/<task>.json from sweeps")
    export.add_argument("sweeps", nargs="+", metavar="SWEEP_DIR",
                        help="a pilco.sweep --output directory")
    export.add_argument("--variant", default=None,
                        help="write results/<task>--VARIANT.json instead of <task>.json "
                             "(another sweep of the same task, e.g. with oneDNN off)")
    render = commands.add_parser("render", help="rewrite the README table and the figures")
    render.add_argument("--check", action="store_true",
                        help="write nothing; status 1 when the README's table is stale")
    render.add_argument("--no-figures", action="store_true", help="leave docs/figures/")
    pairs = commands.add_parser(
        "pairs", help="per seed: the adaptation's damaged episodes to reach again against "
                      "the episodes to solve from scratch (Markdown)")
    pairs.add_argument("adaptation", help="an export's name, e.g. adaptation")
    pairs.add_argument("scratch", help="an export's name, e.g. damaged_reacher")
    args = parser.parse_args(argv)
    try:
        if args.command == "pairs":
            exports = load_exports()
            for name in (args.adaptation, args.scratch):
                if name not in exports:
                    raise FileNotFoundError(f"results/{name}.json: no such export")
            print(pairs_table(exports[args.adaptation], exports[args.scratch]), end="")
            return 0
        if args.command == "export":
            return export_main(args.sweeps, variant=args.variant)
        return render_main(check=args.check, figures=not args.no_figures)
    except (OSError, ValueError, TypeError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
