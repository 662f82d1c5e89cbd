"""The sweep under faults: what it leaves on disk when Ray, a run, a worker or the driver
fails, and what the next sweep makes of it.

Every case runs real processes: ``python -m pilco.tasks cartpole`` runs of random
episodes only (no model or policy is trained; a 400-step episode takes about a second,
long enough to kill a run between two saved episodes), on a Ray that serves the module
or, where the driver is the subject, in a driver process of its own. Every Ray here keeps
its files in a temporary folder of its own (``RAY_TMPDIR``), never in the user's, and is
stopped by its processes' ids (``ray stop`` would stop every Ray on the machine).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np
import pytest

ray = pytest.importorskip("ray")

from pilco.sweep import cli, preflight, runs  # noqa: E402 - after the skip
# the cart-pole's module (and TensorFlow with it), imported here: the sweep imports it for
# the task's flags, which the sweeps timed below would otherwise count
from pilco.tasks import cartpole  # noqa: E402,F401

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: three random episodes: the runs save an episode about every second, train nothing
RANDOM = ["--episodes", "3", "--random-episodes", "3", "--horizon", "400"]
#: one 5-step random episode: the shortest complete run
SHORT = ["--episodes", "1", "--horizon", "5"]


# ------------------------------------------------------------------------------ helpers
def load(path):
    with open(path, encoding="utf-8") as fh:
        return json.load(fh)


def closed_port():
    """A local TCP port nothing listens on (bound, then released)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def ray_temp():
    """A short temporary folder for a Ray of the tests (Ray's socket paths must stay
    under the 107 characters of a Unix socket address)."""
    return tempfile.mkdtemp(prefix="pilco-ray-")


def processes_with(text):
    """Pids of the processes (other than this one) whose command line contains ``text``."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) == os.getpid():
            continue
        try:
            with open(f"/proc/{entry}/cmdline", "rb") as fh:
                cmdline = fh.read().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if text in cmdline:
            found.append(int(entry))
    return found


def run_processes(directory):
    """Pids of the ``python -m pilco.tasks`` processes writing into ``directory``."""
    return [pid for pid in processes_with(f"--output {directory} ")
            if pid in processes_with("pilco.tasks")]


def wait_for(condition, timeout, what):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.02)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


def stop_ray_processes(folder):
    """Kill the processes of a Ray that keeps its files in ``folder`` (a test's own Ray;
    ``ray stop`` would stop every Ray on the machine), then remove the folder."""
    for pid in processes_with(folder):
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    shutil.rmtree(folder, ignore_errors=True)


def environment(ray_folder):
    """This process's environment for a driver process with its Ray files in
    ``ray_folder``: the repository's pilco first, no cluster address from outside."""
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    env.update(RAY_TMPDIR=ray_folder, TF_CPP_MIN_LOG_LEVEL="3",
               PYTHONPATH=os.pathsep.join([ROOT, *filter(None, [env.get("PYTHONPATH")])]))
    return env


def sweep_process(argv, ray_folder, **kwargs):
    """``python -m pilco.sweep ARGV`` started in its own process (SIGINT handled as by a
    terminal's Ctrl-C, even when this process was started with SIGINT ignored)."""
    return subprocess.Popen(
        [sys.executable, "-m", "pilco.sweep", *argv], cwd=ROOT, env=environment(ray_folder),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL), **kwargs)


def episodes(directory):
    """The episode records ``progress.json`` in ``directory`` counts (with timings)."""
    progress = runs.read_json(os.path.join(directory, "progress.json")) or {}
    return progress.get("records", [])[:progress.get("episodes_done", 0)]


