"""pilco.sweep without Ray: statistics on hand-made summaries, argument checks, figures."""
from __future__ import annotations

import math
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from pilco.sweep import aggregate, cli, figures, flags, runs
from pilco.tasks import TASKS, build_parser

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def summary(seed, solved_at=None, success=None, episodes=3, final=0.5, minimum=0.2,
            steps_to_target=None, total=10.0, distances=None, **extra):
    """A run summary like the tasks write (``success`` left out when None)."""
    recs = [{"episode": k, "random": k == 1, "steps": 5, "cost": 1.0,
             "final_distance": 1.0, "min_distance": 0.9, "steps_to_target": None,
             "seconds": {"interaction": 0.1, "model": 0.2, "policy": 0.3}}
            for k in range(1, episodes + 1)]
    recs[-1].update(final_distance=final, min_distance=minimum,
                    steps_to_target=steps_to_target)
    s = {"task": "cartpole", "seed": seed, "solved": solved_at is not None,
         "solved_at_episode": solved_at, "episodes": recs,
         "seconds": {"interaction": 0.3, "model": 0.6, "policy": 0.9, "total": total}, **extra}
    if success is not None:
        s["success"] = success
    if distances is not None:
        s["distances"] = distances
    return s


# ------------------------------------------------------------------------------ Wilson
def test_wilson_interval_known_values():
    z2 = aggregate.WILSON_Z95 ** 2
    low, high = aggregate.wilson_interval(0, 20)
    assert low == 0.0
    assert high == pytest.approx(z2 / (20 + z2), rel=1e-12)
    assert high == pytest.approx(0.161125, abs=1e-6)
    low, high = aggregate.wilson_interval(20, 20)
    assert high == 1.0
    assert low == pytest.approx(20 / (20 + z2), rel=1e-12)
    assert low == pytest.approx(0.838875, abs=1e-6)
    low, high = aggregate.wilson_interval(10, 20)
    assert low == pytest.approx(0.299298, abs=1e-6)
    assert high == pytest.approx(0.700702, abs=1e-6)
    assert low + high == pytest.approx(1.0, rel=1e-14)


def test_wilson_interval_contains_rate_and_shrinks_with_runs():
    for k, n in [(1, 3), (7, 10), (3, 40)]:
        low, high = aggregate.wilson_interval(k, n)
        assert 0.0 <= low < k / n < high <= 1.0
    wide = aggregate.wilson_interval(5, 10)
    narrow = aggregate.wilson_interval(50, 100)
    assert narrow[1] - narrow[0] < wide[1] - wide[0]


def test_wilson_interval_rejects_bad_counts():
    with pytest.raises(ValueError, match="successes <= runs"):
        aggregate.wilson_interval(3, 2)
    with pytest.raises(ValueError, match="successes <= runs"):
        aggregate.wilson_interval(-1, 2)
    with pytest.raises(TypeError, match="booleans"):
        aggregate.wilson_interval(True, 2)
    assert all(math.isnan(v) for v in aggregate.wilson_interval(0, 0))


# --------------------------------------------------------------------------- quartiles
def test_quantiles_match_numpy_on_finite_values():
    rng = np.random.default_rng(0)
    xs = rng.standard_normal(11)
    for q in (0.0, 0.25, 0.5, 0.75, 1.0):
        assert aggregate.quantile(xs, q) == pytest.approx(np.quantile(xs, q), rel=1e-12)
    assert aggregate.quartiles([1, 2, 3, 4]) == {"q1": 1.75, "median": 2.5, "q3": 3.25}
    assert aggregate.quartiles([]) == {"q1": None, "median": None, "q3": None}


def test_quantile_with_unsolved_runs_is_infinite_once_they_weigh_in():
    xs = [2, 3, math.inf, math.inf]
    assert aggregate.quantile(xs, 0.25) == 2.75
    assert aggregate.quantile(xs, 0.5) == math.inf
    assert aggregate.quartiles(xs) == {"q1": 2.75, "median": None, "q3": None}
    with pytest.raises(ValueError, match="NaN"):
        aggregate.quantile([1.0, math.nan], 0.5)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        aggregate.quantile([1.0], 1.5)


