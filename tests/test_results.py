"""The committed results and what is generated from them (``results/build.py``).

The README's success table must be what ``python results/build.py render`` makes of
``results/*.json`` and ``results/table.json``; rows without committed data must be
marked manual. The exporter and the table are checked on small synthetic sweeps.
"""
from __future__ import annotations

import copy
import json
import os
from pathlib import Path

import pytest
from _scripts import load_script

ROOT = Path(__file__).resolve().parent.parent


build = load_script("_pilco_results_build", ROOT / "results" / "build.py")


# ------------------------------------------------------------------ the committed data
def test_readme_table_is_the_one_the_committed_data_gives():
    text = build.README.read_text(encoding="utf-8")
    start, end = build.readme_block(text)
    expected = build.render_table(build.load_table(), build.load_exports())
    assert text[start:end] == expected, (
        "README.md's success table differs from results/*.json and results/table.json: "
        f"run `{build.COMMAND}` and commit README.md")
    assert build.with_table(text, expected) == text      # the marker line is current too


def test_rows_without_committed_data_are_exactly_the_manual_ones():
    rows = build.load_table()
    exports = build.load_exports()
    text = build.README.read_text(encoding="utf-8")
    start, end = build.readme_block(text)
    table_lines = [line for line in text[start:end].splitlines() if line.startswith("| ")]
    assert len(table_lines) == 1 + len(rows)             # the header and one line per row
    for row, line in zip(rows, table_lines[1:]):
        assert line.startswith(f"| {row['label']} |")
        if "manual" in row:
            assert build.data_name(row) not in exports
            assert line.count(build.MANUAL_MARK) == 2       # the result and the per-run cell
            assert f"{build.MANUAL_MARK} {row['label']}: typed into" in text[start:end]
        else:
            assert build.data_name(row) in exports, f"no results/{build.data_name(row)}.json"
            assert build.MANUAL_MARK not in line


def test_committed_exports_are_small_and_named_by_task():
    exports = build.load_exports()             # checks format, runs and their aggregates
    assert exports
    for name, data in exports.items():
        assert (build.RESULTS_DIR / f"{name}.json").stat().st_size < build.MAX_BYTES
        assert name.split(build.VARIANT_SEP)[0] == data["task"]


# --------------------------------------------------------------- a synthetic sweep
def _summary(seed, *, success, solved_at, total, cpu="AMD EPYC", dirty=False, onednn=None,
             complete=True, arithmetic=None):
    environment = {"TF_NUM_INTRAOP_THREADS": "1"}
    if onednn is not None:
        environment["TF_ENABLE_ONEDNN_OPTS"] = onednn
    return {
        "task": "reacher", "seed": seed, "complete": complete, "success": success,
        "solved": solved_at is not None, "solved_at_episode": solved_at,
        "seconds": {"model": 1.0, "policy": 2.0, "total": total},
        "episodes": [
            {"episode": 1, "random": True, "steps": 3, "min_distance": 0.412345678,
             "final_distance": 0.5, "steps_to_target": None, "cost": 9.0},
            {"episode": 2, "random": False, "steps": 2, "min_distance": 0.04,
             "final_distance": 0.04, "steps_to_target": 2 if solved_at else None},
        ],
        "distances": [[0.5, 0.45, 0.412345678, 0.42], [0.5, 0.2, 0.04]],
        "provenance": {"git": {"commit": "abcdef1234567890", "dirty": dirty}, "cpu": cpu,
                       "python": "3.11.7", "environment": environment,
                       **({"arithmetic": arithmetic} if arithmetic else {})},
    }


def _write(path, data):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data), encoding="utf-8")