def check_run_files(directory, n_episodes, kept=()):
    """A finished run's files: ``n_episodes`` episodes numbered 1..n once each, in the
    summary, the progress and ``data.npz`` alike; the records ``kept`` (saved before a
    kill) unchanged, timings included, so they were continued, not run again."""
    summary = load(os.path.join(directory, "summary.json"))
    assert summary["complete"] is True
    assert [e["episode"] for e in summary["episodes"]] == list(range(1, n_episodes + 1))
    assert summary["episodes"][:len(kept)] == list(kept)
    assert episodes(directory) == summary["episodes"]
    with np.load(os.path.join(directory, "data.npz")) as data:
        assert sorted(k for k in data.files if k.startswith("states_")) == [
            f"states_{i}" for i in range(1, n_episodes + 1)]
        np.testing.assert_array_equal(np.bincount(data["episode"])[1:],
                                      [e["steps"] for e in summary["episodes"]])
    return summary


def attempts(directory):
    with open(os.path.join(directory, runs.ATTEMPTS), encoding="utf-8") as fh:
        return [line.split(" ", 4)[4].strip() for line in fh]


@pytest.fixture(scope="module")
def shared_ray():
    """A local Ray (2 CPUs) for the module, its files in a temporary folder; yields that
    folder."""
    folder = ray_temp()
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("RAY_TMPDIR", folder)
        mp.delenv("RAY_ADDRESS", raising=False)
        started, _ = cli._start_ray(argparse.Namespace(address=None, num_cpus=2))
        assert started, "a Ray was running in this process already"
        try:
            yield folder
        finally:
            ray.shutdown()
            stop_ray_processes(folder)


# ----------------------------------------------------------------- addresses (no Ray)
def refused_within_seconds(out, address, capsys) -> str:
    """Run a one-run sweep into ``out`` with ``--address address``; assert that it exits
    with status 2 within the connection timeout (plus start-up); return its stderr."""
    t0 = time.monotonic()
    with pytest.raises(SystemExit) as stop:
        cli.main(["cartpole", "--seeds", "0", "--output", str(out), "--no-progress",
                  "--address", address, "--", *SHORT])
    assert time.monotonic() - t0 < preflight.CONNECT_TIMEOUT + 5
    assert stop.value.code == 2
    return capsys.readouterr().err


def test_an_unreachable_address_fails_within_seconds(tmp_path, capsys):
    port = closed_port()
    err = refused_within_seconds(tmp_path, f"127.0.0.1:{port}", capsys)
    assert f"no Ray cluster answers at 127.0.0.1:{port}" in err
    assert "leave out --address" in err
    # nothing was started: no run directory, no report, only the released lock
    assert os.listdir(tmp_path) == [preflight.LOCK_FILE]


def test_auto_with_a_stopped_heads_record_fails_within_seconds(tmp_path, monkeypatch, capsys):
    """``--address auto`` after ``ray start --head`` was stopped: Ray's record of the head
    is still there; the sweep names it instead of waiting for the head."""
    port = closed_port()
    record = tmp_path / "ray" / "ray" / "ray_current_cluster"
    record.parent.mkdir(parents=True)
    record.write_text(f"127.0.0.1:{port}")
    monkeypatch.setenv("RAY_TMPDIR", str(tmp_path / "ray"))
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    out = tmp_path / "out"
    err = refused_within_seconds(out, "auto", capsys)
    assert f"127.0.0.1:{port} (recorded in {record})" in err
    assert "ray start --head" in err
    assert os.listdir(out) == [preflight.LOCK_FILE]
    assert record.read_text() == f"127.0.0.1:{port}"  # Ray's file is not the sweep's


def test_auto_without_any_cluster_fails_clearly(tmp_path):
    """``--address auto`` with no cluster at all: Ray's discovery of running Ray
    processes is made to find none (this machine may run other Rays)."""
    code = ("import ray._private.services as s\n"
            "def none(): return []\n"
            "none.cache_clear = lambda: None\n"
            "s.find_gcs_addresses = none\n"
            "from pilco.sweep.cli import main\n"
            "raise SystemExit(main())\n")
    out = tmp_path / "out"
    done = subprocess.run(
        [sys.executable, "-c", code, "cartpole", "--seeds", "0", "--output", str(out),
         "--no-progress", "--address", "auto", "--", *SHORT],
        cwd=ROOT, env=environment(str(tmp_path / "ray")), capture_output=True, text=True,
        timeout=120)
    assert done.returncode == 2, done.stderr[-2000:]
    assert "--address auto: Ray could not connect" in done.stderr
    assert "Could not find any running Ray instance" in done.stderr
    assert os.listdir(out) == [preflight.LOCK_FILE]


