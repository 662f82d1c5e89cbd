"""Safe PILCO's two cars at a crossing as a task (``pilco run cars``): the first car must
pass the crossing soon without being in it while the second car is.

``pilco/TwoCarsCrossing-v0`` (:class:`pilco.envs.crossing.TwoCarsCrossing`): state
``[x1, v1, x2, v2]``, the first car's acceleration the action, 0.5 s steps, the second car
one metre ahead at the same speed. The reward is the first car's position ``x1`` (a
linear reward: the further along, the better, at every step); the constraint is the
collision region, both cars within the crossing (``|x1| ≤ 1`` and ``|x2| ≤ 1``,
:class:`pilco.constraints.Region`, its probability bounded by the smaller of the two
dimensions' by default). The loop is Safe PILCO's (:class:`pilco.experiment.safety.SafeRun`):
a learned policy runs only when its predicted risk of a collision over the horizon is
below ``--risk-threshold``; otherwise ``mu`` grows and the search is repeated, and an
episode with no safe policy brakes (``--safe-action``).

Defaults as the Safe PILCO paper's published script for this system: 5 random episodes,
then 5 learned ones, 25 steps, a horizon of 25, an RBF policy of 40 basis functions
bounded by ±0.2 m/s², the risk threshold 0.1, the policy optimiser's 20 iterations with 2
restarts, 100 for the model. (The script ran the policy on the system whatever its
predicted risk; here an unsafe policy is never executed.)

"Solved": the first car is through the crossing (``info["distance"]`` 0) in a learned
episode; "success": it is through in the last episode and no executed learned episode
collided.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Dict, List

import numpy as np

from ..experiment import ExperimentConfig
from ..experiment.safety import SafeRun
from .base import Task, TaskHooks
from .settings import (SafetySettings, non_negative_float, positive_float, setting,
                       task_settings)

__all__ = ["CarsSettings", "CarsTask", "CarsHooks", "CARS", "collision_region", "HALF_WIDTH"]

#: the crossing's half width on both roads [m] (the env's default)
HALF_WIDTH = 1.0


@task_settings(episodes=10, random_episodes=5, horizon=25, basis_functions=40,
               policy_iters=20, policy_restarts=2, model_iters=100,
               output="runs/cars-seed{seed}")
class CarsSettings(SafetySettings):
    """The two cars' settings (Safe PILCO's published script, except that an unsafe
    policy never runs)."""

    max_action: float = setting(0.2, "the policy's acceleration bound [m/s²] (the env "
                                "allows 0.4)", kind=positive_float)
    region_rule: str = setting("bound", "the probability of both cars in the crossing: "
                               "'bound' (the smaller of the two cars' own, never below the "
                               "truth) or 'independent' (their product)",
                               choices=("bound", "independent"), group="safety")
    safe_action: float = setting(-0.2, "the acceleration an episode runs when no policy is "
                                 "predicted safe [m/s²] (braking)", group="safety")
    start_std: float = setting(0.03, "std of each start state entry", kind=non_negative_float)
    start_var: float = setting(0.01, "variance of the policy objective's start "
                               "distribution, each state entry", kind=positive_float)


def collision_region(combine: str = "bound"):
    """Both cars inside the crossing: positions ``x1`` (dimension 0) and ``x2`` (2) in
    ``[-1, 1]`` at once."""
    from ..constraints import Region

    return Region(4, [0, 2], [-HALF_WIDTH, -HALF_WIDTH], [HALF_WIDTH, HALF_WIDTH],
                  combine=combine)


class CarsHooks(SafeRun, TaskHooks):
    """Safe PILCO's loop on the cars; success: through the crossing in the last episode,
    and no executed learned episode collided."""

    def __init__(self, task, s: CarsSettings, config: ExperimentConfig, env):
        super().__init__(task, s, config, env)
        self.safety = s.safety(collision_region(s.region_rule), [s.safe_action])

    def success(self, summary: Dict[str, Any]) -> bool:
        if not summary["episodes"]:
            return False
        counts = summary.get("safety") or {}
        return bool(summary["episodes"][-1]["final_distance"] == 0.0
                    and not counts.get("executed_violated"))


class CarsTask(Task):
    """The two cars at a crossing, with Safe PILCO's loop."""

    name = "cars"
    settings = CarsSettings
    description = "Safe PILCO: two cars at a crossing, no collision"
    run_hooks = CarsHooks

    def check(self, s: CarsSettings) -> CarsSettings:
        if abs(s.safe_action) > s.max_action:
            raise ValueError(f"--safe-action {s.safe_action} is beyond the policy's bound "
                             f"--max-action {s.max_action}")
        return s

    def config(self, s: CarsSettings) -> ExperimentConfig:
        """The loop's config, never rendering (the cars have no renderer: their figures
        are drawn)."""
        from ..envs import CROSSING_ID

        config = self.loop_config(
            s, env_id=CROSSING_ID,
            env_kwargs=dict(start_std=s.start_std, max_action=s.max_action,
                            max_episode_steps=s.horizon),
            random_action_scale=s.max_action, cost_width=1.0,
            success_threshold=1e-9, solved_rule="reach")
        return dataclasses.replace(config, render=False)

    def agent_builder(self, s: CarsSettings, env):
        """``(data, start_states) -> PILCO``: an RBF policy on the 4 states, the reward
        ``x1`` minus ``mu`` times the collision's probability per step."""
        from ..constraints import ViolationPenalty
        from ..controllers import RbfController
        from ..envs.crossing import CROSSING_START
        from ..models import PILCO
        from ..rewards import CombinedRewards, LinearReward

        def build(data, start_states):
            controller = RbfController(4, 1, s.basis_functions, max_action=s.max_action,
                                       seed=s.seed)
            reward = CombinedRewards(4, [LinearReward(4, [1.0, 0.0, 0.0, 0.0]),
                                         ViolationPenalty(collision_region(s.region_rule),
                                                          s.mu)])
            return PILCO(data, controller, reward, horizon=s.horizon,
                         m_init=CROSSING_START[None, :], S_init=s.start_var * np.eye(4))

        return build

    def notes(self, summary: Dict[str, Any]) -> List[str]:
        counts = summary.get("safety") or {}
        return [f"\nlearned episodes {counts.get('learned')}, executed {counts.get('executed')}"
                f", executed with a collision {counts.get('executed_violated')}; random "
                f"episodes with a collision {counts.get('random_violated')}"]

    def figures(self, exp, s: CarsSettings) -> List[str]:
        """The first car's distance to the crossing's far side per step, predicted vs
        real cost, one- and multi-step predictions."""
        from .. import plotting

        return plotting.save_all(exp, exp.directory, title="two cars at a crossing",
                                 state_dims=(0, 2), state_names=("x1 [m]", "x2 [m]"),
                                 distance_label="first car to the crossing's far side [m]",
                                 threshold=None)


CARS = CarsTask()