# ------------------------------------------------------------------------- aggregates
def test_episodes_to_solve_counts_unsolved_runs():
    runs_ = [summary(0, solved_at=2), summary(1, solved_at=3), summary(2, solved_at=4),
             summary(3)]
    r = aggregate.aggregate_setting(runs_)
    assert r["episodes_to_solve"] == {"q1": 2.75, "median": 3.5, "q3": None,
                                      "solved": 3, "unsolved": 1}
    assert r["successes"] == 3
    assert r["success_rate"] == 0.75
    assert r["success_ci95"] == list(aggregate.wilson_interval(3, 4))


def test_success_falls_back_to_solved():
    assert aggregate.run_success(summary(0, solved_at=2)) is True
    assert aggregate.run_success(summary(0)) is False
    # the task's own rule wins over the solved flag, both ways
    assert aggregate.run_success(summary(0, solved_at=2, success=False)) is False
    assert aggregate.run_success(summary(0, success=True)) is True
    with pytest.raises(ValueError, match="neither"):
        aggregate.run_success({"task": "cartpole"})
    r = aggregate.aggregate_setting([summary(0, solved_at=2, success=False),
                                     summary(1, success=True), summary(2, solved_at=3)])
    assert r["successes"] == 2


def test_aggregate_fields():
    runs_ = [summary(0, final=0.1, minimum=0.05, steps_to_target=4, total=10.0),
             summary(1, final=0.3, minimum=0.1, steps_to_target=8, total=30.0),
             summary(2, final=0.2, minimum=0.2, total=20.0)]
    r = aggregate.aggregate_setting(runs_, runs=5, failed=1, not_run=1)
    assert (r["runs"], r["finished"], r["failed"], r["not_run"]) == (5, 3, 1, 1)
    assert r["last_episode"]["steps_to_target"] == {"median": 6.0, "reached": 2,
                                                     "not_reached": 1}
    assert r["last_episode"]["final_distance"] == pytest.approx(
        {"q1": 0.15, "median": 0.2, "q3": 0.25})
    assert r["last_episode"]["min_distance"]["median"] == 0.1
    assert r["seconds_per_run"] == {"median": 20.0, "max": 30.0}
    assert "episodes_to_recover" not in r
    empty = aggregate.aggregate_setting([], runs=2, failed=2)
    assert empty["success_rate"] is None and empty["success_ci95"] is None
    assert empty["finished"] == 0 and empty["failed"] == 2


def test_provenance_counts_commits_cpus_and_onednn_settings():
    def prov(commit, dirty=False, cpu="cpu A", onednn=None):
        env = {} if onednn is None else {"TF_ENABLE_ONEDNN_OPTS": onednn}
        git = None if commit is None else {"commit": commit, "dirty": dirty}
        return {"git": git, "cpu": cpu, "environment": env}

    runs_ = [summary(0, provenance=prov("a" * 40)),
             summary(1, provenance=prov("a" * 40, onednn="0")),
             summary(2, provenance=prov("b" * 40, dirty=True, cpu="cpu B")),
             summary(3, provenance=prov(None)),
             summary(4)]
    r = aggregate.aggregate_setting(runs_)["provenance"]
    assert r["commit"] == {"a" * 12: 2, "b" * 12 + "-dirty": 1, "not a git checkout": 1,
                           "unknown": 1}
    assert r["cpu"] == {"cpu A": 3, "cpu B": 1, "unknown": 1}
    assert r["onednn"] == {"default": 3, "0": 1, "unknown": 1}


def test_adaptation_adds_episodes_to_recover():
    runs_ = [summary(0, episodes_to_recover=1, damage_at_episode=3),
             summary(1, episodes_to_recover=None, damage_at_episode=3),
             summary(2, episodes_to_recover=3, damage_at_episode=4)]
    r = aggregate.aggregate_setting(runs_)["episodes_to_recover"]
    assert r == {"q1": 2.0, "median": 3.0, "q3": None, "recovered": 2, "not_recovered": 1}


