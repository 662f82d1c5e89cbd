"""How many steps the Fetch arm needs at least to reach its target: a kinematic bound.

Each step rotates every joint by at most ``max_action``, so an episode that reaches the
target in ``k`` steps ends in a pose ``q`` with ``max_j |q_j - start_j| <= k * max_action``
and the gripper within the success distance. The fewest steps are therefore
``ceil(min over reaching poses of max_j |q_j - start_j| / max_action)``, and the straight
line in joint space from the start to that pose, cut into equal steps, achieves it (the
env is kinematic: no dynamics, no collisions). Damaged joints cannot move: they hold their
start angle (``"stuck"``) or 0 rad (``"straight"``).

The minimum over poses is found by sequential quadratic programming (SLSQP) from many
random starting poses, so the returned pose is the best local optimum found: with the
default 64 starts repeated runs agree to a few hundredths of a step on the paper's
reacher. Use it to ask whether a success rule ("within 15 steps") is attainable for a
start pose, target and damage before sweeping seeds.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from pilco.envs.fetch_model import SHORT_NAMES

__all__ = ["ReachBound", "fewest_steps"]


@dataclasses.dataclass(frozen=True)
class ReachBound:
    """The result of :func:`fewest_steps`.

    Attributes:
        steps: fewest steps in which the gripper can get within the env's
            ``distance_threshold`` of the target.
        qpos: a reaching pose that needs only ``steps`` steps, shape ``(7,)`` [rad].
        start: the pose the steps start from (damage applied), shape ``(7,)`` [rad].
        rotation: ``max_j |qpos_j - start_j|`` [rad], the largest joint rotation needed.
        distance: gripper-target distance at ``qpos`` [m].
    """

    steps: int
    qpos: np.ndarray
    start: np.ndarray
    rotation: float
    distance: float

    def actions(self) -> np.ndarray:
        """Equal actions that move the arm from ``start`` to ``qpos`` in ``steps`` steps,
        shape ``(steps, 7)`` [rad]."""
        return np.tile((self.qpos - self.start) / self.steps, (self.steps, 1))


def _effective_start(env) -> tuple[np.ndarray, list[int]]:
    """The start pose after the env's damage, and the indices of the damaged joints."""
    start = np.asarray(env.start_qpos, dtype=np.float64).copy()
    damaged = [SHORT_NAMES.index(n) for n in env.damaged_joints]
    if env.damage_mode != "stuck":
        start[damaged] = 0.0
    return start, damaged


def fewest_steps(env, starts: int = 64, seed: int = 0) -> ReachBound:
    """Fewest steps in which ``env`` (a :class:`~pilco.envs.FetchJointReacher`, its start
    pose, target, ``max_action``, ``distance_threshold``, joint limits and damage) can
    bring the gripper within the success distance of the target.

    Args:
        env: the reacher env (unwrapped or wrapped: ``env.unwrapped`` is used).
        starts: random starting poses of the local search (more: closer to the global
            minimum, slower; about 20 ms each).
        seed: seed of the starting poses.

    Raises:
        ValueError: bad ``starts``, or no reaching pose found (the target is out of
            reach of the working joints).
    """
    from scipy.optimize import minimize

    if isinstance(starts, bool) or not isinstance(starts, (int, np.integer)) or starts < 1:
        raise ValueError(f"starts must be a positive integer, got {starts!r}")
    env = getattr(env, "unwrapped", env)
    start, damaged = _effective_start(env)
    free = [j for j in range(7) if j not in damaged]
    if not free:
        raise ValueError("every joint is damaged: the arm cannot move")
    limits = np.asarray(env.joint_limits, dtype=np.float64)
    lower = np.maximum(limits[free, 0], start[free] - 2 * np.pi)
    upper = np.minimum(limits[free, 1], start[free] + 2 * np.pi)
    target = np.asarray(env.target, dtype=np.float64)
    radius = float(env.distance_threshold) * (1 - 1e-6)

    def pose(x: np.ndarray) -> np.ndarray:
        q = start.copy()
        q[free] = x[:-1]
        return q

    def reach_margin(x: np.ndarray) -> float:
        return radius ** 2 - float(np.sum((env.forward_kinematics(pose(x)) - target) ** 2))

    # variables: the free joints' angles and t >= |q_j - start_j| for every free joint
    constraints = [{"type": "ineq", "fun": reach_margin},
                   {"type": "ineq", "fun": lambda x: x[-1] - np.abs(x[:-1] - start[free])}]
    bounds = list(zip(lower, upper)) + [(0.0, 2 * np.pi)]
    rng = np.random.default_rng(seed)
    best = None
    for _ in range(int(starts)):
        x0 = np.append(rng.uniform(lower, upper), 2 * np.pi)
        x0[:-1] = np.clip(start[free] + 0.5 * (x0[:-1] - start[free]), lower, upper)
        result = minimize(lambda x: x[-1], x0, method="SLSQP", bounds=bounds,
                          constraints=constraints, options={"maxiter": 200})
        q = np.clip(pose(result.x), limits[:, 0], limits[:, 1])
        distance = float(np.linalg.norm(env.forward_kinematics(q) - target))
        if distance >= env.distance_threshold:
            continue
        rotation = float(np.max(np.abs(q - start)))
        if best is None or rotation < best.rotation:
            steps = max(1, math.ceil(rotation / env.max_action - 1e-9))
            best = ReachBound(steps, q, start.copy(), rotation, distance)
    if best is None:
        raise ValueError(
            f"no pose of the working joints brings the gripper within "
            f"{env.distance_threshold} m of the target {target.tolist()} "
            f"({starts} searches); damaged joints: {list(env.damaged_joints)}")
    return best
