"""The kinematic bound on the steps the Fetch arm needs to reach its target."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

from pilco.envs import FetchJointReacher, fewest_steps


def replay(env, bound):
    """Step ``env`` from its reset with the bound's actions; the step at which the
    episode terminated (reached), or None."""
    env.reset(seed=0)
    for k, action in enumerate(bound.actions(), start=1):
        _, _, terminated, _, info = env.step(action)
        if terminated:
            return k, info["distance"]
    return None, info["distance"]


@pytest.mark.parametrize("kwargs, expected", [
    ({}, 3),
    ({"damaged_joints": ("elbow_flex",), "damage_mode": "stuck"}, 5),
])
def test_bound_is_reached_by_its_straight_line_and_not_earlier(kwargs, expected):
    env = FetchJointReacher(**kwargs)
    bound = fewest_steps(env, starts=16, seed=0)
    assert bound.steps == expected
    assert bound.steps == int(np.ceil(bound.rotation / env.max_action - 1e-9))
    assert np.max(np.abs(bound.qpos - bound.start)) == pytest.approx(bound.rotation)
    assert np.all(bound.qpos >= env.joint_limits[:, 0] - 1e-12)
    assert np.all(bound.qpos <= env.joint_limits[:, 1] + 1e-12)
    # the straight line in joint space reaches at exactly the bound's step
    step, distance = replay(env, bound)
    assert step == bound.steps
    assert distance < env.distance_threshold
    # and no pose reachable in one step fewer is within the success distance:
    # sample that box around the start densely
    rng = np.random.default_rng(1)
    box = (bound.steps - 1) * env.max_action
    best = min(np.linalg.norm(env.forward_kinematics(bound.start + rng.uniform(-box, box, 7))
                              - env.target) for _ in range(2000))
    assert best > env.distance_threshold


def test_damaged_joint_is_held_and_makes_the_paper_target_far():
    env = FetchJointReacher(damaged_joints=("elbow_flex",), damage_mode="straight")
    bound = fewest_steps(env, starts=16, seed=0)
    elbow = 3
    assert bound.start[elbow] == 0.0 and bound.qpos[elbow] == 0.0
    assert bound.steps == 13  # the paper's "15 steps" leaves two steps to spare
    step, _ = replay(env, bound)
    assert step == bound.steps


def test_bad_input_and_unreachable_target():
    env = FetchJointReacher()
    for bad in (0, -3, 2.5, True, "8"):
        with pytest.raises(ValueError, match="starts"):
            fewest_steps(env, starts=bad)
    far = FetchJointReacher(target=(4.0, 4.0, 4.0))
    with pytest.raises(ValueError, match="no pose"):
        fewest_steps(far, starts=4)
