"""Every public way data reach an agent keeps PILCO.data, the saved file, predictions and
training consistent (the raw transitions are the one source of the model's data)."""
import json
import subprocess
import sys

import numpy as np
import pytest

from pilco.controllers import RbfController
from pilco.models import MGPR, PILCO
from pilco.rewards import ExponentialReward

D, U = 2, 1

LOAD = """
import json, sys
import numpy as np
from pilco.models import PILCO
agent = PILCO.load(sys.argv[1])
X, Y = agent.data
gp_X = np.asarray(agent.mgpr.X)
print(json.dumps(dict(X=X.tolist(), Y=Y.tolist(), gp_rows=len(gp_X),
                      gp_consistent=bool(np.array_equal(gp_X, agent.gp_inputs(X))))))
"""


def make_agent(angles=(), sparse=False, n=8, seed=0):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-1.0, 1.0, (n, D + U))
    Y = 0.1 * rng.standard_normal((n, D))
    return PILCO((X, Y), RbfController(D + len(angles), U, 3, seed=seed), ExponentialReward(D),
                 angle_indices=angles, num_induced_points=4 if sparse else None)


def more_data(n=13, seed=5):
    rng = np.random.default_rng(seed)
    return rng.uniform(-1.0, 1.0, (n, D + U)), 0.1 * rng.standard_normal((n, D))


def reload_in_fresh_process(agent, path):
    agent.save(path)
    out = subprocess.run([sys.executable, "-c", LOAD, str(path)], capture_output=True,
                         text=True, check=True)
    got = json.loads(out.stdout.strip().splitlines()[-1])
    return np.array(got["X"]), np.array(got["Y"]), got["gp_rows"], got["gp_consistent"]


def assert_round_trip(agent, X, Y, path):
    np.testing.assert_array_equal(agent.data[0], X)
    np.testing.assert_array_equal(agent.data[1], Y)
    np.testing.assert_array_equal(np.asarray(agent.mgpr.X), agent.gp_inputs(X))
    mean, _ = agent.one_step_prediction(X[:2])  # predictions run on the new data
    assert mean.shape == (2, D) and np.all(np.isfinite(mean))
    got_X, got_Y, rows, consistent = reload_in_fresh_process(agent, path)
    assert got_X.shape == X.shape and rows == len(X) and consistent
    np.testing.assert_array_equal(got_X, X)
    np.testing.assert_array_equal(got_Y, Y)


@pytest.mark.parametrize("angles", [(), (1,)], ids=["plain", "angle"])
def test_pilco_set_data(tmp_path, angles):
    agent = make_agent(angles)
    X, Y = more_data()
    agent.set_data((X, Y))
    assert_round_trip(agent, X, Y, tmp_path / "agent.npz")


@pytest.mark.parametrize("sparse", [False, True], ids=["exact", "sparse"])
def test_model_set_data_without_angles(tmp_path, sparse):
    agent = make_agent(sparse=sparse)
    X, Y = more_data()
    agent.mgpr.set_data((X, Y))  # the paper code's way: GP inputs are the raw data here
    assert_round_trip(agent, X, Y, tmp_path / "agent.npz")
    agent.optimize_models(maxiter=3)  # training sees the same data
    np.testing.assert_array_equal(np.asarray(agent.mgpr.X), X)


def test_model_shared_by_two_agents(tmp_path):
    first, second = make_agent(seed=0), make_agent(seed=1)
    second.mgpr = first.mgpr  # adopts the shared model's data
    np.testing.assert_array_equal(second.data[0], first.data[0])
    X, Y = more_data()
    first.mgpr.set_data((X, Y))
    assert_round_trip(first, X, Y, tmp_path / "first.npz")
    assert_round_trip(second, X, Y, tmp_path / "second.npz")


def test_model_set_data_with_angles_is_refused(tmp_path):
    agent = make_agent(angles=(1,))
    X0, Y0 = agent.data
    X, Y = more_data()
    gp_X = agent.gp_inputs(X)
    with pytest.raises(ValueError, match=r"PILCO\.set_data"):
        agent.mgpr.set_data((gp_X, Y))
    # nothing changed: raw data, model data and the file agree
    assert_round_trip(agent, X0, Y0, tmp_path / "agent.npz")
    # the consistent data (those of PILCO.set_data) are accepted
    agent.mgpr.set_data((agent.gp_inputs(X0), Y0))
    with pytest.raises(ValueError, match=r"PILCO\.set_data"):
        agent.mgpr = MGPR((gp_X, Y))
    assert np.asarray(agent.mgpr.X).shape[0] == len(X0)


def test_replaced_model_no_longer_drives_the_agent():
    agent = make_agent()
    old = agent.mgpr
    agent.mgpr = MGPR(agent.data)
    X, Y = more_data()
    old.set_data((X, Y))
    assert len(agent.data[0]) == 8


def test_gp_data_without_raw_states(tmp_path):
    agent = make_agent(angles=(1,))
    X, Y = more_data()
    gp_X = agent.gp_inputs(X)
    gp_X[:, 1:3] *= 0.5  # (sin, cos) columns that no angle produces
    agent.set_gp_data((gp_X, Y))
    np.testing.assert_array_equal(np.asarray(agent.mgpr.X), gp_X)
    with pytest.raises(ValueError, match=r"raw transitions are unknown .*PILCO\.set_data"):
        agent.data
    with pytest.raises(ValueError, match="raw transitions are unknown"):
        agent.save(tmp_path / "agent.npz")
    assert not list(tmp_path.iterdir())
    agent.set_data((X, Y))  # raw transitions again: consistent and savable
    assert_round_trip(agent, X, Y, tmp_path / "agent.npz")
