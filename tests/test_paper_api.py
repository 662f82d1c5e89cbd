"""The API the paper's code (the nrontsis/PILCO GPflow port) shares with this library:
a script written against it runs here unchanged and means the same.

Each test takes one line of such a script (as ``examples/pendulum.py`` writes it) and
checks what it does here, with tiny sizes: 2 basis functions, horizon 3, 2 optimiser
iterations.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from gpflow import set_trainable

from pilco.controllers import RbfController
from pilco.models import PILCO
from pilco.rewards import ExponentialReward
from pilco.snapshots import restore, snapshot

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
M_INIT = np.reshape([-1.0, 0.0, 0.0], (1, 3))
S_INIT = np.diag([0.01, 0.05, 0.01])
TARGET = np.array([1.0, 0.0, 0.0])
W = np.diag([2.0, 2.0, 0.3])


def transitions(n=20, seed=0):
    """``X [n, 4] = [cos, sin, dtheta, u]`` and ``Y [n, 3]`` (float32, as gymnasium's
    observations are) of a smooth made-up system."""
    rng = np.random.default_rng(seed)
    theta = rng.uniform(-np.pi, np.pi, n)
    X = np.column_stack([np.cos(theta), np.sin(theta), rng.uniform(-2, 2, n),
                         rng.uniform(-2, 2, n)]).astype(np.float32)
    Y = np.column_stack([-0.1 * X[:, 1], 0.1 * X[:, 0], 0.2 * X[:, 3] - 0.3 * X[:, 1]])
    return X, Y.astype(np.float32)


def paper_agent(data=None, horizon=3):
    """The construction lines of the paper's pendulum script."""
    X, Y = transitions() if data is None else data
    state_dim = Y.shape[1]
    control_dim = X.shape[1] - state_dim
    controller = RbfController(state_dim=state_dim, control_dim=control_dim,
                               num_basis_functions=2, max_action=2.0)
    R = ExponentialReward(state_dim=state_dim, t=TARGET, W=W)
    return PILCO((X, Y), controller=controller, horizon=horizon, reward=R,
                 m_init=M_INIT, S_init=S_INIT)


def fix_noise(pilco, value=1e-3):
    for model in pilco.mgpr.models:
        model.likelihood.variance.assign(value)
        set_trainable(model.likelihood.variance, False)


def test_fixed_noise_stays_fixed_through_model_restarts():
    """``likelihood.variance.assign`` + ``set_trainable(..., False)``: the noise is the
    user's value after training with restarts (a restart must not draw a new one), and
    the trainable hyperparameters did move."""
    pilco = paper_agent()
    fix_noise(pilco, 1e-3)
    before = [m.kernel.lengthscales.numpy().copy() for m in pilco.mgpr.models]
    pilco.optimize_models(maxiter=5, restarts=3, seed=0)
    for model, ell in zip(pilco.mgpr.models, before):
        assert float(model.likelihood.variance.numpy()) == pytest.approx(1e-3, rel=1e-12)
        assert not model.likelihood.variance.trainable
        assert not np.allclose(model.kernel.lengthscales.numpy(), ell)
    # a restart starts the free hyperparameters afresh and leaves the fixed one alone
    pilco.mgpr.initialize_hyperparameters(np.random.default_rng(1), spread=0.5)
    assert all(float(m.likelihood.variance.numpy()) == pytest.approx(1e-3, rel=1e-12)
               for m in pilco.mgpr.models)


def test_np_random_seed_makes_a_paper_script_repeatable():
    """The paper's scripts start with ``np.random.seed(0)``: the unseeded draws (the
    initial policy, the random starts of policy and model restarts) then repeat; another
    seed draws other values."""
    pilco = paper_agent()

    def draws(seed):
        np.random.seed(seed)
        controller = RbfController(state_dim=3, control_dim=1, num_basis_functions=2)
        pilco.controller.randomize()  # what optimize_policy's restarts call
        pilco.mgpr.initialize_hyperparameters(spread=0.5)  # optimize_models' restarts
        return (controller.centers.numpy(), pilco.controller.centers.numpy().copy(),
                pilco.mgpr.hyperparameters()[0].numpy())

    first, again, other = draws(3), draws(3), draws(4)
    for a, b, c in zip(first, again, other):
        np.testing.assert_array_equal(a, b)
        assert not np.allclose(a, c)


