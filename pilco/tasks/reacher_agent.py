"""The reacher's agent: its RBF policy, its costs on the gripper position (and near the
joint limits), the GP priors of the paper's code, the hooks that change the agent
during a run (the start and cost schedule, the long lengthscale of a constant GP input).
Every function reads the task's typed settings (:class:`~pilco.tasks.reacher.ReacherSettings`).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Optional

import numpy as np

if TYPE_CHECKING:  # the settings class lives with the task, which imports this module
    from .reacher import ReacherSettings

__all__ = ["PAPER_GP_PRIORS", "agent_builder", "reacher_agent", "ignore_constant_inputs",
           "init_policy_near", "limit_bumps", "set_gp_priors", "position_weights",
           "main_position_reward", "schedule", "after_model_fit"]

#: The paper code's priors on every dynamics GP's hyperparameters (GPflow 1's Gamma(shape,
#: scale)): lengthscales ~ Gamma(1, 10), signal variance ~ Gamma(1.5, 2); training is then
#: MAP instead of maximum evidence.
PAPER_GP_PRIORS = {"lengthscales": (1.0, 10.0), "variance": (1.5, 2.0)}

def ignore_constant_inputs(agent, lengthscale: float = 100.0) -> None:
    """Give the dynamics GPs a long lengthscale on GP-input columns that are constant in
    the training data (a damaged joint held at one angle), so that the column is
    irrelevant; called after building the agent and after every model fit."""
    X = np.asarray(agent.mgpr.X)
    constant = np.std(X, axis=0) < 1e-9
    if not np.any(constant):
        return
    for model in agent.mgpr.models:
        ell = np.array(model.kernel.lengthscales.numpy(), dtype=float)
        ell[constant] = lengthscale
        model.kernel.lengthscales.assign(ell)


def agent_builder(s: "ReacherSettings", target: np.ndarray,
                  joint_limits: Optional[np.ndarray] = None):
    """``(data, start_states) -> PILCO`` for the reacher; ``target [3]`` is the gripper
    target, the reward looks at state dims 0..2 (x, y, z); with ``--limit-cost`` also at
    the joint angles (dims 3..9) near ``joint_limits [7, 2]`` (±inf: unlimited)."""
    from ..rewards import ExponentialReward

    def position_reward(D: int, width: float) -> ExponentialReward:
        t = np.zeros((1, D))
        t[0, :3] = target
        return ExponentialReward(D, position_weights(D, width), t)

    def build(data, start_states):
        D = np.shape(data[1])[1]
        return reacher_agent(s, data, start_states, joint_limits, position_reward,
                             m_init=start_states[0:1], S_init=s.start_var * np.eye(D))

    return build


def reacher_agent(s: "ReacherSettings", data, start_states: np.ndarray,
                  joint_limits: Optional[np.ndarray], position_reward, m_init, S_init,
                  **options):
    """The reacher's PILCO agent on ``data`` (X [N, D + U], Y [N, D]): an RBF policy of
    the settings' size (centres near ``start_states[0]`` with ``--policy-init-var``), the
    reward ``position_reward(D, width)`` of ``--cost-width`` plus, with
    ``--fine-cost-width``, a second of that width, minus the joint-limit bumps
    (``--limit-cost``), the start ``m_init``, ``S_init``; the paper's GP priors with
    ``--gp-priors paper``. ``options`` go to :class:`~pilco.models.PILCO` (e.g.
    ``context_indices``)."""
    from ..controllers import RbfController, squash_sin
    from ..models import PILCO
    from ..rewards import CombinedRewards

    X, Y = data
    D, U = Y.shape[1], X.shape[1] - Y.shape[1]
    controller = RbfController(D, U, s.basis_functions, s.max_action, squash_sin,
                               seed=s.seed)
    if s.policy_init_var:
        init_policy_near(controller, start_states[0], s.policy_init_var, s.seed)
    reward = position_reward(D, s.cost_width)
    if s.fine_cost_width:
        reward = CombinedRewards(D, [reward, position_reward(D, s.fine_cost_width)])
    bumps = (limit_bumps(D, joint_limits, s.limit_cost)
             if s.limit_cost and joint_limits is not None else None)
    if bumps is not None:
        reward = CombinedRewards(D, [reward, bumps], [1.0, -s.limit_cost_weight])
    agent = PILCO(data, controller, reward, horizon=s.planning_horizon or s.horizon,
                  m_init=m_init, S_init=S_init, **options)
    set_gp_priors(agent, s)
    after_model_fit(s)(agent)
    return agent


def init_policy_near(controller, x0: np.ndarray, var: float, seed: int) -> None:
    """The MATLAB release's initial policy, around ``x0 [D]``: RBF centres drawn from
    N(x0, var·I), targets from N(0, 0.1²) (lengthscales stay 1); see
    :meth:`pilco.controllers.RbfController.place_near`."""
    controller.place_near(x0, np.sqrt(var), seed=seed)


def limit_bumps(state_dim: int, joint_limits: np.ndarray, width: float):
    """An :class:`~pilco.rewards.AxisBumpsReward` with one bump of ``width`` [rad] per
    finite joint limit, centred on the limit of joint ``j`` (state dim ``3 + j``), highest
    (1) at the limit; ``None`` when no joint is limited. Subtracted from the reward, the
    bumps keep the predicted joint angles away from the limits, where the real joint
    stops but the GP model, which rarely sees a joint at its limit, predicts it moving
    on."""
    from ..rewards import AxisBumpsReward

    limits = np.asarray(joint_limits, dtype=np.float64)
    dims, centres = [], []
    for j, bounds in enumerate(limits):
        for value in bounds:
            if np.isfinite(value):
                dims.append(3 + j)
                centres.append(value)
    if not dims:
        return None
    return AxisBumpsReward(state_dim, dims, centres, np.full(len(dims), float(width)))


def set_gp_priors(agent, s: ReacherSettings) -> None:
    """With ``--gp-priors paper``, put :data:`PAPER_GP_PRIORS` on every output GP of
    ``agent.mgpr`` (before its first training: the compiled training loss includes the
    priors it saw when it was traced). Called on new and on resumed agents, since
    ``agent.npz`` keeps hyperparameter values, not priors."""
    if s.gp_priors != "paper":
        return
    import tensorflow as tf
    import tensorflow_probability as tfp

    for model in agent.mgpr.models:
        for name, (shape, scale) in PAPER_GP_PRIORS.items():
            getattr(model.kernel, name).prior = tfp.distributions.Gamma(
                tf.constant(shape, tf.float64), tf.constant(1.0 / scale, tf.float64))


def position_weights(state_dim: int, width: float) -> np.ndarray:
    """``W [D, D]`` of a saturating cost of ``width`` [m] on the gripper position (state
    dims 0..2)."""
    W = np.zeros((state_dim, state_dim))
    W[:3, :3] = np.eye(3) / width ** 2
    return W


def main_position_reward(reward):
    """The reacher's main position cost inside its (possibly nested) combined reward:
    the first component, all the way down."""
    while hasattr(reward, "base_rewards"):
        reward = reward.base_rewards[0]
    return reward


def schedule(s: ReacherSettings):
    """``(agent, episode number) -> None`` run before every policy search: in the first
    ``--early-episodes`` learned episodes the main cost has width ``--early-cost-width``
    and the initial state variance is ``--early-start-var`` (when set), afterwards the
    flags' ``--cost-width`` and ``--start-var``. Works on a resumed agent too: it sets
    both every time."""
    early_width, early_var = s.early_cost_width, s.early_start_var

    def before_policy_search(agent, number: int) -> None:
        early = number - s.random_episodes <= s.early_episodes
        if early_width:
            width = early_width if early else s.cost_width
            main_position_reward(agent.reward).W.assign(
                position_weights(agent.state_dim, width))
        if early_var:
            D = agent.state_dim
            agent.S_init = (early_var if early else s.start_var) * np.eye(D)

    return before_policy_search


def after_model_fit(s: ReacherSettings):
    """``agent -> None`` run after building the agent and every model fit:
    :func:`ignore_constant_inputs` unless ``--constant-input-lengthscale 0``."""
    ell = s.constant_input_lengthscale

    def adjust(agent) -> None:
        if ell:
            ignore_constant_inputs(agent, ell)

    return adjust
