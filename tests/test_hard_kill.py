"""A run killed at any moment (SIGKILL: no handler runs) resumes with ``--resume DIR``
and loses at most the episode in progress.

A run writes its ``progress.json`` (and ``summary.json``) before the first episode, then
after every episode ``data.npz``, ``agent.npz``, ``progress.json`` and ``summary.json``,
each atomically. ``Killed`` below stands for the death of the process: from the chosen
write on, nothing reaches the disk, either because the process died before that write
began ("before") or because it died with the new content complete in its temporary file
but not yet renamed over the old file ("before-rename"). For every write of a small run
the tests kill there, resume from what is on disk, run to the end and compare with the
same run never killed (episodes are seeded by their number, and the stand-in agent acts
deterministically on its data, so both runs' episodes are identical). Further tests: a
write that fails while the process lives on, the real agent's file, and a real SIGKILL
of ``python -m pilco.tasks cartpole``.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np
import pytest

from pilco import files
from pilco.experiment import Experiment, FunctionHooks, RunHooks
from pilco.files import write_npz_atomic
from pilco.tasks import adaptation

from test_experiment import LineEnv, StandInAgent, config

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RUN_FILES = ("data.npz", "agent.npz", "progress.json", "summary.json")


class Killed(BaseException):
    """The process died (a ``BaseException``: no ``except Exception`` catches it)."""


class KillAtWrite:
    """Stands in for :func:`pilco.files.atomic_write`: write number ``kill_at`` (from 0)
    and every later write never reach their destination. ``log`` lists ``(file name,
    episodes the run had collected)`` of the writes that did."""

    def __init__(self, kill_at=None, before_rename=False, episodes=lambda: None):
        self.kill_at, self.before_rename, self.episodes = kill_at, before_rename, episodes
        self.real = files.atomic_write
        self.log = []
        self.dead = False

    def __call__(self, path, write):
        if self.dead or len(self.log) == self.kill_at:
            if not self.dead and self.before_rename:
                # the new content is complete in the temporary file; no rename follows
                fd, _ = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".",
                                         suffix=".tmp", dir=os.path.dirname(path))
                with os.fdopen(fd, "wb") as fh:
                    write(fh)
            self.dead = True
            raise Killed(f"killed at write {self.kill_at} ({os.path.basename(path)})")
        written = self.real(path, write)
        self.log.append((os.path.basename(path), self.episodes()))
        return written


class SavingAgent(StandInAgent):
    """The stand-in agent with a file of its own (its training data, written atomically
    as the real agent's is), acting on its data: it fits the action's effect ``b`` in
    ``x' - x = b u`` and aims 60 % of the way to x = 1, so it adapts to a damaged env."""

    def compute_action(self, x):
        X, Y = self.data
        b = float(X[:, 1] @ Y[:, 0] / (X[:, 1] @ X[:, 1]))
        return np.array([[0.6 / b * (1.0 - float(np.ravel(x)[0]))]])

    def save(self, path):
        return write_npz_atomic(path, {"X": self.data[0], "Y": self.data[1]})

    @classmethod
    def load(cls, path):
        with np.load(path) as f:
            agent = cls((f["X"], f["Y"]))
        agent.loaded = True
        return agent


class BreakableLineEnv(LineEnv):
    """The line env whose actuator loses half its effect once damaged."""

    effect = 1.0

    def damage(self, joints, mode):  # the reacher's signature
        self.effect = 0.5

    def step(self, action):
        return super().step(self.effect * np.asarray(action))


class LineHooks(RunHooks):
    """The hooks of a :class:`LineTask`'s runs: its env, its agents."""

    def __init__(self, task):
        self.task = task

    def make_env(self, run):
        return self.task.env()

    def build_agent(self, data, start_states):
        return self.task.build(data, start_states)


class LineAdaptation(adaptation.AdaptationSchedule, LineHooks):
    """The adaptation's schedule on the line, with its task's ``args`` as settings."""

    def __init__(self, task):
        super().__init__(task)
        self.settings = task.args


class LineTask:
    """Three episodes (one random) of the line env, run by ``Experiment.run``."""

    env = LineEnv
    cfg = config(episodes=3)
    hooks = LineHooks  # the class of its runs' hooks

    def __init__(self, built):
        self.built = built  # every agent the runs built

    def build(self, data, start_states):
        self.built.append(SavingAgent(data))
        return self.built[-1]

    def new(self, directory):
        return Experiment(self.cfg, str(directory), self.hooks(self))

    def resume(self, directory):
        return Experiment.resume(str(directory), self.cfg, self.hooks(self))

    def run(self, exp):
        return exp.run()


class AdaptationTask(LineTask):
    """The adaptation's schedule on the breakable line env: one random and one learned
    healthy episode (it reaches), the damage, then up to three damaged episodes; the
    second one reaches again."""

    env = BreakableLineEnv
    cfg = config(episodes=6)
    args = argparse.Namespace(random_episodes=1, healthy_episodes=2, damaged_episodes=3,
                              damaged_joints=[0], damage_mode="stuck", drop_old_data=False,
                              no_stop_when_recovered=False, min_healthy_episodes=1,
                              damaged_cost="all", damage_input=False, old_data_noise=4.0,
                              damaged_policy_restarts=1, changed_output_noise=None,
                              changed_output_threshold=10.0, stop_stuck_joints=False,
                              stuck_joint_ratio=0.1, replan_stuck_joints=False)
    hooks = LineAdaptation


def untimed(records):
    """Episode records without their timings."""
    return [{k: v for k, v in r.items() if k != "seconds"} for r in records]


def on_disk(directory):
    """What a resume finds: the episodes progress.json counts (None without the file),
    and the number of episodes in data.npz."""
    counted = in_data = None
    if os.path.exists(os.path.join(directory, "progress.json")):
        with open(os.path.join(directory, "progress.json"), encoding="utf-8") as f:
            counted = json.load(f)["episodes_done"]
    in_data = 0
    if os.path.exists(os.path.join(directory, "data.npz")):
        with np.load(os.path.join(directory, "data.npz")) as data:
            in_data = len([k for k in data.files if k.startswith("states_")])
    return counted, in_data


def finished_run(directory):
    """The finished run's files, checked for consistency: every counted episode once in
    data.npz, the summary agreeing with progress.json."""
    with open(os.path.join(directory, "progress.json"), encoding="utf-8") as f:
        progress = json.load(f)
    with open(os.path.join(directory, "summary.json"), encoding="utf-8") as f:
        summary = json.load(f)
    steps = [r["steps"] for r in progress["records"]]
    assert progress["complete"] and summary["complete"]
    assert progress["episodes_done"] == len(steps)
    assert [r["steps"] for r in summary["episodes"]] == steps
    with np.load(os.path.join(directory, "data.npz")) as data:
        arrays = {k: data[k] for k in data.files}
    assert len(arrays["X"]) == len(arrays["Y"]) == sum(steps)
    np.testing.assert_array_equal(np.bincount(arrays["episode"])[1:], steps)
    assert sorted(k for k in arrays if k.startswith("states_")) == sorted(
        f"states_{i}" for i in range(1, len(steps) + 1))
    return progress, summary, arrays


@pytest.fixture
def agent_files(monkeypatch):
    """``RunStore.load_agent`` reads the stand-in agent's file (through ``PILCO.load``).
    Writes skip ``fsync``: a process that dies leaves what it wrote in the page cache,
    so these runs need no flushing to disk (a thousand flushes cost seconds); the real
    SIGKILL test below keeps it."""
    from pilco.models import PILCO

    monkeypatch.setattr(PILCO, "load", SavingAgent.load)
    monkeypatch.setattr(os, "fsync", lambda fd: None)


def reference_run(directory, task, monkeypatch):
    """The run never killed: its writes in order, its summary and data."""
    exp = task.new(directory)
    counter = KillAtWrite(episodes=lambda: len(exp.episodes))
    monkeypatch.setattr(files, "atomic_write", counter)
    task.run(exp)
    monkeypatch.setattr(files, "atomic_write", counter.real)
    _, summary, arrays = finished_run(directory)
    return counter.log, summary, arrays


@pytest.mark.parametrize("task_class", [LineTask, AdaptationTask], ids=["loop", "adaptation"])
@pytest.mark.parametrize("before_rename", [False, True], ids=["before", "before-rename"])
def test_a_kill_at_any_write_loses_at_most_the_episode_in_progress(
        tmp_path, monkeypatch, agent_files, task_class, before_rename):
    writes, summary, reference = reference_run(tmp_path / "reference", task_class([]),
                                               monkeypatch)
    names = [name for name, _ in writes]
    # progress first, then per episode data, agent, progress, summary
    assert writes[:2] == [("progress.json", 0), ("summary.json", 0)]
    assert names[2:6] == ["data.npz", "agent.npz", "progress.json", "summary.json"]
    if task_class is AdaptationTask:
        assert (summary["damage_at_episode"], summary["episodes_to_recover"]) == (3, 2)
        assert len(summary["episodes"]) == 4 and summary["success"]

    for kill_at in range(len(writes)):
        directory = tmp_path / f"kill-{kill_at}"
        built = []
        task = task_class(built)
        exp = task.new(directory)
        killer = KillAtWrite(kill_at, before_rename, episodes=lambda: len(exp.episodes))
        monkeypatch.setattr(files, "atomic_write", killer)
        with pytest.raises(Killed):
            task.run(exp)
        monkeypatch.setattr(files, "atomic_write", killer.real)
        where = f"killed at write {kill_at} {writes[kill_at]}"
        counted, in_data = on_disk(directory)
        if counted is None:
            # killed in the run's very first write: nothing to resume, and resume says so
            assert kill_at == 0, where
            with pytest.raises(FileNotFoundError):
                task.resume(directory)
            continue
        assert counted <= in_data, where  # progress never counts data that are not there
        assert counted >= len(exp.episodes) - 1, where  # at most the episode in progress

        resumed = task.resume(directory)
        assert len(resumed.episodes) == counted, where
        for i, episode in enumerate(resumed.episodes, start=1):
            np.testing.assert_array_equal(episode.states, reference[f"states_{i}"],
                                          err_msg=where)
        if counted >= task.cfg.random_episodes:
            # agent.npz is as new as progress.json or newer: it is read, not rebuilt,
            # and then trained on exactly the counted episodes
            assert getattr(resumed.agent, "loaded", False), where
            assert len(resumed.agent.data[0]) == sum(e.steps for e in resumed.episodes)
        task.run(resumed)
        _, final, arrays = finished_run(directory)
        # the same run as the one never killed: no episode lost, repeated or changed
        assert untimed(final["episodes"]) == untimed(summary["episodes"]), where
        assert {k: final[k] for k in ("solved_at_episode", "success")} == {
            k: summary[k] for k in ("solved_at_episode", "success")}, where
        if task_class is AdaptationTask:
            assert (final["damage_at_episode"], final["episodes_to_recover"]) == (3, 2), where
            # the healthy episodes (1, 2) down-weighted against the damaged ones (3, 4)
            steps = [e["steps"] for e in final["episodes"]]
            np.testing.assert_array_equal(resumed.agent.noise_scales,
                                          np.repeat([4.0, 4.0, 1.0, 1.0], steps), err_msg=where)
        assert arrays.keys() == reference.keys(), where
        for key in reference:
            np.testing.assert_array_equal(arrays[key], reference[key], err_msg=where)
        leftovers = sorted(set(os.listdir(directory)) - set(RUN_FILES))
        assert len(leftovers) == int(before_rename), (where, leftovers)
        assert all(name.endswith(".tmp") for name in leftovers), (where, leftovers)


class FailOnce:
    """Stands in for :func:`pilco.files.atomic_write`: write number ``fail_at`` raises
    ``OSError`` (a full disk) and leaves its file as it was; the process lives on and
    the other writes succeed."""

    def __init__(self, fail_at):
        self.fail_at, self.count, self.real = fail_at, 0, files.atomic_write

    def __call__(self, path, write):
        self.count += 1
        if self.count - 1 == self.fail_at:
            raise OSError(28, "No space left on device", path)
        return self.real(path, write)


def test_a_failed_write_never_makes_progress_count_missing_data(
        tmp_path, monkeypatch, agent_files):
    writes, summary, reference = reference_run(tmp_path / "reference", LineTask([]),
                                               monkeypatch)
    for fail_at, (name, _) in enumerate(writes):
        directory = tmp_path / f"fail-{fail_at}"
        task = LineTask([])
        exp = task.new(directory)
        failing = FailOnce(fail_at)
        monkeypatch.setattr(files, "atomic_write", failing)
        try:
            task.run(exp)
        except OSError:
            assert name != "agent.npz", fail_at  # a failed agent write is only logged
        monkeypatch.setattr(files, "atomic_write", failing.real)
        if name == "agent.npz":
            # progress tells whether agent.npz is the newest agent: not after its last
            # write failed (the older file stays), again after a later write succeeded
            last_agent_write = max(i for i, (n, _) in enumerate(writes) if n == "agent.npz")
            progress = json.loads((directory / "progress.json").read_text())
            assert progress["agent_saved"] is (fail_at != last_agent_write), fail_at
        counted, in_data = on_disk(directory)
        # the session's last progress write, after the failure, counts only saved data
        assert counted is not None and counted <= in_data, (fail_at, name)
        resumed = task.resume(directory)
        assert len(resumed.episodes) == counted
        task.run(resumed)
        _, _, arrays = finished_run(directory)
        np.testing.assert_array_equal(arrays["X"], reference["X"], err_msg=str(fail_at))


def line_pilco(data, start_states):
    """A real PILCO agent for the line env, tiny."""
    from pilco.controllers import LinearController
    from pilco.models import PILCO
    from pilco.rewards import ExponentialReward

    return PILCO(data, LinearController(1, 1, max_action=0.5, seed=0),
                 ExponentialReward(1, W=[[4.0]], t=[[1.0]]), horizon=3,
                 m_init=[[0.0]], S_init=[[1e-4]])


def test_a_kill_with_the_real_agent_newer_than_progress(tmp_path, monkeypatch):
    """Killed after episode 2's agent.npz, before its progress.json: the resumed run
    reads that agent file (PILCO.load, not rebuilt), gives it episode 1's data only, and
    finishes."""
    cfg = config(episodes=2, model_iters=5, policy_iters=2)
    directory = tmp_path / "run"
    exp = Experiment(cfg, str(directory), FunctionHooks(line_pilco, LineEnv))
    # writes: progress and summary (0 episodes), then per episode data, agent, progress,
    # summary: write 8 is episode 2's progress
    killer = KillAtWrite(8, episodes=lambda: len(exp.episodes))
    monkeypatch.setattr(files, "atomic_write", killer)
    with pytest.raises(Killed):
        exp.run()
    monkeypatch.setattr(files, "atomic_write", killer.real)
    assert killer.log[-2:] == [("data.npz", 2), ("agent.npz", 2)]
    with np.load(directory / "agent.npz") as f:
        saved_rows = len(f["data/X"])
    assert on_disk(directory) == (1, 2)

    rebuilt = []
    resumed = Experiment.resume(str(directory), cfg, FunctionHooks(
        lambda *a: rebuilt.append(1) or line_pilco(*a), LineEnv))
    assert not rebuilt and len(resumed.episodes) == 1
    assert resumed.agent.data[0].shape[0] == resumed.episodes[0].steps < saved_rows
    summary = resumed.run()
    assert summary["complete"] and len(summary["episodes"]) == 2 and not rebuilt
    _, _, arrays = finished_run(directory)
    assert resumed.agent.data[0].shape[0] == len(arrays["X"])


def test_sigkill_of_a_real_run_then_resume(tmp_path):
    """``python -m pilco.tasks cartpole`` killed with SIGKILL once its first episode is
    saved; ``--resume`` continues it to the end."""
    directory = tmp_path / "run"
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""),
               TF_CPP_MIN_LOG_LEVEL="3", OMP_NUM_THREADS="1")
    command = [sys.executable, "-m", "pilco.tasks", "cartpole", "--horizon", "8",
               "--basis-functions", "3", "--policy-iters", "2", "--model-iters", "10",
               "--quiet", "--no-render", "--no-figures"]
    proc = subprocess.Popen([*command, "--episodes", "3", "--output", str(directory)],
                            cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        deadline = time.time() + 300
        while proc.poll() is None and time.time() < deadline:
            if (on_disk(directory)[0] or 0) >= 1:
                break
            time.sleep(0.05)
        assert proc.poll() is None, "the run ended before it could be killed"
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    counted, in_data = on_disk(directory)
    assert 1 <= counted <= in_data and counted < 3
    with np.load(directory / "data.npz") as data:
        first_episode = data["states_1"]

    # one more episode than those saved (flags given again win over the saved ones)
    out = subprocess.run([*command[:4], "--resume", str(directory), "--episodes",
                          str(counted + 1)], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    progress, summary, arrays = finished_run(directory)
    assert progress["episodes_done"] == len(summary["episodes"]) == counted + 1
    np.testing.assert_array_equal(arrays["states_1"], first_episode)  # kept, not re-run