def test_construction_action_and_prediction_mean_what_the_paper_script_expects():
    """``PILCO((X, Y), controller=, horizon=, reward=, m_init=, S_init=)`` on float32
    data; ``compute_action(x[None, :])`` is the policy's action [1, U] at a known state;
    ``predict(m, S, T)`` is the state after T steps, its covariance and the total
    expected reward of steps 1..T."""
    X, Y = transitions()
    pilco = paper_agent((X, Y), horizon=3)
    assert (pilco.state_dim, pilco.control_dim, pilco.horizon) == (3, 1, 3)
    np.testing.assert_array_equal(pilco.m_init, M_INIT)
    np.testing.assert_array_equal(pilco.S_init, S_INIT)
    np.testing.assert_array_equal(pilco.data[0], X.astype(np.float64))

    x = X[0, :3]
    u = pilco.compute_action(x[None, :])
    assert isinstance(u, np.ndarray) and u.shape == (1, 1)
    expected, _, _ = pilco.controller.compute_action(x[None, :].astype(np.float64),
                                                    np.zeros((3, 3)))
    np.testing.assert_allclose(u, expected.numpy(), rtol=1e-10)
    assert abs(u[0, 0]) <= 2.0  # max_action
    assert pilco.compute_action(x[None, :])[0, :].shape == (1,)  # the script's policy line

    m, S, total = pilco.predict(M_INIT, S_INIT, 3)
    assert tuple(m.shape) == (1, 3) and tuple(S.shape) == (3, 3)
    assert tuple(total.shape) == (1, 1)
    mi, si, summed = M_INIT, S_INIT, 0.0
    for _ in range(3):
        mi, si = pilco.propagate(mi, si)
        summed += float(pilco.reward.compute_reward(mi, si)[0][0, 0])
    np.testing.assert_allclose(m, mi, rtol=1e-8)
    np.testing.assert_allclose(S, si, rtol=1e-8, atol=1e-12)
    assert float(total[0, 0]) == pytest.approx(summed, rel=1e-8)

    # the reward as the script checks it by inspection: mean and variance, 1 at the target
    r, v = pilco.reward.compute_reward(TARGET[None, :], 1e-9 * np.eye(3))
    assert float(r[0, 0]) == pytest.approx(1.0, abs=1e-6) and float(v[0, 0]) > -1e-12


def test_optimizers_take_maxiter_and_restarts(monkeypatch):
    """``optimize_models(maxiter=, restarts=)`` and ``optimize_policy(maxiter=,
    restarts=)``: at most ``maxiter`` iterations per run, ``restarts`` runs in all, each
    further run from a new random start; the policy ends at least as good as it began."""
    pilco = paper_agent()
    iterations = []
    pilco.optimize_models(maxiter=2, restarts=2, callback=iterations.append)
    assert 2 < len(iterations) <= 4  # two runs of at most 2 iterations

    draws = []
    randomize = pilco.controller.randomize
    monkeypatch.setattr(pilco.controller, "randomize",
                        lambda *a, **k: (draws.append(1), randomize(*a, **k)))
    before = pilco.expected_return()
    iterations.clear()
    best = pilco.optimize_policy(maxiter=2, restarts=2, callback=iterations.append)
    assert len(draws) == 1  # the second run starts from a random policy
    assert 2 < len(iterations) <= 4
    assert best >= before - 1e-9
    assert pilco.expected_return() == pytest.approx(best, rel=1e-9)


