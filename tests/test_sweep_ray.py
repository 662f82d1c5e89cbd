"""pilco.sweep on a local Ray: a tiny cart-pole sweep, its resume, a failing setting.

One Ray instance (2 CPUs) serves the module; the runs are tiny (2 episodes of 5 steps).
The task is the cart-pole as a module outside the package whose runs fail at run time
for one setting (settings the task refuses fail the sweep before any run: test_sweep.py).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import textwrap

import pytest

ray = pytest.importorskip("ray")

from pilco.sweep import aggregate, cli, runs  # noqa: E402 - after the skip

TINY = ["--", "--episodes", "2", "--horizon", "5", "--policy-iters", "1", "--model-iters",
        "2", "--basis-functions", "3"]


#: the cart-pole, except that its environment cannot be made for a force above 50 N
FAILING_TASK = textwrap.dedent('''
    from pilco.tasks.cartpole import CartPoleTask


    class FailingCartPole(CartPoleTask):
        def make_env(self, s, config):
            if s.max_force > 50:
                raise RuntimeError("no motor gives a force above 50 N")
            return super().make_env(s, config)


    TASK = FailingCartPole()
''')
TASK = "failing_cartpole:TASK"


@pytest.fixture(scope="module")
def local_ray(tmp_path_factory):
    """A local Ray, and the failing task importable here (its runs get its directory on
    their PYTHONPATH from the sweep)."""
    where = tmp_path_factory.mktemp("task")
    (where / "failing_cartpole.py").write_text(FAILING_TASK)
    sys.path.insert(0, str(where))
    started, _ = cli._start_ray(argparse.Namespace(address=None, num_cpus=2))
    yield
    if started:
        ray.shutdown()
    sys.path.remove(str(where))
    sys.modules.pop("failing_cartpole", None)


# max_force=60 passes every check of the settings; its runs fail when they make the env
COMMAND = [TASK, "--seeds", "0-1", "--no-progress", "--max-retries", "0",
           "--grid", "max_force=10,60"]
OK, BAD = "max_force=10", "max_force=60"


def load(path):
    with open(path, encoding="utf-8") as fh:
        return json.load(fh)


@pytest.fixture(scope="module")
def sweep(tmp_path_factory, local_ray):
    """A 2-seed sweep of a good and a failing setting: (directory, exit status, report)."""
    out = tmp_path_factory.mktemp("sweep")
    code = cli.main([*COMMAND, "--output", str(out), *TINY])
    return out, code, load(out / "sweep.json")


def test_sweep_runs_every_seed_and_aggregates_their_summaries(sweep):
    out, code, report = sweep
    assert code == 1  # some runs failed
    summaries = [load(out / OK / f"seed-{s}" / "summary.json") for s in (0, 1)]
    assert [s["seed"] for s in summaries] == [0, 1]
    assert all(len(s["episodes"]) == 2 for s in summaries)
    assert report["task"] == TASK and report["seeds"] == [0, 1]
    assert report["interrupted"] is False
    assert [(r["setting"], r["status"]) for r in report["runs"]] == [
        (OK, "finished"), (OK, "finished"), (BAD, "failed"), (BAD, "failed")]
    expected = json.loads(json.dumps(aggregate.aggregate_setting(summaries, runs=2)))
    assert report["results"][OK] == expected
    assert report["results"][OK]["finished"] == 2
    record = load(out / OK / "seed-1" / "sweep-run.json")
    assert record["status"] == "finished" and record["returncode"] == 0
    assert record["flags"] == ["--max-force", "10", *TINY[1:]]
    assert (out / "success_rate.png").stat().st_size > 0


def test_a_failing_run_is_reported_with_its_error_and_the_others_kept(sweep):
    out, _, report = sweep
    bad = report["results"][BAD]
    assert (bad["finished"], bad["failed"], bad["success_rate"]) == (0, 2, None)
    assert sorted((f["setting"], f["seed"], f["returncode"]) for f in report["failures"]) == [
        (BAD, 0, 1), (BAD, 1, 1)]
    for failure in report["failures"]:
        assert failure["attempts"] == 1
        assert "exit code 1" in failure["error"]
        assert "no motor gives a force above 50 N" in failure["stderr_tail"]
    assert load(out / BAD / "seed-0" / "sweep-run.json")["status"] == "failed"
    assert report["results"][OK]["finished"] == 2


def test_same_command_again_reruns_only_the_failed_runs(sweep, monkeypatch):
    out = sweep[0]
    before = {s: os.stat(out / OK / f"seed-{s}" / "summary.json").st_mtime_ns for s in (0, 1)}
    asked = []

    def record_runs(specs, **_):
        asked.extend(specs)
        return runs.SweepOutcome(not_run=list(specs), interrupted=True)

    monkeypatch.setattr(runs, "execute", record_runs)
    assert cli.main([*COMMAND, "--output", str(out), "--no-figures", *TINY]) == 130
    assert [(s.label, s.seed) for s in asked] == [(BAD, 0), (BAD, 1)]
    after = {s: os.stat(out / OK / f"seed-{s}" / "summary.json").st_mtime_ns for s in (0, 1)}
    assert after == before
    report = load(out / "sweep.json")
    assert [r["status"] for r in report["runs"]] == ["skipped", "skipped", "not_run",
                                                     "not_run"]
    assert report["results"][OK] == sweep[2]["results"][OK]
    assert report["interrupted"] is True


def test_a_finished_sweep_starts_no_run(sweep, monkeypatch):
    out = sweep[0]

    def no_runs(*_, **__):
        raise AssertionError("a finished sweep must start no run")

    monkeypatch.setattr(runs, "execute", no_runs)
    good_only = [a if a != "max_force=10,60" else "max_force=10" for a in COMMAND]
    assert cli.main([*good_only, "--output", str(out), "--no-figures", *TINY]) == 0
    assert [r["status"] for r in load(out / "sweep.json")["runs"]] == ["skipped", "skipped"]


def test_a_failing_process_is_retried(tmp_path, local_ray):
    # a task pilco.tasks does not know: the process exits with status 2 at once
    spec = runs.RunSpec("no_such_task", 3, "default", (), str(tmp_path / "seed-3"))
    outcome = runs.execute([spec], max_retries=2, progress=False)
    assert outcome.finished == [] and not outcome.interrupted
    [(failed, failure)] = outcome.failed
    assert failed == spec
    assert failure["attempts"] == 3
    assert failure["returncode"] == 2
    assert "exit code 2" in failure["error"]
    with open(tmp_path / "seed-3" / runs.ATTEMPTS, encoding="utf-8") as fh:
        assert len(fh.readlines()) == 3
    record = load(tmp_path / "seed-3" / runs.RUN_RECORD)
    assert (record["status"], record["attempts"]) == ("failed", 3)