def test_address_forms_are_checked_before_anything_starts(tmp_path, capsys):
    assert preflight.split_address("10.0.0.5:6379") == ("10.0.0.5", 6379)
    assert preflight.split_address("ray://head.example") == \
        ("head.example", preflight.RAY_CLIENT_PORT)
    assert preflight.split_address("auto") is None
    assert preflight.split_address("local") is None
    for bad in ("head", "head:", "ray://", "a b:1", "head:70000"):
        with pytest.raises(ValueError, match="--address"):
            preflight.split_address(bad)
    with pytest.raises(SystemExit) as stop:
        cli.main(["cartpole", "--output", str(tmp_path / "out"), "--address", "head"])
    assert stop.value.code == 2
    assert "--address must be auto, HOST:PORT or ray://HOST[:PORT]" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------- the lock (no Ray needed)
def finished_by_hand(directory, seed):
    """A complete one-episode summary in ``directory``, as a run started by hand leaves."""
    from pilco.files import write_json_atomic

    write_json_atomic(os.path.join(directory, "summary.json"), {
        "task": "cartpole", "seed": seed, "solved": False, "solved_at_episode": None,
        "success": False, "complete": True,
        "episodes": [{"episode": 1, "steps": 5, "final_distance": 1.0, "min_distance": 0.5,
                      "steps_to_target": None}],
        "seconds": {"total": 1.0}})


def test_a_second_sweep_refuses_a_locked_directory_and_a_killed_holder_frees_it(
        tmp_path, capsys):
    out = tmp_path / "out"
    finished_by_hand(str(out / "default" / "seed-0"), 0)
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; "
                               "from pilco.sweep.preflight import lock_output; "
                               "held = lock_output(sys.argv[1]); print('locked', flush=True); "
                               "time.sleep(600)", str(out)],
        cwd=ROOT, env=environment(str(tmp_path / "ray")), stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        command = ["cartpole", "--seeds", "0", "--output", str(out), "--no-figures"]
        with pytest.raises(SystemExit) as stop:
            cli.main(command)
        assert stop.value.code == 2
        err = capsys.readouterr().err
        assert f"another sweep (pid {holder.pid} on " in err
        assert f"is running in {out}" in err
        assert not (out / "sweep.json").exists()
    finally:
        holder.send_signal(signal.SIGKILL)  # no handler runs: only the kernel frees it
        holder.wait()
    # the same command now runs: the finished run is skipped, no Ray is needed
    assert cli.main(command) == 0
    report = load(out / "sweep.json")
    assert [r["status"] for r in report["runs"]] == ["skipped"]
    assert (out / preflight.LOCK_FILE).read_text().startswith(f"pid {os.getpid()} on ")


# --------------------------------------------------------------------- foreign clusters
def test_a_local_sweep_does_not_join_a_running_cluster(shared_ray, tmp_path):
    """The module's Ray plays a cluster started on this machine: its address is recorded
    where ``ray start --head`` records it. The sweep must start a Ray of its own: its
    driver's log is in a session of its own, none is in the running cluster's."""
    gcs = ray.get_runtime_context().gcs_address
    record = os.path.join(shared_ray, "ray", "ray_current_cluster")
    with open(record, "w", encoding="utf-8") as fh:
        fh.write(gcs)
    foreign = os.path.basename(ray._private.worker._global_node.get_session_dir_path())
    out = tmp_path / "out"
    try:
        proc = sweep_process(["cartpole", "--seeds", "0", "--output", str(out),
                              "--no-progress", "--no-figures", "--", *SHORT], shared_ray)
        _, stderr = proc.communicate(timeout=300)
    finally:
        os.remove(record)
    assert proc.returncode == 0, stderr[-3000:]
    report = load(out / "sweep.json")
    assert report["ray"]["address"] == "local"
    assert [r["status"] for r in report["runs"]] == ["finished"]
    check_run_files(str(out / "default" / "seed-0"), 1)
    own = driver_logs(shared_ray, proc.pid)
    assert len(own) == 1 and own[0] != foreign