def test_data_added_through_mgpr_set_data_are_what_the_agent_sees(tmp_path):
    """The paper's scripts add data with ``pilco.mgpr.set_data((X, Y))``: ``pilco.data``,
    the saved file, the loaded agent, its predictions and the model's evidence all see
    every transition."""
    X, Y = transitions(12)
    pilco = paper_agent((X, Y))
    fix_noise(pilco)
    X_new, Y_new = transitions(8, seed=1)
    X, Y = np.vstack((X, X_new)), np.vstack((Y, Y_new))
    pilco.mgpr.set_data((X, Y))

    data_X, data_Y = pilco.data
    assert len(data_X) == 20
    np.testing.assert_array_equal(data_X, X.astype(np.float64))
    np.testing.assert_array_equal(data_Y, Y.astype(np.float64))
    assert pilco.mgpr.X.shape[0] == 20

    path = pilco.save(tmp_path / "agent.npz")
    with np.load(path) as stored:
        np.testing.assert_array_equal(stored["data/X"], data_X)
        np.testing.assert_array_equal(stored["data/Y"], data_Y)
    loaded = PILCO.load(path)
    np.testing.assert_array_equal(loaded.data[0], data_X)
    np.testing.assert_allclose(loaded.mgpr.log_marginal_likelihood(),
                               pilco.mgpr.log_marginal_likelihood(), rtol=1e-10)
    assert all(float(m.likelihood.variance.numpy()) == pytest.approx(1e-3)
               and not m.likelihood.variance.trainable for m in loaded.mgpr.models)
    for a, b in zip(pilco.predict(M_INIT, S_INIT, 3), loaded.predict(M_INIT, S_INIT, 3)):
        np.testing.assert_allclose(a, b, rtol=1e-8)


def assert_same_values(module, expected, **tolerance):
    """Every parameter of ``module`` as in ``expected`` (a module of the same structure)."""
    got, want = snapshot(module), snapshot(expected)
    assert got.keys() == want.keys()
    for path, value in want.items():
        np.testing.assert_allclose(got[path], value, err_msg=path, **tolerance)


def test_training_after_mgpr_set_data_uses_the_new_data():
    """The optimisers keep their compiled objectives across calls (GPflow's Scipy caches
    them): a second ``optimize_models`` / ``optimize_policy`` after
    ``pilco.mgpr.set_data`` must train on the new data, not on data captured when the
    objective was first compiled. Training an agent that saw the small data set first
    gives exactly what training a new agent on the large set from the same values gives."""
    X, Y = transitions(12)
    X_new, Y_new = transitions(10, seed=1)
    X_all, Y_all = np.vstack((X, X_new)), np.vstack((Y, Y_new))

    used = paper_agent((X, Y))
    fix_noise(used)
    used.optimize_models(maxiter=3)
    used.optimize_policy(maxiter=2)  # both objectives compiled on 12 transitions
    used.mgpr.set_data((X_all, Y_all))

    fresh = paper_agent((X_all, Y_all))
    fix_noise(fresh)
    restore(fresh.mgpr, snapshot(used.mgpr))
    restore(fresh.controller, snapshot(used.controller))
    assert fresh.expected_return() == pytest.approx(used.expected_return(), rel=1e-10)

    used.optimize_models(maxiter=3)
    fresh.optimize_models(maxiter=3)
    assert_same_values(used.mgpr, fresh.mgpr, rtol=1e-8)
    best_used = used.optimize_policy(maxiter=3)
    best_fresh = fresh.optimize_policy(maxiter=3)
    assert best_used == pytest.approx(best_fresh, rel=1e-8)
    assert_same_values(used.controller, fresh.controller, rtol=1e-8, atol=1e-12)


