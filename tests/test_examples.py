"""Smoke tests of the example scripts: each runs as a subprocess with tiny settings.

The runs are started together (one module fixture) so their TensorFlow start-up and
tracing overlap; every test then checks one run's outputs: ``summary.json`` keys and
types exactly as documented, ``data.npz`` holding every transition, the figures, and
``--resume`` / SIGTERM handling on the cart-pole.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLES = os.path.join(ROOT, "examples")

TINY = ["--episodes", "2", "--basis-functions", "3", "--policy-iters", "2",
        "--model-iters", "10", "--quiet"]
CARTPOLE = ["--horizon", "8", *TINY]
REACHER = ["--horizon", "6", *TINY, "--no-render"]
TIMEOUT = 600

EPISODE_KEYS = {"episode", "random", "steps", "cost", "final_distance", "min_distance",
                "steps_to_target", "seconds", "policy_evaluations"}
SUMMARY_KEYS = {"task", "seed", "solved", "solved_at_episode", "episodes", "seconds",
                "complete", "success", "distances", "provenance", "solved_episodes",
                "held_for_good"}
PHASE_KEYS = {"interaction", "model", "policy"}
FIGURES = ["distance.png", "cost_prediction.png", "one_step.png", "multi_step.png"]


def _have_mujoco() -> bool:
    try:
        import mujoco  # noqa: F401
        import gymnasium_robotics  # noqa: F401
    except Exception:
        return False
    return True


def _start(script, out, args, env_extra=None):
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""),
               TF_CPP_MIN_LOG_LEVEL="3", OMP_NUM_THREADS="1")
    env.update(env_extra or {})
    cmd = [sys.executable, os.path.join(EXAMPLES, script), "--output", str(out), *args]
    return subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def _finish(proc):
    out, _ = proc.communicate(timeout=TIMEOUT)
    return proc.returncode, out


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Start every run at once, wait for all; ``{name: (dir, returncode, output)}``."""
    base = tmp_path_factory.mktemp("examples")
    procs = {"cartpole": ("cartpole.py", [*CARTPOLE[:2], *TINY[2:], "--episodes", "6"])}
    if _have_mujoco():
        procs.update({
            "reacher": ("reacher.py", REACHER),
            "damaged": ("damaged_reacher.py", [*REACHER, "--damage-mode", "stuck"]),
            "adaptation": ("adaptation.py", ["--horizon", "6", "--basis-functions", "3",
                                             "--policy-iters", "2", "--model-iters", "10",
                                             "--quiet", "--no-render", "--healthy-episodes",
                                             "2", "--min-healthy-episodes", "2",
                                             "--damaged-episodes", "1"]),
        })
    started = {name: (base / name, _start(script, base / name, args))
               for name, (script, args) in procs.items()}

    # SIGTERM the cart-pole run (6 episodes asked) once its second episode is saved ...
    d, proc = started["cartpole"]
    deadline = time.time() + TIMEOUT
    while time.time() < deadline and proc.poll() is None:
        try:
            with open(d / "progress.json", encoding="utf-8") as f:
                if json.load(f)["episodes_done"] >= 2:
                    break
        except (OSError, ValueError, KeyError):
            pass
        time.sleep(0.2)
    proc.send_signal(signal.SIGTERM)
    results = {name: (d, *_finish(p)) for name, (d, p) in started.items()}

    # ... keep what the interrupted run saved, then resume it up to 3 episodes
    d = results["cartpole"][0]
    with open(d / "summary.json", encoding="utf-8") as f:
        results["cartpole_interrupted_summary"] = json.load(f)
    results["cartpole_resumed"] = (d, *_finish(_start(
        "cartpole.py", d, ["--resume", str(d), "--episodes", "3"])))
    return results


def _load_summary(d):
    with open(d / "summary.json", encoding="utf-8") as f:
        return json.load(f)


def _check_summary(s, task, episodes, extra=(), episode_extra=None):
    assert set(s) == SUMMARY_KEYS | set(extra)
    assert s["task"] == task
    assert isinstance(s["seed"], int) and s["seed"] == 0
    assert isinstance(s["solved"], bool)
    assert s["solved_at_episode"] is None or isinstance(s["solved_at_episode"], int)
    assert s["solved"] == (s["solved_at_episode"] is not None)
    assert isinstance(s["complete"], bool) and isinstance(s["success"], bool)
    assert len(s["distances"]) == episodes
    assert [len(d) for d in s["distances"]] == [e["steps"] + 1 for e in s["episodes"]]
    assert set(s["seconds"]) == PHASE_KEYS | {"total"}
    assert all(isinstance(v, float) and v >= 0 for v in s["seconds"].values())
    assert len(s["episodes"]) == episodes
    for i, e in enumerate(s["episodes"], start=1):
        assert set(e) == EPISODE_KEYS | set((episode_extra or {}).get(i, ()))
        assert e["episode"] == i
        assert isinstance(e["random"], bool) and e["random"] == (i == 1)
        assert isinstance(e["steps"], int) and e["steps"] >= 1
        for k in ("cost", "final_distance", "min_distance"):
            assert isinstance(e[k], float) and np.isfinite(e[k]), k
        assert e["min_distance"] <= e["final_distance"] + 1e-12
        assert e["steps_to_target"] is None or 1 <= e["steps_to_target"] <= e["steps"]
        assert set(e["seconds"]) == PHASE_KEYS
        assert all(isinstance(v, float) for v in e["seconds"].values())
        if e["random"]:
            assert e["seconds"]["model"] == 0.0 and e["seconds"]["policy"] == 0.0
            assert e["policy_evaluations"] == 0
        else:
            assert e["seconds"]["policy"] > 0.0
            assert isinstance(e["policy_evaluations"], int) and e["policy_evaluations"] >= 1
    total = sum(e["seconds"]["policy"] for e in s["episodes"])
    assert s["seconds"]["policy"] == pytest.approx(total)