# ------------------------------------------------------- a killed run, a dying worker
def faulty(out, seeds="0-1"):
    """The command of the sweep with faults: three random episodes per run, one retry."""
    return ["cartpole", "--seeds", seeds, "--output", str(out), "--no-progress",
            "--no-figures", "--max-retries", "1", "--", *RANDOM]


class Injector(threading.Thread):
    """Kills, while a sweep runs: seed 0's run process once (SIGKILL) as soon as it saved
    its first episode; seed 1's Ray worker each time it runs seed 1's process."""

    def __init__(self, out):
        super().__init__(daemon=True)
        self.killed_run = os.path.join(out, "default", "seed-0")
        self.dying = os.path.join(out, "default", "seed-1")
        self.saved_before_kill = None
        self.killed_workers = []
        self.errors = []
        self.stop = threading.Event()

    def run(self):
        try:
            while not self.stop.is_set():
                self.step()
                time.sleep(0.02)
        except Exception as err:  # reported by the fixture
            self.errors.append(err)

    def step(self):
        if self.saved_before_kill is None and episodes(self.killed_run):
            pids = run_processes(self.killed_run)
            saved = episodes(self.killed_run)
            if pids and 1 <= len(saved) < 3:
                for pid in pids:
                    os.kill(pid, signal.SIGKILL)
                self.saved_before_kill = saved
        if len(self.killed_workers) < 2 and os.path.exists(
                os.path.join(self.dying, runs.ATTEMPTS)):
            with open(os.path.join(self.dying, runs.ATTEMPTS), encoding="utf-8") as fh:
                lines = fh.readlines()
            if len(lines) > len(self.killed_workers) and run_processes(self.dying):
                worker = int(re.search(r" pid (\d+)\b", lines[-1]).group(1))
                os.kill(worker, signal.SIGKILL)
                self.killed_workers.append(worker)


@pytest.fixture(scope="module")
def faulty_sweep(shared_ray, tmp_path_factory):
    """Two seeds with one retry each: seed 0's run killed once, seed 1's worker killed
    at both attempts. ``(directory, exit status, report, injector)``."""
    out = str(tmp_path_factory.mktemp("faulty"))
    injector = Injector(out)
    injector.start()
    try:
        code = cli.main(faulty(out))
    finally:
        injector.stop.set()
        injector.join()
    assert not injector.errors, injector.errors
    assert injector.saved_before_kill, "seed 0's run was never killed"
    return out, code, load(os.path.join(out, "sweep.json")), injector


def test_a_killed_run_is_retried_from_its_saved_episodes(faulty_sweep):
    out, code, report, injector = faulty_sweep
    directory = os.path.join(out, "default", "seed-0")
    kept = injector.saved_before_kill
    assert code == 1  # seed 1 failed
    assert report["runs"][0]["status"] == "finished"
    # the second attempt continued the saved run; no episode is missing or twice there
    assert attempts(directory) == ["new run", f"resume after episode {len(kept)}"]
    check_run_files(directory, 3, kept=kept)
    record = load(os.path.join(directory, runs.RUN_RECORD))
    assert (record["status"], record["attempts"], record["returncode"]) == ("finished", 2, 0)
    assert report["results"]["default"]["finished"] == 1