@pytest.fixture
def sweep(tmp_path):
    """A sweep of seeds 0-4: 0 succeeded, 1 failed the task, 2 is still running, 3's
    process failed, 4 was interrupted (its summary complete, its record not finished)."""
    root = tmp_path / "sweep-reacher"
    run = root / "default"
    _write(run / "seed-0" / "summary.json", _summary(0, success=True, solved_at=2, total=100.04))
    _write(run / "seed-0" / "sweep-run.json", {"status": "finished"})
    _write(run / "seed-1" / "summary.json",
           _summary(1, success=False, solved_at=None, total=300.0,
                    cpu="Intel(R) Xeon(R) Processor", dirty=True, onednn="0",
                    arithmetic={"portable": True, "numpy_avx512": [], "blas": ["Haswell"]}))
    _write(run / "seed-2" / "summary.json", _summary(2, success=True, solved_at=2, total=1.0,
                                                     complete=False))
    _write(run / "seed-2" / "sweep-run.json", {"status": "running"})
    _write(run / "seed-3" / "sweep-run.json", {"status": "failed"})
    _write(run / "seed-4" / "summary.json", _summary(4, success=True, solved_at=2, total=1.0))
    _write(run / "seed-4" / "sweep-run.json", {"status": "interrupted"})
    (run / "seed-x").mkdir()
    (run / "notes.txt").write_text("not a run\n")
    _write(root / "sweep.json", {
        "task": "reacher", "seeds": [0, 1, 2, 3, 4],
        "command": ["python", "-m", "pilco.sweep", "reacher", "--seeds", "0-4",
                    "--output", str(root), "--no-progress"],
        "runs": [{"setting": "default", "seed": 0, "status": "finished"},
                 {"setting": "default", "seed": 1, "status": "skipped"},
                 {"setting": "default", "seed": 2, "status": "not_run"},
                 {"setting": "default", "seed": 3, "status": "failed"},
                 {"setting": "default", "seed": 4, "status": "not_run"}]})
    return root


def test_export_keeps_the_finished_runs_and_counts_the_others(sweep):
    data = build.export_sweep(sweep)
    assert data["format"] == build.FORMAT and data["task"] == "reacher"
    assert data["command"] == ["python", "-m", "pilco.sweep", "reacher", "--seeds", "0-4",
                               "--output", "DIR", "--no-progress"]
    assert data["seeds"] == [0, 1, 2, 3, 4]
    assert data["failed"] == {"default": [3]}
    assert [(r["seed"], r["success"]) for r in data["runs"]] == [(0, True), (1, False)]
    first = data["runs"][0]
    assert first["seconds"] == 100.0
    assert first["episodes"][0] == {"episode": 1, "random": True, "steps": 3,
                                    "min_distance": 0.4123, "final_distance": 0.5,
                                    "steps_to_target": None}
    assert first["distances"][0] == [0.5, 0.45, 0.4123, 0.42]
    assert first["provenance"] == {"git": {"commit": "abcdef1234567890", "dirty": False},
                                   "cpu": "AMD EPYC"}
    assert data["runs"][1]["provenance"]["environment"] == {"TF_ENABLE_ONEDNN_OPTS": "0"}
    assert data["runs"][1]["provenance"]["arithmetic"] == {"portable": True}
    aggregate = data["settings"]["default"]
    assert (aggregate["runs"], aggregate["finished"], aggregate["failed"],
            aggregate["not_run"], aggregate["successes"]) == (5, 2, 1, 2, 1)
    assert aggregate["seconds_per_run"] == {"median": 200.0, "max": 300.0}
    assert aggregate["provenance"] == {
        "commit": {"abcdef123456": 1, "abcdef123456-dirty": 1},
        "cpu": {"AMD EPYC": 1, "Intel(R) Xeon(R) Processor": 1},
        "onednn": {"default": 1, "0": 1}, "arithmetic": {"unknown": 1, "portable": 1}}


def test_export_round_trips_and_a_hand_edit_is_caught(sweep, tmp_path):
    out = tmp_path / "results"
    out.mkdir()
    assert build.export_main([str(sweep)], directory=out) == 0
    path = out / "reacher.json"
    assert build.load_export(path) == build.export_sweep(sweep)
    assert build.load_exports(out) == {"reacher": build.export_sweep(sweep)}
    edited = json.loads(path.read_text())
    edited["runs"][1]["success"] = True
    path.write_text(json.dumps(edited))
    with pytest.raises(ValueError, match="not the aggregates of its 'runs'"):
        build.load_export(path)


def test_export_without_sweep_json_or_finished_runs(sweep, tmp_path):
    (sweep / "sweep.json").unlink()
    data = build.export_sweep(sweep)
    assert data["command"] is None and data["failed"] == {}
    assert data["seeds"] == [0, 1, 2, 3, 4]                    # the seed-S directories
    aggregate = data["settings"]["default"]
    assert (aggregate["runs"], aggregate["finished"], aggregate["not_run"]) == (5, 2, 3)
    empty = tmp_path / "empty" / "default" / "seed-0"
    empty.mkdir(parents=True)
    assert build.export_sweep(tmp_path / "empty") is None
    with pytest.raises(ValueError, match="not a directory"):
        build.export_sweep(tmp_path / "missing")
    assert build.portable_command(["x", "--output=/a/b"]) == ["x", "--output=DIR"]


