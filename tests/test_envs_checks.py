"""Bad input to the environments: every constructor argument and reset option is refused
with a TypeError/ValueError that names it."""
from __future__ import annotations

import numpy as np
import pytest

from pilco.envs import CartPoleSwingUp

NAN = float("nan")

CARTPOLE_BAD = [
    ({"render_mode": "human"}, ValueError, "render_mode"),
    ({"cart_mass": 0.0}, ValueError, "cart_mass"),
    ({"cart_mass": "heavy"}, TypeError, "cart_mass"),
    ({"pole_mass": -0.5}, ValueError, "pole_mass"),
    ({"pole_length": NAN}, ValueError, "pole_length"),
    ({"friction": -0.1}, ValueError, "friction"),
    ({"friction": True}, TypeError, "friction"),
    ({"gravity": float("inf")}, ValueError, "gravity"),
    ({"dt": 0}, ValueError, "dt"),
    ({"max_force": None}, TypeError, "max_force"),
    ({"noise_std": -0.01}, ValueError, "noise_std"),
    ({"start_mean": [0.0, 0.0]}, ValueError, "start_mean"),
    ({"start_mean": [0.0, NAN, 0.0, 0.0]}, ValueError, "start_mean"),
    ({"start_mean": ["a", "b", "c", "d"]}, TypeError, "start_mean"),
    ({"start_mean": ["0", "0", "0", "0"]}, TypeError, "start_mean must be .*, got strings"),
    ({"start_mean": [True, False, False, False]}, TypeError, "start_mean .* got booleans"),
    ({"start_std": "0.1"}, TypeError, "start_std must be .*, got strings"),
    ({"start_std": [0.1, 0.1]}, ValueError, "start_std"),
    ({"start_std": -0.1}, ValueError, "start_std"),
    ({"start_std": NAN}, ValueError, "start_std"),
    ({"max_episode_steps": 0}, ValueError, "max_episode_steps"),
    ({"max_episode_steps": 4.0}, TypeError, "max_episode_steps"),
    ({"cost_width": 0.0}, ValueError, "cost_width"),
    ({"render_width": 8}, ValueError, "render_width"),
    ({"render_height": 400.0}, TypeError, "render_height"),
    ({"rtol": -1e-8}, ValueError, "rtol"),
    ({"atol": NAN}, ValueError, "atol"),
]


