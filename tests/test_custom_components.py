"""Controllers and rewards of a user's own classes in agent files: the ``get_config``
protocol (pilco.models.custom)."""
import gpflow
import numpy as np
import pytest
import tensorflow as tf

from pilco.models import PILCO
from pilco.rewards import CombinedRewards, ExponentialReward

D, U = 2, 1


class AffinePolicy(gpflow.base.Module):
    """u = x W^T + b, written against pilco.protocols.Controller, storable by its config."""

    def __init__(self, state_dim, control_dim, gain=0.0):
        super().__init__()
        self.state_dim, self.control_dim, self.gain = state_dim, control_dim, gain
        self.W = gpflow.Parameter(np.full((control_dim, state_dim), gain))
        self.b = gpflow.Parameter(np.zeros((1, control_dim)))
        self.scale = gpflow.Parameter(1.0, transform=gpflow.utilities.positive())

    def get_config(self):
        return {"state_dim": self.state_dim, "control_dim": self.control_dim,
                "gain": np.float64(self.gain)}

    def prepare(self):
        return self.scale * tf.convert_to_tensor(self.W)

    def moments(self, m, s, squash=True, prepared=None):
        W = self.prepare() if prepared is None else prepared
        return (tf.matmul(m, W, transpose_b=True) + self.b,
                tf.matmul(W, tf.matmul(s, W, transpose_b=True)), tf.transpose(W))


class QuadraticCost(gpflow.base.Module):
    """r(x) = -w |x - t|^2 with its exact mean and variance; t is a constant from the
    config, w a Parameter."""

    def __init__(self, target, weight=1.0):
        super().__init__()
        self.target = np.asarray(target, dtype=np.float64)
        self.t = tf.constant(self.target.reshape(1, -1))
        self.state_dim = self.target.size
        self.w = gpflow.Parameter(weight, transform=gpflow.utilities.positive())

    @classmethod
    def from_config(cls, config):
        return cls(np.array(config["target"]), config["weight"])

    def get_config(self):
        return {"target": self.target, "weight": 1.0}

    def moments(self, m, s):
        d = m - self.t
        mean = -(tf.linalg.trace(s) + tf.matmul(d, d, transpose_b=True))
        var = 2.0 * tf.linalg.trace(s @ s) + 4.0 * tf.matmul(d @ s, d, transpose_b=True)
        w = tf.convert_to_tensor(self.w)
        return tf.reshape(w * mean, (1, 1)), tf.reshape(w * w * var, (1, 1))


class NoConfigCost(QuadraticCost):
    get_config = None


def agent(reward=None):
    rng = np.random.default_rng(0)
    X = rng.uniform(-1.0, 1.0, (25, D + U))
    Y = 0.1 * np.stack([X[:, 1], X[:, 2] - X[:, 1]], axis=1)
    controller = AffinePolicy(D, U, gain=0.1)
    controller.W.assign([[0.3, -0.2]])
    controller.scale.assign(0.7)
    gpflow.set_trainable(controller.b, False)
    reward = reward or QuadraticCost([1.0, 0.0])
    return PILCO((X, Y), controller, reward, horizon=4, m_init=np.zeros((1, D)),
                 S_init=0.01 * np.eye(D))


@pytest.mark.parametrize("nested", [False, True])
def test_custom_controller_and_reward_round_trip_exactly(tmp_path, nested):
    reward = QuadraticCost([1.0, 0.0], weight=2.0)
    reward.w.assign(0.35)  # a trained value, not the config's: restored from the file
    gpflow.set_trainable(reward.w, False)
    if nested:
        reward = CombinedRewards(D, [ExponentialReward(D, t=[[1.0, 0.0]]), reward],
                                 coefs=[1.0, 0.5])
    a = agent(reward)
    path = a.save(tmp_path / "agent.npz")
    b = PILCO.load(path)
    assert type(b.controller) is AffinePolicy and b.controller.gain == 0.1
    np.testing.assert_array_equal(b.controller.W.numpy(), [[0.3, -0.2]])
    assert b.controller.scale.numpy() == a.controller.scale.numpy()
    assert not b.controller.b.trainable and b.controller.W.trainable
    custom = b.reward.base_rewards[1] if nested else b.reward
    assert type(custom) is QuadraticCost and custom.w.numpy() == 0.35
    assert not custom.w.trainable
    assert b.expected_return() == a.expected_return()
    for x, y in zip(a.predict(), b.predict()):
        np.testing.assert_array_equal(x, y)


def test_a_component_without_get_config_is_refused_at_save(tmp_path):
    with pytest.raises(TypeError, match="reward of type NoConfigCost: define get_config"):
        agent(NoConfigCost([1.0, 0.0])).save(tmp_path / "agent.npz")


def test_a_class_defined_in_a_function_is_refused_at_save(tmp_path):
    class Local(QuadraticCost):
        pass

    with pytest.raises(TypeError, match="defined inside a function"):
        agent(Local([1.0, 0.0])).save(tmp_path / "agent.npz")


def test_a_config_that_is_not_json_is_refused_at_save(tmp_path):
    reward = QuadraticCost([1.0, 0.0])
    reward.get_config = lambda: {"target": object()}
    with pytest.raises(TypeError, match="get_config.*target is a object"):
        agent(reward).save(tmp_path / "agent.npz")


def test_a_class_that_cannot_be_imported_is_named_at_load(tmp_path, monkeypatch):
    monkeypatch.setattr(QuadraticCost, "__module__", "no_such_module_here")
    path = agent().save(tmp_path / "agent.npz")
    with pytest.raises(ValueError, match="'no_such_module_here:QuadraticCost' cannot be "
                                         "imported.*PYTHONPATH"):
        PILCO.load(path)


def test_a_reward_of_your_own_gives_the_diagnosis_its_geometry():
    from pilco.diagnose.geometry import CostGeometry, cost_geometry

    reward = QuadraticCost([1.0, 0.0])
    assert cost_geometry(reward) is None
    reward.cost_geometry = lambda: CostGeometry(0.5, (0, 1), lambda X: X - reward.target)
    geometry = cost_geometry(reward)
    np.testing.assert_allclose(geometry.distance(np.array([[1.0, 3.0]])), [3.0])