def test_safe_runs_add_their_safety_counts():
    runs_ = [summary(0, safety={"learned": 5, "executed": 4, "executed_violated": 0,
                                "random_violated": 4, "executed_risks": [0.03, 0.04, 0.05, 0.06]}),
             summary(1, safety={"learned": 5, "executed": 2, "executed_violated": 1,
                                "random_violated": 5, "executed_risks": [0.01, 0.02]})]
    r = aggregate.aggregate_setting(runs_)["safety"]
    assert (r["learned"], r["executed"], r["executed_violated"], r["random_violated"]) == (
        10, 6, 1, 9)
    assert r["executed_risk"]["max"] == 0.06 and r["executed_risk"]["median"] == 0.035
    assert "safety" not in aggregate.aggregate_setting([summary(2)])
    table = aggregate.format_table({"mu=50": aggregate.aggregate_setting(runs_)})
    assert ("safety: 6 of 10 learned episodes ran, 1 of them broke the constraint (random "
            "episodes: 9); predicted risk of those that ran: median 0.035, max 0.060") in table


def risk_records(pairs, executed=True):
    """Learned episodes' records with ``predicted_risk`` (both rules: union = 1.5 x the
    product, capped) and ``violated``; one random episode first."""
    base = {"final_distance": 1.0, "min_distance": 0.9, "steps_to_target": None}
    records = [{**base, "random": True, "violated": True}]
    for risk, violated in pairs:
        record = {**base, "random": False, "violated": violated,
                  "predicted_risk": {"independent": risk, "union": min(1.0, 1.5 * risk)}}
        if executed is not None:
            record["safety"] = {"executed": executed}
        records.append(record)
    return records


def test_risk_calibration_bins_the_executed_episodes():
    """Executed learned episodes are binned by predicted risk (bins [low, high), the last
    closed); random episodes and episodes whose policy did not run are left out; the
    rate and its Wilson interval are the bin's own."""
    a = summary(0, episodes=4)
    a["episodes"] = risk_records([(0.0, False), (0.004, False), (0.03, True), (1.0, True)])
    b = summary(1, episodes=3)
    b["episodes"] = risk_records([(0.002, True), (0.6, False)], executed=None)  # no loop
    b["episodes"] += risk_records([(0.003, True)], executed=False)[1:]  # braked: left out
    bins = aggregate.risk_calibration([a, b])
    assert [(x["low"], x["high"], x["episodes"], x["violated"]) for x in bins] == [
        (0.0, 0.01, 3, 1), (0.01, 0.05, 1, 1), (0.5, 0.8, 1, 0), (0.95, 1.0, 1, 1)]
    assert bins[0]["rate"] == pytest.approx(1 / 3)
    assert bins[0]["mean_risk"] == pytest.approx(0.002)
    assert bins[0]["ci95"] == pytest.approx(list(aggregate.wilson_interval(1, 3)))
    union = aggregate.risk_calibration([a, b], "union")
    assert [x["episodes"] for x in union] == [3, 1, 1, 1]  # 0.045 still below 0.05
    assert aggregate.risk_calibration([summary(2)]) == []
    from pilco.constraints import COMBINE

    assert sorted(aggregate.RISK_RULES) == sorted(COMBINE)  # the rules the records hold
    with pytest.raises(ValueError, match="increasing"):
        aggregate.risk_calibration([a], edges=[0.0, 0.5, 0.5])
    a["safety"] = {"learned": 4, "executed": 4, "executed_violated": 2,
                   "random_violated": 1, "executed_risks": []}
    r = aggregate.aggregate_setting([a])["safety"]["calibration"]
    assert r["independent"] == aggregate.risk_calibration([a])


def test_the_risk_calibration_figure(tmp_path):
    a = summary(0, episodes=3)
    a["episodes"] = risk_records([(0.02, False), (0.9, True)])
    path = figures.risk_calibration_figure({"safe": [a]}, str(tmp_path / "cal.png"))
    assert path and os.path.getsize(path) > 0
    # no run records a predicted risk: no figure
    assert figures.risk_calibration_figure({"a": [summary(0)]}, str(tmp_path / "x.png")) is None
    assert not (tmp_path / "x.png").exists()


