"""Saving and loading agents (PILCO.save, PILCO.load): exact round trips, atomic writes,
errors."""
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import gpflow
import numpy as np
import pytest

from pilco.controllers import LinearController, RbfController, squash_sat, squash_sin
from pilco.models import MGPR, PILCO, SMGPR
from pilco.rewards import (AxisBumpsReward, CartPoleReward, CombinedRewards, ExponentialReward,
                           LinearReward)

ROOT = Path(__file__).resolve().parents[1]


def _data(rng, D, U, N=20):
    X = rng.standard_normal((N, D + U))
    Y = 0.1 * rng.standard_normal((N, D))
    return X, Y


def rbf_agent(seed=0):
    """D=3 with an angle, RBF policy (sat), combined reward, exact GP."""
    rng = np.random.default_rng(seed)
    D, U, ang = 3, 1, (1,)
    X, Y = _data(rng, D, U)
    controller = RbfController(D + len(ang), U, 6, max_action=2.0, squash=squash_sat, seed=seed)
    controller.set_data((rng.standard_normal((6, D + 1)), rng.standard_normal((6, U))))
    controller.models[0].kernel.lengthscales.assign(rng.uniform(0.5, 2.0, D + 1))
    reward = CombinedRewards(
        D, [ExponentialReward(D, W=np.diag([1.0, 2.0, 0.5]), t=np.arange(D)),
            CombinedRewards(D, [LinearReward(D, [0.1, -0.2, 0.3]),
                                AxisBumpsReward(D, [0, 2, 2], [0.5, -1.0, 1.0],
                                                [0.3, 0.2, 0.4], [1.0, 0.5, 2.0])],
                            coefs=[0.5, -0.7])],
        coefs=[1.0, -0.25],
    )
    agent = PILCO((X, Y), controller, reward, horizon=5, angle_indices=ang,
                  m_init=rng.standard_normal((1, D)), S_init=0.05 * np.eye(D))
    for i, m in enumerate(agent.mgpr.models):
        m.kernel.lengthscales.assign(rng.uniform(0.5, 3.0, agent.feature_dim + U))
        m.kernel.variance.assign(0.3 + 0.1 * i)
        m.likelihood.variance.assign(1e-3 * (i + 1))
    gpflow.set_trainable(agent.mgpr.models[0].kernel.variance, False)
    gpflow.set_trainable(controller.models[0].kernel.variance, True)
    return agent


def sparse_agent(seed=1):
    """Cart-pole sized (D=4, angle 3), linear policy (sin), sparse GP with a raised floor."""
    rng = np.random.default_rng(seed)
    D, U, ang = 4, 1, (3,)
    X, Y = _data(rng, D, U)
    controller = LinearController(D + 1, U, max_action=[3.0], squash=squash_sin, seed=seed)
    controller.b.assign([[0.3]])
    agent = PILCO((X, Y), controller, CartPoleReward(pendulum_length=0.6, width=0.3),
                  horizon=4, angle_indices=ang, num_induced_points=7, policy_input_noise=True)
    gp_data = (agent.gp_inputs(X), Y)
    agent.mgpr = SMGPR(gp_data, 7, noise_floor=1e-4, seed=seed)
    for m in agent.mgpr.models:
        m.kernel.lengthscales.assign(rng.uniform(0.5, 3.0, agent.feature_dim + U))
        m.likelihood.variance.assign(1.0001e-4)  # just above its floor
    agent.mgpr.inducing_variable.Z.assign(rng.standard_normal((7, agent.feature_dim + U)))
    return agent


def outputs(agent, states):
    """What must not change across a save/load: actions and the predicted rollout."""
    actions = np.concatenate([agent.compute_action(x) for x in states])
    m, s, r = agent.predict()  # NumPy arrays
    return dict(actions=actions, m=m, s=s, r=r)


def test_round_trip_in_a_fresh_process_is_exact(tmp_path):
    agent = rbf_agent()
    agent.save(tmp_path / "run" / "agent.npz")
    states = np.random.default_rng(5).standard_normal((3, agent.state_dim))
    np.save(tmp_path / "states.npy", states)
    expected = outputs(agent, states)
    script = textwrap.dedent(f"""
        import sys
        import numpy as np
        sys.path.insert(0, {str(ROOT)!r}); sys.path.insert(0, {str(Path(__file__).parent)!r})
        from pilco.models import PILCO
        from test_persistence import outputs
        agent = PILCO.load({str(tmp_path / "run" / "agent.npz")!r})
        states = np.load({str(tmp_path / "states.npy")!r})
        np.savez({str(tmp_path / "out.npz")!r}, **outputs(agent, states))
    """)
    env = dict(os.environ, TF_CPP_MIN_LOG_LEVEL="3")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    with np.load(tmp_path / "out.npz") as got:
        for key, value in expected.items():
            np.testing.assert_array_equal(got[key], value, err_msg=key)