def test_old_and_broken_exports_are_refused(sweep, tmp_path):
    data = build.export_sweep(sweep)
    old = {k: v for k, v in data.items() if k not in ("format", "settings")}
    with pytest.raises(ValueError, match="format None"):
        build.check_export(old, "old.json")
    broken = copy.deepcopy(data)
    del broken["runs"][0]["seconds"]
    with pytest.raises(ValueError, match=r"runs\[0\] lacks seconds"):
        build.check_export(broken, "broken.json")
    with pytest.raises(TypeError, match="JSON object"):
        build.check_export([], "list.json")
    (tmp_path / "other.json").write_text(json.dumps(data))
    with pytest.raises(ValueError, match="holds task 'reacher'"):
        build.load_exports(tmp_path)


# ------------------------------------------------------------------------- the table
ROW = {"task": "reacher", "label": "reacher (healthy arm)", "rule": "within 5 cm",
       "goal": "≥ 19/20", "more": "more text"}


def _export(successes, failures, *, cpus=("AMD EPYC",), seconds=(100.0, 200.0, 300.0)):
    runs = []
    for k in range(successes + failures):
        summary = _summary(k, success=k < successes, solved_at=3 if k < successes else None,
                           total=seconds[k % len(seconds)], cpu=cpus[k % len(cpus)])
        runs.append(build.trim_run(summary, "default"))
    data = {"format": build.FORMAT, "task": "reacher", "command": ["python", "-m", "x"],
            "seeds": list(range(successes + failures)), "failed": {}, "runs": runs}
    data["settings"] = build.aggregates(data)
    return data


def test_row_counts_medians_and_cpu_come_from_the_data():
    cells = build.table_row(ROW, {"reacher": _export(2, 1)})
    assert cells == ["reacher (healthy arm)", "within 5 cm", "0-2",
                     "**2/3**, solved at episode 3 median", "more text", "200 s on AMD EPYC",
                     "≥ 19/20"]


def test_row_of_mixed_cpus_unsolved_runs_and_a_partial_sweep(sweep):
    cells = build.table_row(ROW, {"reacher": build.export_sweep(sweep)})
    assert cells[2] == "0-4"
    assert cells[3] == "**1/2**, 1 of 2 never solved (1 failed, 2 not finished, not counted)"
    assert cells[5] == "200 s on AMD EPYC (1 run), Intel(R) Xeon(R) Processor (1 run)"
    nothing = build.table_row(ROW, {"reacher": _export(0, 2)})
    assert nothing[3] == "**0/2**, none solved"


def test_row_of_runs_without_provenance_says_so():
    data = _export(1, 1)
    for run in data["runs"]:
        del run["provenance"]
    data["settings"] = build.aggregates(data)
    cells = build.table_row(ROW, {"reacher": data})
    assert cells[5] == "150 s (CPU not recorded)"
    line = build.source_line(ROW, data)
    assert "commit not recorded" in line and "`TF_ENABLE_ONEDNN_OPTS`: not recorded" in line


def test_manual_row_is_marked_and_a_missing_export_named(tmp_path):
    manual = {**ROW, "task": "pendulum", "label": "pendulum",
              "manual": {"seeds": "0-19", "result": "16/20", "per_run": "261 s",
                         "note": "not exported"}}
    table = build.render_table([ROW, manual], {"reacher": _export(2, 1)}, directory=tmp_path)
    lines = table.splitlines()
    assert lines[0].startswith("| experiment | success rule | seeds | result |")
    assert lines[3] == ("| pendulum | within 5 cm | 0-19 | 16/20 † | more text | 261 s † "
                        "| ≥ 19/20 |")
    assert "† pendulum: typed into results/table.json, not computed from committed data: " \
           "not exported" in table
    assert "- reacher (healthy arm): `results/reacher.json`, `python -m x`" in table
    with pytest.raises(ValueError, match="marked manual"):
        build.table_row({**manual, "task": "reacher"}, {"reacher": _export(1, 0)})
    with pytest.raises(FileNotFoundError, match="ghost.json: no such file"):
        build.table_row({**ROW, "task": "ghost"}, {}, directory=tmp_path)
    with pytest.raises(ValueError, match="no setting 'wide'"):
        build.table_row({**ROW, "setting": "wide"}, {"reacher": _export(1, 0)})