def _check_data(d, summary, state_dim, action_dim):
    with np.load(d / "data.npz") as data:
        steps = [e["steps"] for e in summary["episodes"]]
        X, Y = data["X"], data["Y"]
        assert X.shape == (sum(steps), state_dim + action_dim)
        assert Y.shape == (sum(steps), state_dim)
        np.testing.assert_array_equal(np.bincount(data["episode"])[1:], steps)
        for i, n in enumerate(steps, start=1):
            S = data[f"states_{i}"]
            assert S.shape == (n + 1, state_dim)
            np.testing.assert_allclose(Y[data["episode"] == i], np.diff(S, axis=0))


def _ok(result):
    d, code, out = result
    assert code == 0, out[-3000:]
    return d, out


def test_cartpole_summary_data_figures(runs):
    d, out = _ok(runs["cartpole_resumed"])  # summary of the resumed run: 3 episodes
    assert "Controller optimisation" in out and "Whole program" in out
    s = _load_summary(d)
    _check_summary(s, "cartpole", 3)
    # the cart-pole's success: held for good, from the first solved learned episode on
    learned = [e["episode"] for e in s["episodes"] if not e["random"]]
    solved = s["solved_episodes"]
    assert s["solved"] == bool(solved) and (not solved or solved[0] == s["solved_at_episode"])
    assert s["held_for_good"] == (bool(solved) and solved == [e for e in learned
                                                              if e >= solved[0]])
    assert s["complete"] is True and s["success"] == s["held_for_good"]
    _check_data(d, s, 4, 1)
    for name in FIGURES + ["final_episode.gif", "final_episode_strip.png"]:
        assert (d / name).stat().st_size > 0, name


def test_cartpole_resume_continues(runs):
    d, out = _ok(runs["cartpole_resumed"])
    with open(d / "progress.json", encoding="utf-8") as f:
        progress = json.load(f)
    assert progress["episodes_done"] == 3
    assert progress["interrupted"] is False
    assert progress["settings"]["horizon"] == 8  # settings of the first run were kept
    assert progress["settings"]["episodes"] == 3  # ... except those given again
    assert progress["agent_saved"] is True and (d / "agent.npz").exists()
    before = runs["cartpole_interrupted_summary"]["episodes"]
    after = _load_summary(d)["episodes"]
    assert after[: len(before)] == before  # the interrupted run's episodes were kept


def test_sigterm_saves_and_exits_cleanly(runs):
    _, code, out = runs["cartpole"]
    assert code == 130, out[-3000:]
    assert "Interrupted" in out and "--resume" in out and "Traceback" not in out
    s = runs["cartpole_interrupted_summary"]
    assert 2 <= len(s["episodes"]) < 6
    assert s["complete"] is False
    _check_summary(s, "cartpole", len(s["episodes"]))


@pytest.mark.parametrize("name,task", [("reacher", "reacher"), ("damaged", "damaged_reacher")])
def test_reacher(runs, name, task):
    pytest.importorskip("mujoco")
    d, out = _ok(runs[name])
    s = _load_summary(d)
    _check_summary(s, task, 2)
    last = s["episodes"][-1]
    assert s["success"] == (last["steps_to_target"] is not None
                            and last["steps_to_target"] <= 15)
    _check_data(d, s, 10, 7)
    for figure in FIGURES:
        assert (d / figure).stat().st_size > 0, figure


def test_adaptation(runs):
    pytest.importorskip("mujoco")
    d, out = _ok(runs["adaptation"])
    s = _load_summary(d)
    _check_summary(s, "adaptation", 4, extra=("healthy_reached_at_episode",
                                              "damage_at_episode", "episodes_to_recover",
                                              "stuck_joints", "joint_follow_ratio"),
                   episode_extra={4: ("replanned",)})  # the first damaged episode re-plans
    assert s["damage_at_episode"] == 4  # both healthy episodes ran, reached or not
    assert s["healthy_reached_at_episode"] in (None, 2, 3)
    # the first damaged episode found the stuck elbow (action 3): it never moved
    assert s["stuck_joints"] == [3] and s["joint_follow_ratio"][3] == 0.0
    assert s["episodes"][3]["replanned"]["stuck_joints"] == [3]
    assert s["episodes_to_recover"] is None or s["episodes_to_recover"] == 1
    assert s["success"] == (s["episodes_to_recover"] is not None) and s["complete"] is True
    _check_data(d, s, 10, 7)
    assert (d / "adaptation_distance.png").stat().st_size > 0