def test_load_restores_every_setting_and_parameter(tmp_path):
    for agent in (rbf_agent(), sparse_agent()):
        path = tmp_path / "agent.npz"
        agent.save(path)
        back = PILCO.load(path)
        assert type(back.controller) is type(agent.controller)
        assert type(back.mgpr) is type(agent.mgpr)
        assert back.controller.squash is agent.controller.squash
        for attr in ("horizon", "angle_indices", "num_induced_points", "policy_input_noise",
                     "state_dim", "control_dim"):
            assert getattr(back, attr) == getattr(agent, attr), attr
        assert back.mgpr.noise_floor == agent.mgpr.noise_floor
        np.testing.assert_array_equal(back.m_init, agent.m_init)
        np.testing.assert_array_equal(back.S_init, agent.S_init)
        for a, b in zip(agent.data, back.data):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(back.controller.max_action, agent.controller.max_action)
        for module in ("mgpr", "controller", "reward"):
            want = gpflow.utilities.parameter_dict(getattr(agent, module))
            got = gpflow.utilities.parameter_dict(getattr(back, module))
            assert set(want) == set(got), module
            for key, p in want.items():
                np.testing.assert_array_equal(got[key].numpy(), p.numpy(), err_msg=key)
                assert getattr(got[key], "trainable", None) == getattr(p, "trainable", None), key
    # the recursive reward structure survives
    assert isinstance(back.reward, CartPoleReward)
    assert (back.reward.pendulum_length, back.reward.width) == (0.6, 0.3)


def test_loaded_agent_continues_learning(tmp_path):
    agent = rbf_agent()
    agent.save(tmp_path / "agent.npz")
    back = PILCO.load(tmp_path / "agent.npz")
    # the optimisers see the same free variables
    for module in ("mgpr", "controller"):
        want = [v.shape for v in getattr(agent, module).trainable_variables]
        assert [v.shape for v in getattr(back, module).trainable_variables] == want
    X, Y = back.data
    rng = np.random.default_rng(3)
    back.set_data((np.vstack([X, rng.standard_normal((5, X.shape[1]))]),
                   np.vstack([Y, 0.1 * rng.standard_normal((5, Y.shape[1]))])))
    back.optimize_models(maxiter=2)
    back.save(tmp_path / "agent.npz")  # overwrite in place
    again = PILCO.load(tmp_path / "agent.npz")
    assert len(again.data[0]) == len(X) + 5
    np.testing.assert_array_equal(again.mgpr.hyperparameters()[0], back.mgpr.hyperparameters()[0])


def test_file_is_one_npz_without_pickles(tmp_path):
    path = tmp_path / "run" / "agent.npz"
    rbf_agent().save(path)
    assert sorted(os.listdir(path.parent)) == ["agent.npz"]  # no temporary file left
    with np.load(path, allow_pickle=False) as z:
        assert all(z[k].dtype != object for k in z.files)
        meta = json.loads(str(z["__meta__"]))
    assert meta["format"] == "pilco-agent"
    assert meta["controller"]["type"] == "RbfController"
    assert meta["controller"]["squash"] == "squash_sat"
    assert meta["reward"]["rewards"][1]["rewards"][0]["type"] == "LinearReward"


def test_failed_write_keeps_the_old_file(tmp_path, monkeypatch):
    agent = rbf_agent()
    path = tmp_path / "agent.npz"
    agent.save(path)
    before = path.read_bytes()

    def broken(fh, **arrays):
        fh.write(b"partial")
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez_compressed", broken)
    with pytest.raises(OSError, match="disk full"):
        agent.save(path)
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["agent.npz"]


def test_write_is_flushed_and_renamed(tmp_path, monkeypatch):
    calls = []
    real_fsync, real_replace = os.fsync, os.replace
    monkeypatch.setattr(os, "fsync", lambda fd: (calls.append("fsync"), real_fsync(fd)))
    monkeypatch.setattr(os, "replace",
                        lambda a, b: (calls.append(("replace", Path(a).parent == Path(b).parent)),
                                      real_replace(a, b)))
    rbf_agent().save(tmp_path / "agent.npz")
    assert calls[0] == "fsync" and calls[1] == ("replace", True)


class _MyController(RbfController):
    pass


class _MyReward(ExponentialReward):
    pass


