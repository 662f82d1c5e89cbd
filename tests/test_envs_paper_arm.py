"""The Fetch arm of the paper's published scripts, as options of FetchJointReacher:
commanded joint angles in the state (``joint_state="commanded"``), the damaged elbow stuck
at its start angle (``damage_mode="stuck"``, the default) and the straightened variant
(``damage_mode="straight"``)."""
from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from pilco.envs import FETCH_DAMAGED_ID, FETCH_ID

pytest.importorskip("mujoco")
from pilco.envs.fetch_reacher import FetchJointReacher, default_model_path

try:
    default_model_path()
except (ImportError, FileNotFoundError) as _exc:
    pytest.skip(f"gymnasium-robotics Fetch model unavailable: {_exc}", allow_module_level=True)

START = np.array([0.0, -1.0, 0.0, 2.0, 0.0, 0.5, 0.0])
ELBOW = 3
# Larger than max_action = 0.1 in some joints, so that clipping matters; the arm stays
# inside its joint limits (the elbow reaches 2.22 of 2.251 rad).
ACTIONS = np.array([
    [0.05, -0.3, 0.2, -0.01, 0.0, 1.0, -0.07],
    [0.1, 0.1, -0.1, 0.08, 0.02, -0.5, 0.1],
    [-0.02, 0.04, 0.3, 0.1, -0.2, 0.06, 0.0],
    [0.07, -0.07, 0.0, 0.05, 0.1, -0.1, 0.5],
    [0.01, 0.0, -0.04, -0.05, 0.03, 0.09, -0.1],
])


def rollout(env, actions, seed=0):
    obs, info = env.reset(seed=seed)
    out = [(obs, 0.0, info)]
    for a in actions:
        obs, reward, _, _, info = env.step(a)
        out.append((obs, reward, info))
    return out


def test_defaults_are_measured_and_stuck():
    env = FetchJointReacher()
    assert env.joint_state == "measured" and env.damage_mode == "stuck"
    damaged = gymnasium.make(FETCH_DAMAGED_ID)
    assert damaged.unwrapped.joint_state == "measured"
    assert damaged.unwrapped.damage_mode == "stuck"
    assert damaged.unwrapped.damaged_joints == ("elbow_flex",)


def test_commanded_state_is_start_plus_sum_of_clipped_actions():
    env = FetchJointReacher(joint_state="commanded")
    steps = rollout(env, ACTIONS)
    clipped = np.clip(ACTIONS, -0.1, 0.1)
    for k, (obs, reward, info) in enumerate(steps):
        np.testing.assert_allclose(obs[3:], START + clipped[:k].sum(axis=0), atol=1e-12)
        np.testing.assert_allclose(env.forward_kinematics(info["qpos"]), obs[:3], atol=1e-12)
        if k:
            assert reward == pytest.approx(-np.linalg.norm(obs[:3] - env.target))
    np.testing.assert_array_equal(env.commanded_qpos, steps[-1][0][3:])


def test_commanded_equals_measured_while_no_limit_or_damage_acts():
    commanded = rollout(FetchJointReacher(joint_state="commanded"), ACTIONS)
    measured = rollout(FetchJointReacher(), ACTIONS)
    for (oc, rc, _), (om, rm, _) in zip(commanded, measured):
        np.testing.assert_allclose(oc, om, atol=1e-12)
        assert rc == pytest.approx(rm, abs=1e-12)


def test_commanded_angles_pass_the_joint_limits_the_arm_keeps():
    env = FetchJointReacher(joint_state="commanded", max_episode_steps=None)
    env.reset(seed=0)
    up = np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    for _ in range(20):
        obs, reward, _, _, info = env.step(up)
    assert obs[3] == pytest.approx(2.0)  # the command: 20 x 0.1 rad
    assert info["qpos"][0] == pytest.approx(1.6056)  # the arm: at the pan limit
    np.testing.assert_allclose(obs[:3], env.forward_kinematics(info["qpos"]), atol=1e-12)
    assert reward == pytest.approx(-info["distance"])
    obs, *_ = env.step(-up)  # back by 0.1 from the command, still beyond the limit
    assert obs[3] == pytest.approx(1.9) and env.qpos[0] == pytest.approx(1.6056)