def test_a_variant_export_backs_its_own_row(sweep, tmp_path):
    """A second sweep of a task (e.g. with oneDNN off) is ``<task>--<variant>.json``, read
    by a table row through its ``data`` key, with its own command and counts."""
    out = tmp_path / "results"
    out.mkdir()
    assert build.export_main([str(sweep)], directory=out) == 0
    assert build.export_main([str(sweep)], directory=out, variant="onednn-off") == 0
    assert sorted(p.name for p in out.iterdir()) == ["reacher--onednn-off.json",
                                                    "reacher.json"]
    exports = build.load_exports(out)
    assert set(exports) == {"reacher", "reacher--onednn-off"}
    variant = {**ROW, "label": "reacher, oneDNN off", "data": "reacher--onednn-off"}
    path = tmp_path / "table.json"
    path.write_text(json.dumps({"rows": [ROW, variant]}), encoding="utf-8")
    rows = build.load_table(path)
    table = build.render_table(rows, exports, directory=out)
    assert "- reacher, oneDNN off: `results/reacher--onednn-off.json`" in table
    assert build.table_row(variant, exports, directory=out)[3].startswith("**1/2**")
    drawn = build.draw_figures(exports["reacher--onednn-off"], directory=tmp_path,
                               name="reacher--onednn-off")
    assert sorted(os.path.basename(p) for p in drawn) == [
        "reacher--onednn-off_distance_bands.png", "reacher--onednn-off_success_rate.png"]
    # a variant's file must hold its task, and a row's data must be an export of its task
    (out / "cartpole--x.json").write_text((out / "reacher.json").read_text())
    with pytest.raises(ValueError, match="holds task 'reacher'"):
        build.load_exports(out)
    path.write_text(json.dumps({"rows": [{**ROW, "data": "cartpole--x"}]}))
    with pytest.raises(ValueError, match="not an export of task 'reacher'"):
        build.load_table(path)
    with pytest.raises(ValueError, match="bad variant name"):
        build.export_main([str(sweep)], directory=out, variant="a/b")
    with pytest.raises(ValueError, match="one sweep directory"):
        build.export_main([str(sweep), str(sweep)], directory=out, variant="v")


@pytest.mark.parametrize("rows, error, match", [
    ([{**ROW, "colour": "red"}], ValueError, "unknown key"),
    ([{k: v for k, v in ROW.items() if k != "goal"}], ValueError, "'goal' must be"),
    ([ROW, ROW], ValueError, "has a row already"),
    ([{**ROW, "manual": {"seeds": "0-19"}}], ValueError, "'manual' must have"),
    ([{**ROW, "more": 3}], TypeError, "'more' must be a string"),
    ([[]], TypeError, "not an object"),
])
def test_bad_table_rows_are_named(tmp_path, rows, error, match):
    path = tmp_path / "table.json"
    path.write_text(json.dumps({"rows": rows}), encoding="utf-8")
    with pytest.raises(error, match=match):
        build.load_table(path)


def test_table_file_missing_or_malformed(tmp_path):
    with pytest.raises(FileNotFoundError, match="table.json: no such file"):
        build.load_table(tmp_path / "table.json")
    (tmp_path / "table.json").write_text("[]")
    with pytest.raises(TypeError, match="rows"):
        build.load_table(tmp_path / "table.json")


def test_with_table_replaces_only_the_marked_block():
    text = f"# t\n\nabove\n{build.BEGIN_PREFIX} old -->\n| old |\n{build.END}\nbelow\n"
    new = build.with_table(text, "| new |\n\n")
    assert new == f"# t\n\nabove\n{build.BEGIN}\n| new |\n\n{build.END}\nbelow\n"
    with pytest.raises(ValueError, match="one line starting"):
        build.with_table("no markers\n", "| new |\n")
    with pytest.raises(ValueError, match="one line starting"):
        build.with_table(f"{build.END}\n{build.BEGIN}\n", "| new |\n")