@pytest.mark.parametrize("what", ["controller", "squash", "reward", "nested reward", "model"])
def test_unsupported_components_fail_at_save_time(tmp_path, what):
    agent = rbf_agent()
    if what == "controller":
        c = _MyController(4, 1, 6)
        agent.controller = c
        match = "controller of type _MyController"
    elif what == "squash":
        agent.controller.squash = lambda m, s, e: squash_sin(m, s, e)
        match = "squash function"
    elif what == "reward":
        agent.reward = _MyReward(3)
        match = "reward of type _MyReward"
    elif what == "nested reward":
        agent.reward = CombinedRewards(3, [ExponentialReward(3), _MyReward(3)])
        match = "reward of type _MyReward"
    else:
        agent.mgpr = type("OtherGP", (MGPR,), {})((agent.mgpr.X.numpy(), agent.mgpr.Y.numpy()))
        match = "dynamics model of type OtherGP"
    with pytest.raises(TypeError, match=match):
        agent.save(tmp_path / "agent.npz")
    assert not os.listdir(tmp_path)


def test_load_rejects_other_files(tmp_path):
    agent = rbf_agent()
    agent.export_policy(tmp_path / "policy.npz")
    with pytest.raises(ValueError, match="format 'pilco-policy', expected 'pilco-agent'"):
        PILCO.load(tmp_path / "policy.npz")
    np.savez(tmp_path / "other.npz", a=np.ones(2))
    with pytest.raises(ValueError, match="not a pilco-agent file"):
        PILCO.load(tmp_path / "other.npz")
    (tmp_path / "text.npz").write_text("hello")
    with pytest.raises(ValueError, match="not a pilco-agent file"):
        PILCO.load(tmp_path / "text.npz")
    with pytest.raises(FileNotFoundError):
        PILCO.load(tmp_path / "missing.npz")
    # a file from a newer pilco
    agent.save(tmp_path / "agent.npz")
    with np.load(tmp_path / "agent.npz") as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["__meta__"]))
    meta["version"] = 99
    arrays["__meta__"] = np.array(json.dumps(meta))
    np.savez(tmp_path / "newer.npz", **arrays)
    with pytest.raises(ValueError, match="version 99"):
        PILCO.load(tmp_path / "newer.npz")
    # no pilco wrote format versions other than 1 and 2: older, odd or missing ones are
    # refused
    for version in (0, -1, "1", 1.0, True):
        meta["version"] = version
        arrays["__meta__"] = np.array(json.dumps(meta))
        np.savez(tmp_path / "other.npz", **arrays)
        with pytest.raises(ValueError, match=f"agent format version {version!r} .*written by "
                                             r"pilco .*reads agent format versions 1 to 2$"):
            PILCO.load(tmp_path / "other.npz")
    # another pilco release writing the same format version: read as ours
    meta.update(version=1, pilco_version="0.0.1")
    arrays["__meta__"] = np.array(json.dumps(meta))
    np.savez(tmp_path / "release.npz", **arrays)
    np.testing.assert_array_equal(PILCO.load(tmp_path / "release.npz").data[0], agent.data[0])
    no_gp = {k: v for k, v in meta.items() if k != "gp"}
    np.savez(tmp_path / "no-gp.npz", **dict(arrays, __meta__=np.array(json.dumps(no_gp))))
    with pytest.raises(ValueError, match="is incomplete: its metadata lack 'gp'"):
        PILCO.load(tmp_path / "no-gp.npz")
    del arrays["gp/lengthscales"], arrays["gp/lengthscales_raw"]
    meta["version"] = 1
    arrays["__meta__"] = np.array(json.dumps(meta))
    np.savez(tmp_path / "broken.npz", **arrays)
    with pytest.raises(ValueError, match="'gp/lengthscales' is missing"):
        PILCO.load(tmp_path / "broken.npz")


def test_load_rejects_truncated_files_and_save_needs_a_path(tmp_path):
    agent = rbf_agent()
    content = Path(agent.save(tmp_path / "agent.npz")).read_bytes()
    for size in (len(content) - 1, len(content) // 2, 0):
        (tmp_path / "cut.npz").write_bytes(content[:size])
        with pytest.raises(ValueError, match="not a pilco-agent file written by pilco: it is "
                                             "truncated or not an .npz archive"):
            PILCO.load(tmp_path / "cut.npz")
    for path in (None, 7):
        with pytest.raises(TypeError, match="path must be a file path"):
            agent.save(path)
        with pytest.raises(TypeError, match="path must be a file path"):
            agent.export_policy(path)
        with pytest.raises(TypeError, match="path must be a file path"):
            PILCO.load(path)
    assert sorted(os.listdir(tmp_path)) == ["agent.npz", "cut.npz"]  # nothing written