def test_solved_by_episode_and_table():
    runs_ = [summary(0, solved_at=2), summary(1, solved_at=3), summary(2)]
    assert aggregate.solved_by_episode(runs_, 4) == pytest.approx([0.0, 1 / 3, 2 / 3, 2 / 3])
    table = aggregate.format_table({"default": aggregate.aggregate_setting(runs_)})
    assert "default" in table and "0.67 [" in table


# --------------------------------------------------------------------------- arguments
def test_parse_seeds():
    assert flags.parse_seeds("0-3") == [0, 1, 2, 3]
    assert flags.parse_seeds("5,0,3") == [0, 3, 5]
    assert flags.parse_seeds("0-2,10,12-13,1") == [0, 1, 2, 10, 12, 13]
    for bad in ("", "3-1", "a", "1-", "-1", "1,,2", "0-2-4"):
        with pytest.raises(ValueError):
            flags.parse_seeds(bad)


def test_assignments_and_flags():
    assert flags.parse_assignment("horizon=30") == ("horizon", "30")
    assert flags.parse_assignment("policy-iters=3") == ("policy_iters", "3")
    assert flags.parse_assignment("cost_width=0.2,0.3", grid=True) == ("cost_width", ["0.2", "0.3"])
    for bad in ("horizon", "=3", "horizon=", "1x=2", "seed=3", "output=x"):
        with pytest.raises(ValueError):
            flags.parse_assignment(bad)
    with pytest.raises(ValueError, match="repeated"):
        flags.parse_assignment("horizon=3,3", grid=True)
    parser = build_parser("cartpole")
    assert parser is not None
    assert flags.setting_flags("horizon", "30", parser) == ["--horizon", "30"]
    assert flags.setting_flags("retrain_unchanged_model", "true", parser) == \
        ["--retrain-unchanged-model"]
    assert flags.setting_flags("retrain_unchanged_model", "false", parser) == []
    with pytest.raises(ValueError, match="takes no value"):
        flags.setting_flags("retrain_unchanged_model", "3", parser)
    with pytest.raises(ValueError, match="no flag --bogus"):
        flags.setting_flags("bogus", "1", parser)
    # a flag that is on by default (--key/--no-key): false turns it off
    adaptation = build_parser("adaptation")
    assert flags.setting_flags("stop_stuck_joints", "false", adaptation) == \
        ["--no-stop-stuck-joints"]
    assert flags.setting_flags("stop_stuck_joints", "true", adaptation) == \
        ["--stop-stuck-joints"]
    # without the task's parser: true/false are flags without value
    assert flags.setting_flags("no_early_stop", "true", None) == ["--no-early-stop"]
    assert flags.setting_flags("horizon", "30", None) == ["--horizon", "30"]


def test_grid_settings_and_labels():
    parser = build_parser("cartpole")
    combos = flags.settings([("horizon", "30")], [("max_force", ["5", "10"]),
                                                ("squash", ["sat", "sin"])], parser)
    assert [label for label, _ in combos] == [
        "horizon=30,max_force=5,squash=sat", "horizon=30,max_force=5,squash=sin",
        "horizon=30,max_force=10,squash=sat", "horizon=30,max_force=10,squash=sin"]
    assert combos[1][1] == ["--horizon", "30", "--max-force", "5", "--squash", "sin"]
    assert flags.settings([], [], parser) == [("default", [])]
    with pytest.raises(ValueError, match="more than once"):
        flags.settings([("horizon", "3")], [("horizon", ["4", "5"])], parser)


def test_plan_builds_run_directories(tmp_path):
    args = cli.build_parser().parse_args(["cartpole", "--seeds", "0,2", "--output",
                                          str(tmp_path), "--grid", "horizon=4,5"])
    specs, described = cli.plan(args, ["--episodes", "2"])
    assert [s.directory for s in specs] == [
        os.path.join(str(tmp_path), label, f"seed-{seed}")
        for label in ("horizon=4", "horizon=5") for seed in (0, 2)]
    assert specs[0].flags == ("--horizon", "4", "--episodes", "2")
    assert specs[0].command()[2:] == ["pilco.tasks", "cartpole", "--seed", "0", "--output",
                                      specs[0].directory, "--quiet", "--no-render",
                                      "--no-figures", "--horizon", "4", "--episodes", "2"]
    assert described[1] == {"label": "horizon=5", "flags": ["--horizon", "5", "--episodes", "2"]}


