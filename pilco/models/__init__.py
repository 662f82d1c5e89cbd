"""Dynamics models and the PILCO agent.

One job per module:

- ``mgpr``: :class:`MGPR`, one GP per output, moment matching at Gaussian inputs;
- ``gp_training``: how the dynamics GPs are trained (the base class of :class:`MGPR`);
- ``smgpr``: :class:`SMGPR`, the sparse (FITC) dynamics model;
- ``pilco``: :class:`PILCO`, the agent: its parts, data, learning and files;
- ``predictions``: the agent's predictions and actions (a base class of :class:`PILCO`);
- ``agent_starts``: the agent's start distributions (a base class of :class:`PILCO`);
- ``rollout``: the compiled, moment-matched step and horizon loops;
- ``objective``: the policy objective over the tasks' starts (the base class of the rollout);
- ``policy_search``: the guarded policy optimiser with restarts;
- ``layout``: which state dimensions the model and the policy read and predict;
- ``starts``: start distributions of one or several tasks, checked and split;
- ``transitions``: the raw transitions kept in step with the GP's data;
- ``storage``: the agent and policy file layout;
- ``custom``: rewards and controllers of your own in agent files;
- ``safe``: Safe PILCO's policy search (a policy runs only below a predicted risk).
"""
from .mgpr import MGPR
from .smgpr import SMGPR
from .pilco import PILCO

__all__ = ["MGPR", "SMGPR", "PILCO"]