@pytest.mark.parametrize("kwargs, exc, match", CARTPOLE_BAD)
def test_cartpole_constructor_refuses(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        CartPoleSwingUp(**kwargs)


RESET_BAD = [
    ({"seed": -1}, ValueError, "seed"),
    ({"seed": 1.5}, TypeError, "seed"),
    ({"seed": "0"}, TypeError, "seed"),
    ({"options": [("state", [0, 0, 0, 0])]}, TypeError, "options"),
    ({"options": "state"}, TypeError, "options must be a dict or None, got str"),
    ({"options": {1: 0.0}}, ValueError, r"Unknown reset options \[1\]"),
]

CARTPOLE_RESET_BAD = RESET_BAD + [
    ({"options": {"state": [0.0, 0.0, 0.0]}}, ValueError, r"options\['state'\]"),
    ({"options": {"state": [[0.0, 0.0, 0.0, 0.0]]}}, ValueError,
     r"options\['state'\] must have shape \(4,\)"),
    ({"options": {"state": [0.0, NAN, 0.0, 0.0]}}, ValueError, "finite"),
    ({"options": {"state": [0, 0, 0, 0], "qpos": 1}}, ValueError,
     r"Unknown reset options \['qpos'\]"),
    ({"options": {"State": [0, 0, 0, 0]}}, ValueError, r"Unknown reset options \['State'\]"),
    ({"options": {"state": None}}, TypeError, r"options\['state'\] .* got NoneType"),
    ({"options": {"state": ["0", "0", "0", "0"]}}, TypeError, r"options\['state'\] .* strings"),
    ({"options": {"state": [True, False, True, False]}}, TypeError,
     r"options\['state'\] .* booleans"),
    ({"options": {"state": {"x": 0.0}}}, TypeError, r"options\['state'\] .* got dict"),
    ({"options": {"state": [1j, 0, 0, 0]}}, TypeError, r"options\['state'\] .* complex"),
]


@pytest.mark.parametrize("kwargs, exc, match", CARTPOLE_RESET_BAD)
def test_cartpole_reset_refuses(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        CartPoleSwingUp().reset(**kwargs)


def test_a_refused_cartpole_reset_changes_nothing():
    """A reset refused for a bad option neither reseeds the env nor moves it."""
    a, b = CartPoleSwingUp(), CartPoleSwingUp()
    a.reset(seed=3)
    b.reset(seed=3)
    with pytest.raises(ValueError, match="Unknown reset options"):
        b.reset(seed=9, options={"nope": 1})
    with pytest.raises(ValueError, match="options"):
        b.reset(seed=9, options={"state": [0.0, 0.0, 0.0]})
    np.testing.assert_array_equal(b.state, a.state)
    np.testing.assert_array_equal(b.reset()[0], a.reset()[0])  # the same random stream


def test_the_pendulum_has_no_reset_options_and_a_refused_reset_changes_nothing():
    from pilco.envs import PendulumSwingUp

    a, b = PendulumSwingUp(), PendulumSwingUp()
    a.reset(seed=3)
    b.reset(seed=3)
    for kwargs, exc, match in RESET_BAD + [({"options": {"state": [0.0, 0.0]}}, ValueError,
                                            r"Unknown reset options \['state'\]")]:
        with pytest.raises(exc, match=match):
            b.reset(**{"seed": 9, **kwargs})
    np.testing.assert_array_equal(b.pendulum.state, a.pendulum.state)
    np.testing.assert_array_equal(b.reset()[0], a.reset()[0])
    np.testing.assert_array_equal(b.reset(options={})[0], a.reset(options=None)[0])


def test_cartpole_reset_options_that_work():
    env = CartPoleSwingUp(noise_std=0.0)
    for options in (None, {}):
        obs, info = env.reset(seed=0, options=options)
        assert obs.shape == (4,) and np.all(np.isfinite(obs))
    for state in ([0, 0, 0, 1], np.array([0.0, 0.0, 0.0, 1.0], dtype=np.float32),
                  (0.0, 0.0, 0.0, np.float64(1.0))):
        _, info = env.reset(options={"state": state})
        np.testing.assert_array_equal(info["state"], [0.0, 0.0, 0.0, 1.0])


def test_cartpole_accepts_numpy_seed_like_int():
    a, b = CartPoleSwingUp(), CartPoleSwingUp()
    np.testing.assert_array_equal(a.reset(seed=np.int64(4))[0], b.reset(seed=4)[0])


def test_cartpole_integrate_refuses_bad_duration():
    env = CartPoleSwingUp()
    with pytest.raises(ValueError, match="duration"):
        env.integrate(np.zeros(4), 0.0, duration=0.0)
    with pytest.raises(ValueError, match="state"):
        env.integrate(np.zeros(3), 0.0)


@pytest.fixture(scope="module")
def fetch_cls():
    pytest.importorskip("mujoco")
    from pilco.envs.fetch_reacher import FetchJointReacher, default_model_path

    try:
        default_model_path()
    except (ImportError, FileNotFoundError) as exc:
        pytest.skip(f"gymnasium-robotics Fetch model unavailable: {exc}")
    return FetchJointReacher


FETCH_BAD = [
    ({"render_mode": "human"}, ValueError, "render_mode"),
    ({"start_qpos": np.zeros(6)}, ValueError, "start_qpos"),
    ({"start_qpos": [0, 0, 0, NAN, 0, 0, 0]}, ValueError, "start_qpos"),
    ({"target": [1.0, 0.5]}, ValueError, "target"),
    ({"target": [1.0, float("inf"), 0.5]}, ValueError, "target"),
    ({"target": "far"}, TypeError, "target"),
    ({"start_noise": -0.1}, ValueError, "start_noise"),
    ({"start_noise": NAN}, ValueError, "start_noise"),
    ({"max_action": 0.0}, ValueError, "max_action"),
    ({"max_action": "0.1"}, TypeError, "max_action"),
    ({"distance_threshold": -0.05}, ValueError, "distance_threshold"),
    ({"max_episode_steps": -3}, ValueError, "max_episode_steps"),
    ({"max_episode_steps": True}, TypeError, "max_episode_steps"),
    ({"damaged_joints": ("knee",)}, ValueError, "elbow_flex"),
    ({"damaged_joints": 3}, TypeError, "joints"),
    ({"damaged_joints": (3,)}, TypeError, "joint names"),
    ({"damage_mode": "broken"}, ValueError, "damage_mode"),
    ({"damage_mode": None}, TypeError, "damage_mode"),
    ({"joint_state": "desired"}, ValueError, "joint_state"),
    ({"joint_state": 1}, TypeError, "joint_state"),
    ({"fixed_qpos": [("robot0:slide0", 0.4)]}, TypeError, "fixed_qpos"),
    ({"fixed_qpos": {"robot0:elbow_flex_joint": 0.0}}, ValueError, "arm joint"),
    ({"fixed_qpos": {"robot0:slide0": NAN}}, ValueError, "slide0"),
    ({"fixed_qpos": {"robot0:slide0": "0.4"}}, TypeError, "slide0"),
    ({"fixed_qpos": {"robot0:no_such_joint": 0.0}}, ValueError, "no_such_joint"),
    ({"fixed_qpos": {7: 0.0}}, TypeError, "fixed_qpos"),
    ({"model_path": "/nonexistent/reach.xml"}, ValueError, "model_path"),
    ({"model_path": 42}, TypeError, "model_path"),
    ({"render_width": 10}, ValueError, "render_width"),
    ({"render_height": None}, TypeError, "render_height"),
    ({"render_width": 1280}, ValueError, "offscreen buffer"),
]


@pytest.mark.parametrize("kwargs, exc, match", FETCH_BAD)
def test_fetch_constructor_refuses(fetch_cls, kwargs, exc, match):
    with pytest.raises(exc, match=match):
        fetch_cls(**kwargs)


FETCH_RESET_BAD = RESET_BAD + [
    ({"options": {"qpos": np.zeros(3)}}, ValueError, r"options\['qpos'\]"),
    ({"options": {"qpos": np.full(7, NAN)}}, ValueError, "finite"),
    ({"options": {"target": [1.0, 2.0]}}, ValueError, r"options\['target'\]"),
    ({"options": {"target": [1.0, NAN, 0.4]}}, ValueError, "finite"),
    ({"options": {"state": np.zeros(10)}}, ValueError, r"Unknown reset options \['state'\]"),
    ({"options": {"qpos": ["0"] * 7}}, TypeError, r"options\['qpos'\] .* strings"),
    ({"options": {"target": [True, False, True]}}, TypeError, r"options\['target'\] .* booleans"),
    ({"options": {"target": None}}, TypeError, r"options\['target'\] .* NoneType"),
]


@pytest.mark.parametrize("kwargs, exc, match", FETCH_RESET_BAD)
def test_fetch_reset_refuses(fetch_cls, kwargs, exc, match):
    env = fetch_cls()
    with pytest.raises(exc, match=match):
        env.reset(**kwargs)


def test_a_refused_fetch_reset_changes_nothing(fetch_cls):
    """A valid new target beside an invalid qpos is not applied; the seed is not used."""
    a, b = fetch_cls(), fetch_cls()
    a.reset(seed=3)
    b.reset(seed=3)
    with pytest.raises(ValueError, match=r"options\['qpos'\]"):
        b.reset(seed=9, options={"target": [1.0, 0.5, 0.5], "qpos": np.zeros(3)})
    np.testing.assert_array_equal(b.target, a.target)
    np.testing.assert_array_equal(b.reset()[0], a.reset()[0])


def test_fetch_setters_and_damage_refuse(fetch_cls):
    env = fetch_cls()
    with pytest.raises(ValueError, match="target"):
        env.target = [0.0, NAN, 0.0]
    with pytest.raises(ValueError, match="start_qpos"):
        env.start_qpos = np.zeros(8)
    with pytest.raises(ValueError, match="damage_mode"):
        env.damage("elbow_flex", mode="loose")
    with pytest.raises(ValueError, match="qpos"):
        env.forward_kinematics(np.zeros(5))
    np.testing.assert_allclose(env.target, [1.2, 0.38, 0.38])  # nothing was changed
    assert env.damaged_joints == ()