@pytest.mark.parametrize("command, message", [
    # a value its flag accepts (an integer >= 0) that the settings' check refuses
    (["cartpole", "--grid", "max_data=0,1"],
     "setting max_data=1: cartpole rejects its flags: max_data must be at least 2"),
    # two settings the task refuses together (its own check)
    (["adaptation", "--set", "changed_output_noise=1e6"],
     "--stop-stuck-joints (the default) and --changed-output-noise"),
    (["cartpole", "--set", "horizon=0"], "argument --horizon: must be at least 1"),
])
def test_plan_refuses_a_setting_every_run_would_refuse(command, message, tmp_path):
    """The sweep reads each setting as its runs will, before any run starts."""
    args = cli.build_parser().parse_args([*command, "--seeds", "0-1", "--output",
                                          str(tmp_path)])
    with pytest.raises(ValueError, match=re.escape(message)):
        cli.plan(args, [])


def test_the_sweep_takes_the_tasks_of_pilco_tasks():
    """The sweep's help names every task of :data:`pilco.tasks.TASKS`; a task's parser
    comes from :func:`pilco.tasks.build_parser`, which names the tasks for an unknown one."""
    help_text = " ".join(cli.build_parser().format_help().split())
    assert f"one of: {', '.join(TASKS)}" in help_text
    with pytest.raises(ValueError, match=re.escape(f"unknown task 'nope'; choose one of "
                                                   f"{', '.join(TASKS)}")):
        build_parser("nope")