def test_a_worker_that_dies_for_good_is_recorded_failed_and_the_others_finish(faulty_sweep):
    out, _, report, injector = faulty_sweep
    directory = os.path.join(out, "default", "seed-1")
    assert len(injector.killed_workers) == 2
    assert [(r["seed"], r["status"]) for r in report["runs"]] == [(0, "finished"),
                                                                 (1, "failed")]
    [failure] = report["failures"]
    assert (failure["seed"], failure["attempts"], failure["returncode"]) == (1, 2, None)
    assert "default/seed-1:" in failure["error"] and "Worker" in failure["error"]
    record = load(os.path.join(directory, runs.RUN_RECORD))
    assert (record["status"], record["error"]) == ("failed", failure["error"])
    assert len(attempts(directory)) == 2
    assert runs.finished_summary(runs.RunSpec("cartpole", 1, "default", tuple(RANDOM),
                                              directory)) is None
    result = report["results"]["default"]
    assert (result["runs"], result["finished"], result["failed"]) == (2, 1, 1)
    assert not run_processes(directory)  # the killed workers' runs did not live on


def test_a_corrupt_summary_is_run_again_not_counted(faulty_sweep, tmp_path):
    """A finished run whose summary.json was cut short: the sweep does not count it, runs
    it again (from its saved episodes: nothing to redo but the summary) and counts it."""
    out = tmp_path / "out"
    shutil.copytree(os.path.join(faulty_sweep[0], "default", "seed-0"),
                    out / "default" / "seed-0")
    directory = out / "default" / "seed-0"
    saved = episodes(str(directory))
    text = (directory / "summary.json").read_text()
    (directory / "summary.json").write_text(text[:len(text) // 2])
    spec = runs.RunSpec("cartpole", 0, "default", tuple(RANDOM), str(directory))
    assert runs.finished_summary(spec) is None
    assert cli.main(faulty(out, seeds="0")) == 0
    report = load(out / "sweep.json")
    assert [r["status"] for r in report["runs"]] == ["finished"]
    assert report["results"]["default"]["finished"] == 1
    assert attempts(str(directory)) == ["resume after episode 3"]
    check_run_files(str(directory), 3, kept=saved)
    assert runs.finished_summary(spec)["episodes"] == saved


# ------------------------------------------------------------- the driver interrupted
def interrupted(out):
    """A sweep of two settings: 5-step episodes (a quick run) and 400-step ones (a slow
    run of :data:`EPISODES` episodes, which :func:`interrupt` holds still from its first
    saved episode until it is told to stop)."""
    return ["cartpole", "--seeds", "0", "--grid", "horizon=5,400", "--output", str(out),
            "--no-progress", "--no-figures", "--max-retries", "0", "--", "--episodes",
            str(EPISODES), "--random-episodes", str(EPISODES)]
QUICK, SLOW = "horizon=5", "horizon=400"
EPISODES = 3


def driver_logs(ray_folder, pid):
    """The session folders under ``ray_folder`` holding the log of driver ``pid``."""
    pattern = re.compile(rf"^python-core-driver-\w+_{pid}\.log$")
    base = os.path.join(ray_folder, "ray")
    return sorted(name for name in os.listdir(base) if name.startswith("session_2")
                  and any(pattern.match(n) for n in os.listdir(os.path.join(base, name,
                                                                              "logs"))))


def pending_signals(pid):
    """The signals pending for process ``pid`` (a bit mask, bit ``n - 1`` for signal
    ``n``), or None once the process is gone."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as fh:
            fields = dict(line.split(":", 1) for line in fh if ":" in line)
    except OSError:
        return None
    return int(fields["SigPnd"], 16) | int(fields["ShdPnd"], 16)


def stopping(pids, signum):
    """True once each process of ``pids`` has ``signum`` pending or is gone."""
    masks = [pending_signals(pid) for pid in pids]
    return all(mask is None or mask & (1 << (signum - 1)) for mask in masks)


def hold(pids):
    """Stop ``pids`` (SIGSTOP: they keep their state and resume where they were)."""
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGSTOP)


def release(pids):
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGCONT)


def interrupt(out, ray_folder, signum, address=None):
    """Run the sweep in a driver process of its own; once the slow run saved an episode
    and the quick one finished, start a second sweep into the same directory (in this
    process), then send ``signum`` to the driver. What is on disk at each step.

    The slow run's process is held (SIGSTOP) from its first saved episode on, and let go
    (SIGCONT) once the SIGTERM by which its Ray worker stops it is pending: so it is
    under way when the driver is signalled, whatever the machine's load, and it stops at
    its next safe point as a running run does."""
    quick, slow = (os.path.join(out, label, "seed-0") for label in (QUICK, SLOW))
    extra = [] if address is None else ["--address", address]

    def slow_run_under_way():
        """The slow run's processes once it saved an episode; an error if it finished."""
        record = runs.read_json(os.path.join(slow, runs.RUN_RECORD)) or {}
        assert record.get("status") != "finished", "the slow run finished before it was held"
        return episodes(slow) and run_processes(slow)

    proc = sweep_process([interrupted(out)[0], *extra, *interrupted(out)[1:]], ray_folder)
    held = []
    try:
        held = wait_for(slow_run_under_way, 300, "the slow run to save an episode")
        hold(held)
        wait_for(lambda: (runs.read_json(os.path.join(quick, runs.RUN_RECORD)) or {})
                 .get("status") == "finished", 300, "the quick run to finish")
        files_before = {path: os.stat(path).st_mtime_ns
                        for path in (os.path.join(quick, "summary.json"),
                                     os.path.join(slow, runs.RUN_RECORD))}
        # the second sweep runs in this process (pilco is imported: it is quick)
        second_err = io.StringIO()
        with contextlib.redirect_stderr(second_err), pytest.raises(SystemExit) as stop:
            cli.main(interrupted(out))
        second = {"code": stop.value.code, "stderr": second_err.getvalue(),
                  "report": os.path.exists(os.path.join(out, "sweep.json")),
                  "files": {path: os.stat(path).st_mtime_ns for path in files_before}}
        saved, running = episodes(slow), run_processes(slow)
        proc.send_signal(signum)
        # the worker gives the run a few seconds to stop before it kills it: let go at once
        wait_for(lambda: stopping(held, signal.SIGTERM), 60,
                 "the driver's cancellation to reach the slow run")
        release(held)
        _, stderr = proc.communicate(timeout=120)
    finally:
        release(held)
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    wait_for(lambda: not run_processes(slow), 30, "the interrupted run's process to end")
    return {"out": out, "quick": quick, "slow": slow, "pid": proc.pid,
            "code": proc.returncode, "stderr": stderr, "second": second,
            "files_before": files_before, "saved": saved, "running": running,
            "report": load(os.path.join(out, "sweep.json")),
            "quick_summary_mtime": os.stat(os.path.join(quick, "summary.json")).st_mtime_ns,
            "slow_record": load(os.path.join(slow, runs.RUN_RECORD)),
            "slow_summary": runs.read_json(os.path.join(slow, "summary.json")),
            "slow_episodes": episodes(slow)}


def rerun(result):
    """The same command again, on the module's Ray: the exit status and the report."""
    result["rerun"] = cli.main(interrupted(result["out"]))
    result["rerun_report"] = load(os.path.join(result["out"], "sweep.json"))
    return result


@pytest.fixture(scope="module")
def interrupted_local(shared_ray, tmp_path_factory):
    """Ctrl-C (SIGINT) to a sweep on a Ray of its own, started where a stopped head left
    its record (``ray start --head``, then ``ray stop``)."""
    folder = ray_temp()
    try:
        record = os.path.join(folder, "ray", "ray_current_cluster")
        os.makedirs(os.path.dirname(record))
        stale = f"127.0.0.1:{closed_port()}"
        with open(record, "w", encoding="utf-8") as fh:
            fh.write(stale)
        result = interrupt(str(tmp_path_factory.mktemp("interrupted-local")), folder,
                           signal.SIGINT)
        with open(record, encoding="utf-8") as fh:
            result["record"] = (stale, fh.read())
        result["driver_sessions"] = driver_logs(folder, result["pid"])
    finally:
        stop_ray_processes(folder)
    return rerun(result)


@pytest.fixture(scope="module")
def interrupted_on_cluster(shared_ray, tmp_path_factory):
    """SIGTERM to a sweep on a running cluster (``--address``: the module's Ray, which
    lives on after the driver: its runs must stop by the driver's cancellation)."""
    result = interrupt(str(tmp_path_factory.mktemp("interrupted-cluster")), shared_ray,
                       signal.SIGTERM, address=ray.get_runtime_context().gcs_address)
    return rerun(result)


@pytest.fixture(params=["interrupted_local", "interrupted_on_cluster"])
def interrupted_sweep(request):
    return request.getfixturevalue(request.param)


def test_a_local_sweep_ignores_a_stopped_heads_record(interrupted_local):
    """The driver started a Ray of its own (its log is in a session there), ran a run on
    it, and left the stopped head's record as it was."""
    s = interrupted_local
    assert s["code"] == 130, s["stderr"][-3000:]
    assert s["report"]["ray"]["address"] == "local"
    assert s["report"]["runs"][0]["status"] == "finished"
    assert len(s["driver_sessions"]) == 1
    assert s["record"][1] == s["record"][0]


def test_a_second_sweep_into_a_running_sweeps_directory_refuses(interrupted_sweep):
    s = interrupted_sweep
    assert s["second"]["code"] == 2, s["second"]["stderr"][-2000:]
    assert f"another sweep (pid {s['pid']} on " in s["second"]["stderr"]
    assert "choose another --output" in s["second"]["stderr"]
    # it wrote nothing: no report, the first sweep's files untouched
    assert s["second"]["report"] is False
    assert s["second"]["files"] == s["files_before"]


def test_an_interrupted_driver_stops_its_runs_and_keeps_what_finished(interrupted_sweep):
    s = interrupted_sweep
    assert s["code"] == 130, s["stderr"][-3000:]
    assert s["running"], "the slow run was not running when the driver was signalled"
    report = s["report"]
    assert report["interrupted"] is True
    assert [(r["setting"], r["status"]) for r in report["runs"]] == [(QUICK, "finished"),
                                                                     (SLOW, "not_run")]
    assert report["results"][QUICK]["finished"] == 1
    assert report["results"][SLOW]["not_run"] == 1
    check_run_files(s["quick"], EPISODES)
    assert s["slow_record"]["status"] == "interrupted"
    # the stopped run saved its episodes so far and ended before its last one
    assert 1 <= len(s["saved"]) <= len(s["slow_episodes"]) < EPISODES
    assert s["slow_episodes"][:len(s["saved"])] == s["saved"]
    assert s["slow_summary"] is None or s["slow_summary"]["complete"] is False


def test_the_rerun_skips_finished_runs_and_resumes_the_interrupted_one(interrupted_sweep):
    s = interrupted_sweep
    assert s["rerun"] == 0
    report = s["rerun_report"]
    assert report["interrupted"] is False
    assert [(r["setting"], r["status"]) for r in report["runs"]] == [(QUICK, "skipped"),
                                                                     (SLOW, "finished")]
    assert os.stat(os.path.join(s["quick"], "summary.json")).st_mtime_ns == \
        s["quick_summary_mtime"]
    kept = s["slow_episodes"]
    assert attempts(s["slow"]) == [f"resume after episode {len(kept)}"]
    check_run_files(s["slow"], EPISODES, kept=kept)
    assert load(os.path.join(s["slow"], runs.RUN_RECORD))["status"] == "finished"
    assert {label: r["finished"] for label, r in report["results"].items()} == {
        QUICK: 1, SLOW: 1}