def test_stuck_elbow_with_commanded_state_starts_healthy_and_never_moves():
    healthy = FetchJointReacher(joint_state="commanded")
    env = FetchJointReacher(joint_state="commanded", damaged_joints=("elbow_flex",),
                            damage_mode="stuck")
    h_steps, d_steps = rollout(healthy, ACTIONS), rollout(env, ACTIONS)
    (h0, _, _), (d0, _, d0_info) = h_steps[0], d_steps[0]
    np.testing.assert_array_equal(d0, h0)  # the reset pose is the healthy one
    assert d0_info["qpos"][ELBOW] == 2.0
    clipped = np.clip(ACTIONS, -0.1, 0.1)
    for k, (obs, reward, info) in enumerate(d_steps[1:], start=1):
        assert info["qpos"][ELBOW] == 2.0  # the arm's elbow stays at its start angle
        # the state keeps the command, the running sum of the actions, elbow included
        np.testing.assert_allclose(obs[3:], START + clipped[:k].sum(axis=0), atol=1e-12)
        # the gripper and the distance are the real, damaged arm's
        np.testing.assert_allclose(obs[:3], env.forward_kinematics(info["qpos"]), atol=1e-12)
        assert info["distance"] == pytest.approx(np.linalg.norm(obs[:3] - env.target))
        assert reward == pytest.approx(-info["distance"])
    # the other joints move as the healthy arm's do
    h_last, d_last = h_steps[-1][2]["qpos"], d_steps[-1][2]["qpos"]
    np.testing.assert_allclose(np.delete(d_last, ELBOW), np.delete(h_last, ELBOW), atol=1e-12)
    assert h_last[ELBOW] != pytest.approx(2.0)
    obs, info = env.reset(seed=1)  # every episode starts in the healthy pose again
    assert info["qpos"][ELBOW] == 2.0 and obs[3 + ELBOW] == 2.0


def test_straight_mode_with_commanded_state_keeps_the_command():
    env = FetchJointReacher(joint_state="commanded", damaged_joints="elbow_flex",
                            damage_mode="straight")
    obs, info = env.reset(seed=0)
    assert info["qpos"][ELBOW] == 0.0 and obs[3 + ELBOW] == 2.0  # zeroed at reset already
    obs, _, _, _, info = env.step(np.full(7, -0.1))
    assert info["qpos"][ELBOW] == 0.0 and obs[3 + ELBOW] == pytest.approx(1.9)


def test_earlier_mode_names():
    # runs saved with the straightened arm's earlier name resume with it
    assert FetchJointReacher(damaged_joints="elbow_flex", damage_mode="zero").damage_mode \
        == "straight"
    with pytest.raises(ValueError, match="zero_on_step.*removed.*stuck"):
        FetchJointReacher(damaged_joints="elbow_flex", damage_mode="zero_on_step")


def test_runtime_damage_holds_the_angle_it_found():
    env = FetchJointReacher()
    env.reset(seed=0)
    env.step(np.full(7, 0.05))
    env.damage("elbow_flex")  # the default mode: stuck where it is now
    assert env.damage_mode == "stuck"
    for _ in range(3):
        obs, *_ = env.step(np.full(7, 0.1))
    assert obs[3 + ELBOW] == pytest.approx(2.05)
    obs, _ = env.reset(seed=0)  # after a reset: stuck at the start pose's angle
    assert obs[3 + ELBOW] == 2.0
    obs, *_ = env.step(np.full(7, -0.1))
    assert obs[3 + ELBOW] == 2.0
    env.repair()
    obs, *_ = env.step(np.full(7, -0.1))
    assert obs[3 + ELBOW] == pytest.approx(1.9)


def test_options_through_gymnasium_make():
    kwargs = {"joint_state": "commanded", "damaged_joints": ("elbow_flex",),
              "damage_mode": "straight"}
    made = gymnasium.make(FETCH_ID, **kwargs)
    assert made.spec.max_episode_steps == 50
    direct = FetchJointReacher(**kwargs)
    for (om, rm, _), (od, rd, _) in zip(rollout(made, ACTIONS), rollout(direct, ACTIONS)):
        np.testing.assert_array_equal(om, od)
        assert rm == rd
    damaged = gymnasium.make(FETCH_DAMAGED_ID, joint_state="commanded", max_action=0.3)
    obs, info = damaged.reset(seed=0)
    assert obs[3 + ELBOW] == 2.0 and info["qpos"][ELBOW] == 2.0
    obs, _, _, _, info = damaged.step(np.full(7, 0.3))
    assert obs[3 + ELBOW] == pytest.approx(2.3) and info["qpos"][ELBOW] == 2.0
    assert info["qpos"][0] == pytest.approx(0.3)  # steps of up to 0.3 rad


@pytest.mark.filterwarnings("ignore:.*(infinity|symmetric and normalized).*:UserWarning")
def test_paper_arm_passes_gymnasium_checker():
    check_env(FetchJointReacher(joint_state="commanded", damaged_joints="elbow_flex",
                                damage_mode="stuck", start_noise=0.01), skip_render_check=True)