# ------------------------------------------------ examples/pendulum.py and its sweep task
@pytest.fixture(scope="module")
def pendulum_runs(tmp_path_factory):
    """``examples/pendulum.py``, ``python -m pilco.tasks pendulum`` and the benchmark's
    workload script with tiny settings, started together;
    ``{name: (directory, returncode, output)}``."""
    base = tmp_path_factory.mktemp("pendulum")
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""),
               TF_CPP_MIN_LOG_LEVEL="3", OMP_NUM_THREADS="1")
    commands = {
        "example": [os.path.join(ROOT, "examples", "pendulum.py"), "--iterations", "1",
                    "--rollout-steps", "5", "--basis-functions", "2", "--maxiter", "2",
                    "--quiet", "--seed", "1", "--output", str(base / "example" / "agent.npz")],
        "task": ["-m", "pilco.tasks", "pendulum", "--episodes", "2", "--random-episodes", "1",
                 "--horizon", "5", "--basis-functions", "2", "--policy-iters", "2",
                 "--model-iters", "2", "--quiet", "--output", str(base / "task")],
        # the port's pendulum workload that benchmarks/bench_pendulum.py times
        "workload": [os.path.join(ROOT, "benchmarks", "pendulum_workload.py"),
                     "--iterations", "1", "--maxiter", "2", "--restarts", "1"],
    }
    procs = {name: subprocess.Popen([sys.executable, *cmd], cwd=ROOT, env=env, text=True,
                                    stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
             for name, cmd in commands.items()}
    out = {}
    for name, proc in procs.items():
        text, _ = proc.communicate(timeout=600)
        out[name] = (base / name, proc.returncode, text)
    return out


def test_pendulum_example_keeps_every_transition(pendulum_runs):
    """The paper-style script runs unchanged: 4 random rollouts and 1 learned one of 5
    steps, data added with ``pilco.mgpr.set_data``, all 25 transitions in the saved agent."""
    d, code, out = pendulum_runs["example"]
    assert code == 0, out[-3000:]
    assert "seed 1: up first at iteration None, up in the last: False; 25 transitions" in out
    assert "iteration 1: return" in out  # the script's per-iteration line
    with np.load(d / "agent.npz") as agent:
        X, Y = agent["data/X"], agent["data/Y"]
        meta = json.loads(str(agent["__meta__"]))
        noise = agent["gp/noise"]
    assert X.shape == (25, 4) and Y.shape == (25, 3)
    for start in range(0, 25, 5):  # rollouts of 5 steps, each starting hanging down
        rows = slice(start, start + 5)
        assert X[start, 0] < -0.99
        np.testing.assert_allclose(X[rows][1:, :3], X[rows][:-1, :3] + Y[rows][:-1], atol=1e-6)
    assert np.all(np.abs(X[:, 3]) <= 2.0)
    np.testing.assert_allclose(noise, 1e-3)
    assert meta["trainable"]["gp/noise"] == [False, False, False]


def test_pendulum_task_summary_for_the_sweep(pendulum_runs):
    d, code, out = pendulum_runs["task"]
    assert code == 0, out[-3000:]
    with open(d / "summary.json", encoding="utf-8") as f:
        s = json.load(f)
    assert s["task"] == "pendulum" and s["complete"] is True
    assert [e["random"] for e in s["episodes"]] == [True, False]
    assert [len(x) for x in s["distances"]] == [6, 6]
    assert all(x[0] > 2.5 for x in s["distances"])  # every episode starts hanging down
    last = np.asarray(s["distances"][-1][1:])
    assert s["success"] == bool(np.all(last[-10:] < 0.3) and len(last) >= 10)
    assert s["success"] is False  # 5 steps cannot hold the pendulum up for 10
    with np.load(d / "data.npz") as data:
        assert data["X"].shape == (10, 4)
    with np.load(d / "agent.npz") as agent:
        np.testing.assert_allclose(agent["gp/noise"], 1e-3)
    for name in ("distance.png", "one_step.png", "final_episode.gif"):
        assert (d / name).exists(), name


def test_the_benchmark_workload_runs_unchanged_on_this_library(pendulum_runs):
    """``benchmarks/pendulum_workload.py`` (the port's pendulum example in the paper
    code's API, which ``bench_pendulum.py`` also runs against the port): 4 random and 1
    learned rollout of 40 steps, the phases timed, one JSON line."""
    d, code, out = pendulum_runs["workload"]
    assert code == 0, out[-3000:]
    result = json.loads([line for line in out.splitlines() if line.startswith("{")][-1])
    assert result["library"] == "pilco" and result["transitions"] == 200
    (iteration,) = result["iterations"]
    assert iteration["transitions"] == 160 and isinstance(iteration["up"], bool)
    for phase in ("model", "policy", "rollout"):
        assert 0.0 < iteration[phase] <= result["seconds"]
    # each figure is rounded to 0.01 s
    assert result["seconds"] >= result["setup"] + result["model"] + result["policy"] - 0.03