def test_the_sweeps_ray_tasks_import_no_tensorflow():
    """A Ray worker imports the module of its task, :mod:`pilco.sweep.runs`, and only
    starts and watches a run's process: it loads no TensorFlow, GPflow or TensorFlow
    Probability; the run's own process does."""
    code = ("import sys\n"
            "import pilco.sweep.runs\n"
            "print(sorted(m for m in ('tensorflow', 'gpflow', 'tensorflow_probability')\n"
            "             if m in sys.modules))\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [ROOT, *filter(None, [os.environ.get("PYTHONPATH")])]))
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip().splitlines()[-1] == "[]"


def test_pendulum_is_a_sweep_task(tmp_path):
    """The help and the flag checks know the pendulum task."""
    assert "pendulum" in cli.build_parser().format_help()
    args = cli.build_parser().parse_args(["pendulum", "--seeds", "0-1", "--output",
                                          str(tmp_path), "--set", "threshold=0.2"])
    specs, _ = cli.plan(args, ["--episodes", "5"])
    assert specs[1].command()[2:] == ["pilco.tasks", "pendulum", "--seed", "1", "--output",
                                      specs[1].directory, "--quiet", "--no-render",
                                      "--no-figures", "--threshold", "0.2", "--episodes", "5"]
    with pytest.raises(ValueError, match="no flag --max-force"):  # a cart-pole flag
        cli.plan(cli.build_parser().parse_args(
            ["pendulum", "--output", str(tmp_path), "--set", "max_force=3"]), [])


@pytest.mark.parametrize("argv, message", [
    (["nope"], "unknown task"),
    (["cartpole", "--seeds", "5-2"], "backwards"),
    (["cartpole", "--set", "horizon"], "not KEY=VALUE"),
    (["cartpole", "--set", "bogus=1"], "no flag --bogus"),
    (["cartpole", "--grid", "horizon=4,x"], "expected an integer"),
    (["cartpole", "--set", "basis_functions=0"], "--basis-functions: must be at least 1"),
    (["cartpole", "--", "--seed", "3"], "set by the sweep"),
    (["cartpole", "--", "--not-a-flag"], "unrecognized arguments"),
    (["cartpole", "--max-retries", "-1"], "max-retries"),
    (["cartpole", "--log-level", "loud"], "--log-level: invalid log_level value: 'loud'"),
])
def test_bad_arguments_fail_before_ray(argv, message, monkeypatch, capsys, tmp_path):
    def no_ray(*_):
        raise AssertionError("Ray must not start for bad arguments")

    monkeypatch.setattr(cli, "_start_ray", no_ray)
    with pytest.raises(SystemExit) as stop:
        cli.main([*argv[:1], "--output", str(tmp_path), *argv[1:]])
    assert stop.value.code == 2
    assert message in capsys.readouterr().err


def test_resume_refuses_a_directory_of_other_flags(tmp_path):
    spec = runs.RunSpec("cartpole", 0, "default", ("--horizon", "5"), str(tmp_path))
    assert runs.finished_summary(spec) is None
    from pilco.files import write_json_atomic

    write_json_atomic(str(tmp_path / runs.SUMMARY), summary(0))
    assert runs.finished_summary(spec)["seed"] == 0
    write_json_atomic(str(tmp_path / runs.RUN_RECORD),
                      {"flags": ["--horizon", "6"], "status": "finished"})
    with pytest.raises(ValueError, match="--horizon 6"):
        runs.finished_summary(spec)
    write_json_atomic(str(tmp_path / runs.RUN_RECORD),
                      {"flags": ["--horizon", "5"], "status": "finished"})
    write_json_atomic(str(tmp_path / runs.SUMMARY), {**summary(0), "complete": False})
    assert runs.finished_summary(spec) is None  # an interrupted run is run again
    for status in ("pending", "failed", "interrupted"):  # what such a run left behind
        write_json_atomic(str(tmp_path / runs.SUMMARY), summary(0))
        write_json_atomic(str(tmp_path / runs.RUN_RECORD),
                          {"flags": ["--horizon", "5"], "status": status})
        assert runs.finished_summary(spec) is None
    write_json_atomic(str(tmp_path / runs.RUN_RECORD),
                      {"flags": ["--horizon", "5"], "status": "finished"})
    assert runs.finished_summary(spec)["seed"] == 0
    write_json_atomic(str(tmp_path / runs.SUMMARY), {**summary(0), "episodes": []})
    assert runs.finished_summary(spec) is None
    write_json_atomic(str(tmp_path / runs.SUMMARY), summary(1))
    with pytest.raises(ValueError, match="seed 1"):
        runs.finished_summary(spec)


# ----------------------------------------------------------------------------- figures
def test_figures(tmp_path):
    d = [[1.0, 0.8, 0.5], [1.0, 0.5, 0.2, 0.1]]
    with_distances = {"a": [summary(0, solved_at=2, episodes=2, distances=d),
                            summary(1, episodes=2, distances=[[1.0, 0.9], [1.0, 0.7, 0.4]])],
                      "b": [summary(0, episodes=2, distances=d)]}
    q = figures.distance_quartiles(with_distances["a"], 2)
    assert q.shape == (3, 4)
    np.testing.assert_allclose(q[1], [1.0, 0.6, 0.3, 0.1])
    assert figures.distance_quartiles(with_distances["a"], 3).shape == (3, 0)
    path = figures.success_rate_figure(with_distances, str(tmp_path / "rate.png"))
    assert path and os.path.getsize(path) > 0
    path = figures.distance_bands_figure(with_distances, str(tmp_path / "bands.png"))
    assert path and os.path.getsize(path) > 0
    # summaries without per-step distances: no figure
    assert figures.distance_bands_figure({"a": [summary(0)]}, str(tmp_path / "x.png")) is None
    assert not (tmp_path / "x.png").exists()
    assert figures.success_rate_figure({"a": []}, str(tmp_path / "y.png")) is None


def test_solved_in_episode_falls_when_runs_drop_what_they_learned():
    from pilco.sweep.aggregate import solved_by_episode, solved_in_episode

    runs = [{"solved_at_episode": 2, "solved_episodes": [2, 4]},  # dropped in episode 3
            {"solved_at_episode": 3, "solved_episodes": [3, 4]},
            {"solved_at_episode": None, "solved_episodes": []}]
    assert solved_in_episode(runs, 4) == [0.0, 1 / 3, 1 / 3, 2 / 3]
    assert solved_by_episode(runs, 4) == [0.0, 1 / 3, 2 / 3, 2 / 3]
    assert solved_in_episode([{"solved_at_episode": 2}], 3) is None  # older summaries