def test_seed_ranges():
    assert build.seed_ranges([7, 0, 1, 2, 5, 8]) == "0-2, 5, 7-8"
    assert build.seed_ranges([3]) == "3"
    assert build.seed_ranges([]) == ""


def test_figures_are_drawn_from_an_export(sweep, tmp_path):
    drawn = build.draw_figures(build.export_sweep(sweep), directory=tmp_path)
    assert [os.path.basename(p) for p in drawn] == ["reacher_success_rate.png",
                                                    "reacher_distance_bands.png"]
    assert all(Path(p).read_bytes().startswith(b"\x89PNG") for p in drawn)


def test_the_adaptation_row_counts_recoveries_against_learning_from_scratch():
    """An adaptation export's row: the median damaged episodes to reach again, and beside
    it the same seeds' first solved episode in the from-scratch export ('scratch')."""
    runs = []
    for seed, recover in enumerate([1, 1, 2, None]):
        summary = _summary(seed, success=recover is not None and recover <= 3,
                           solved_at=3, total=100.0)
        summary.update(healthy_reached_at_episode=2 + seed % 2, damage_at_episode=4,
                       episodes_to_recover=recover)
        runs.append(build.trim_run(summary, "default"))
    adapted = {"format": build.FORMAT, "task": "adaptation", "command": ["x"],
               "seeds": [0, 1, 2, 3], "failed": {}, "runs": runs}
    adapted["settings"] = build.aggregates(adapted)
    scratch = _export(3, 2)  # seeds 0-2 solved at episode 3, 3-4 never
    row = dict(ROW, task="adaptation", scratch="reacher")
    cells = build.table_row(row, {"adaptation": adapted, "reacher": scratch})
    assert cells[3] == "**3/4**, recovered after 1.5 damaged episode(s) median"
    assert cells[4] == ("more text; on the damaged arm: 1.5 episode(s) median to reach "
                        "again, against 3 learning from scratch (`reacher`, the same 4 "
                        "seeds)")
    pairs = build.paired_recovery(adapted, scratch)
    assert [(p["seed"], p["healthy_reached_at_episode"], p["episodes_to_recover"],
             p["scratch_solved_at_episode"]) for p in pairs] == [
        (0, 2, 1, 3), (1, 3, 1, 3), (2, 2, 2, 3), (3, 3, None, None)]
    assert "| 3 | 3 | never | never |" in build.pairs_table(adapted, scratch)
    with pytest.raises(FileNotFoundError, match="damaged_reacher"):
        build.table_row(dict(row, scratch="damaged_reacher"), {"adaptation": adapted})


def test_runs_on_a_constraint_keep_their_risks_and_draw_a_calibration(sweep, tmp_path):
    """An episode's predicted risk, real violation and whether its policy ran survive the
    export (Safe PILCO's other per-episode notes do not); the export's aggregate has the
    calibration, and its figures include it."""
    path = sweep / "default" / "seed-0" / "summary.json"
    summary = json.loads(path.read_text())
    summary["episodes"][0]["violated"] = True
    summary["episodes"][1].update(
        violated=False, predicted_risk={"independent": 0.02, "union": 0.03},
        safety={"executed": True, "risk": 0.02, "tries": [{"weight": 50.0}]})
    summary["safety"] = {"learned": 1, "executed": 1, "executed_violated": 0,
                         "random_violated": 1, "executed_risks": [0.02]}
    path.write_text(json.dumps(summary))
    data = build.export_sweep(sweep)
    first = data["runs"][0]["episodes"]
    assert first[0]["violated"] is True and "predicted_risk" not in first[0]
    assert first[1]["predicted_risk"] == {"independent": 0.02, "union": 0.03}
    assert first[1]["safety"] == {"executed": True}
    calibration = data["settings"]["default"]["safety"]["calibration"]
    assert [(b["episodes"], b["violated"]) for b in calibration["independent"]] == [(1, 0)]
    drawn = build.draw_figures(data, directory=tmp_path)
    assert [os.path.basename(p) for p in drawn][-1] == "reacher_risk_calibration.png"
    # the other runs' episodes are as before: no constraint fields
    assert set(data["runs"][1]["episodes"][1]) == set(build.EPISODE_FIELDS)
