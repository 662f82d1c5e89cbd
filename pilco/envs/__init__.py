"""Gymnasium environments of the PILCO experiments.

Importing this package registers (once; importing again is harmless):

- ``pilco/CartPoleSwingUp-v0``: :class:`CartPoleSwingUp`, 40 steps of 0.1 s.
- ``pilco/FetchJointReacher-v0``: :class:`FetchJointReacher`, healthy arm, 50 steps.
- ``pilco/FetchJointReacherDamaged-v0``: the same with the elbow's motor unresponsive,
  the joint stuck at its start angle (``damaged_joints=("elbow_flex",)``,
  ``damage_mode="stuck"``, the paper's damage).
- ``pilco/PendulumSwingUp-v0``: :class:`PendulumSwingUp`, gymnasium's Pendulum-v1 from
  hanging down with each action held for 3 of its steps, 40 steps.
- ``pilco/TwoCarsCrossing-v0``: :class:`TwoCarsCrossing`, Safe PILCO's two cars at a
  crossing, 25 steps of 0.5 s.

Constructor arguments pass through ``gymnasium.make``; e.g. the arm of the paper's
published scripts (commanded joint angles in the state: the running sum of the actions,
which keeps growing for the stuck elbow) with the damaged script's larger steps::

    gymnasium.make(FETCH_DAMAGED_ID, joint_state="commanded", max_action=0.3)

The episode horizon of the registered ids is enforced by gymnasium's ``TimeLimit``
wrapper (``env.spec.max_episode_steps``; override with
``gymnasium.make(id, max_episode_steps=N)``); the envs' own limit is disabled there.

Importing this package does not import mujoco or gymnasium-robotics; the Fetch env
imports them when constructed. The Fetch arm's replay renderer (recorded joint angles drawn
in a process without TensorFlow) is :mod:`pilco.envs.fetch_render`, imported on its own.
"""
from __future__ import annotations

import logging

import gymnasium

from pilco.envs.cartpole import CartPoleSwingUp
from pilco.envs.crossing import TwoCarsCrossing
from pilco.envs.fetch_context import TargetInState
from pilco.envs.fetch_damage import DamageFlag
from pilco.envs.fetch_reach_bound import ReachBound, fewest_steps
from pilco.envs.fetch_reacher import ARM_JOINTS, FetchJointReacher
from pilco.envs.pendulum import PendulumSwingUp

logger = logging.getLogger(__name__)

__all__ = [
    "ARM_JOINTS",
    "CARTPOLE_ID",
    "CartPoleSwingUp",
    "CROSSING_ID",
    "DamageFlag",
    "FETCH_DAMAGED_ID",
    "FETCH_ID",
    "FetchJointReacher",
    "PENDULUM_ID",
    "PendulumSwingUp",
    "ReachBound",
    "TargetInState",
    "TwoCarsCrossing",
    "fewest_steps",
    "register_envs",
]

CARTPOLE_ID = "pilco/CartPoleSwingUp-v0"
FETCH_ID = "pilco/FetchJointReacher-v0"
FETCH_DAMAGED_ID = "pilco/FetchJointReacherDamaged-v0"
PENDULUM_ID = "pilco/PendulumSwingUp-v0"
CROSSING_ID = "pilco/TwoCarsCrossing-v0"

_SPECS = (
    (CARTPOLE_ID, "pilco.envs.cartpole:CartPoleSwingUp", 40, {}),
    (FETCH_ID, "pilco.envs.fetch_reacher:FetchJointReacher", 50, {}),
    (
        FETCH_DAMAGED_ID,
        "pilco.envs.fetch_reacher:FetchJointReacher",
        50,
        {"damaged_joints": ("elbow_flex",), "damage_mode": "stuck"},
    ),
    (PENDULUM_ID, "pilco.envs.pendulum:PendulumSwingUp", 40, {}),
    (CROSSING_ID, "pilco.envs.crossing:TwoCarsCrossing", 25, {}),
)


def register_envs() -> None:
    """Register the environments with gymnasium (skips ids already registered)."""
    for env_id, entry_point, steps, kwargs in _SPECS:
        if env_id in gymnasium.registry:
            continue
        gymnasium.register(
            id=env_id,
            entry_point=entry_point,
            max_episode_steps=steps,
            # TimeLimit does the truncation; keep a single source of the horizon.
            kwargs={"max_episode_steps": None, **kwargs},
        )
        logger.debug("Registered %s", env_id)


register_envs()
