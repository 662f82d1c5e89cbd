"""How the adaptation changes its agent's model and policy after the damage: the damage
flag's lengthscale (``--damage-input``), the healthy data's noise factors per state
dimension (``--changed-output-noise``), the joints found stuck and no longer commanded
(``--stop-stuck-joints``), and the re-plan inside the first damaged episode once one is
found (``--replan-stuck-joints``). The settings are
:class:`~pilco.tasks.adaptation.AdaptationSettings`.
"""
from __future__ import annotations

import logging
import time
from types import SimpleNamespace
from typing import TYPE_CHECKING, List, Sequence

import numpy as np

from ..experiment import Experiment, stack_transitions
from ..experiment.learning import search_policy

if TYPE_CHECKING:  # the settings class lives with the task, which imports this module
    from .adaptation import AdaptationSettings

__all__ = ["DATA_STATE", "track_damage_data", "damaged_arm_data", "learn_the_flag",
           "output_disagreement", "per_output_noise", "joint_follow_ratios", "stuck_joints",
           "stop_stuck_joints", "ReplanWhenStuck", "MIN_COMMANDED_ROTATION",
           "HEALTHY_FOLLOW_RATIO"]

logger = logging.getLogger(__name__)

#: the adaptation's data state (in the run's ``task_state``), as before the damage:
#: ``train_from_episode`` (1-based: the model learns from this episode on),
#: ``older_noise_scale`` and ``older_before_episode`` (the transitions of episodes before
#: ``older_before_episode`` have their noise variance multiplied by ``older_noise_scale``:
#: a large factor down-weights the healthy arm's after the damage; a list gives each state
#: dimension's GP its own factor), ``inert_actions`` and ``inert_from_episode`` (action
#: dimensions that have no effect from that episode on, a stuck joint's command: the model
#: sees them as 0 there, their effective value; the episodes keep what was sent)
DATA_STATE = dict(train_from_episode=1, older_noise_scale=1.0, older_before_episode=1,
                  inert_actions=[], inert_from_episode=1)


def track_damage_data(exp) -> dict:
    """Give the run ``exp`` the adaptation's data state (its ``task_state``, with the
    :data:`DATA_STATE` defaults for keys it lacks); returns the state. The run's hooks
    choose its model's transitions with :func:`damaged_arm_data`."""
    for key, value in DATA_STATE.items():
        exp.task_state.setdefault(key, list(value) if isinstance(value, list) else value)
    return exp.task_state


def damaged_arm_data(record):
    """The adaptation's model transitions (its hooks' ``model_data``): the episodes from
    ``train_from_episode`` on (at least the last one), the inert actions at 0 from
    ``inert_from_episode`` on, the first ``max_data``; their noise factors are
    ``older_noise_scale`` for the episodes before ``older_before_episode``, else 1, and
    all 1 while no later transition is among them (older data are down-weighted against
    newer ones only: scaling every noise variance alike would only change the fit).
    Returns ``(X [N, D+U], Y [N, D], factors [N] or [D, N])``."""
    state = {**DATA_STATE, **record.task_state}
    first = min(int(state["train_from_episode"]), len(record.episodes))
    numbered = list(enumerate(record.episodes[first - 1:], start=first))
    X, Y = stack_transitions([e for _, e in numbered])
    if not numbered:
        return X, Y, None
    inert = [int(a) for a in state["inert_actions"]]
    if inert and len(X):
        rows = np.concatenate([np.full(e.steps, n >= int(state["inert_from_episode"]))
                               for n, e in numbered])
        X[np.ix_(rows, Y.shape[1] + np.asarray(inert, dtype=int))] = 0.0  # X is new
    old = np.concatenate([np.full(e.steps, n < int(state["older_before_episode"]))
                          for n, e in numbered])
    cap = record.config.max_data
    if cap is not None:
        X, Y, old = X[:cap], Y[:cap], old[:cap]
    if np.all(old):
        old = np.zeros_like(old)
    older = np.asarray(state["older_noise_scale"], dtype=float)
    return X, Y, np.where(old, older[..., None] if older.ndim else older, 1.0)

#: a joint whose rotations summed to less than this share of its commanded ones in every
#: healthy episode never followed its commands there either (e.g. held at a limit)
HEALTHY_FOLLOW_RATIO = 0.5

def learn_the_flag(agent, lengthscale: float = 1.0, ignored: float = 100.0) -> None:
    """With ``--damage-input``: when the model's data first hold transitions of the
    damaged arm (the state's last dimension, the flag, is 1), the flag's GP input gets
    ``lengthscale`` in every output GP instead of the ``ignored`` value that
    :func:`~pilco.tasks.reacher_agent.ignore_constant_inputs` gave it while it was constant, so
    that the next fit learns how far each output of the damaged arm follows the healthy
    arm's data (from a long lengthscale the fit's gradient would be ~0)."""

    column = agent.state_dim - 1  # the reacher's GP inputs: the state, then the action

    def on_new_data(X, Y) -> None:
        if not np.any(X[:, column] != 0.0):
            return
        for model in agent.mgpr.models:
            ell = np.array(model.kernel.lengthscales.numpy(), dtype=float)
            if np.isclose(ell[column], ignored, rtol=1e-9):  # exact but for the bijector
                ell[column] = lengthscale
                model.kernel.lengthscales.assign(ell)

    agent.mgpr.add_data_listener(on_new_data)


def output_disagreement(agent, known, new) -> np.ndarray:
    """How badly ``agent``'s dynamics model, learning from the transitions ``known`` only,
    explains the transitions ``new``, per state dimension [D]: the mean over ``new`` of
    ``(Δx - mean)^2 / var`` with the one-step prediction of a model with the agent's
    hyperparameters conditioned on ``known`` (``var`` includes the noise). About 1 where
    that model knew the dynamics. Shapes: ``known``, ``new`` = (X [N, D + U], Y [N, D])."""
    from ..models import MGPR
    from ..snapshots import restore, snapshot

    X, Y = known
    Xn, Yn = new
    trained = agent.mgpr
    model = MGPR((agent.gp_inputs(X), Y), noise_floor=trained.noise_floor)
    for mine, theirs in zip(model.models, trained.models):
        # unconstrained copies: exact also for a noise variance on its floor
        restore(mine.kernel, snapshot(theirs.kernel))
        restore(mine.likelihood, snapshot(theirs.likelihood))
    mean, var = (np.asarray(t) for t in model.predict_f(agent.gp_inputs(Xn)))
    var = var + np.asarray(model.noise_variance)
    return np.mean((Yn - mean) ** 2 / var, axis=0)


def per_output_noise(exp: Experiment, s: AdaptationSettings, first: int) -> None:
    """With ``--changed-output-noise G``, once the first damaged episode (``first``) ran
    and before the model learns from it: each state dimension's factor of the healthy
    arm's transitions is G where :func:`output_disagreement` of the healthy model (the
    agent's hyperparameters are still those fitted to the healthy episodes) on that
    episode exceeds ``--changed-output-threshold``, else ``--old-data-noise``; the agent
    gets its data with the new factors. The factors are kept in the run's state, the
    disagreement in the summary (``output_disagreement``)."""
    fields = exp.summary_fields
    if (s.changed_output_noise is None or len(exp.episodes) < first
            or fields.get("output_disagreement") is not None):
        return
    state = track_damage_data(exp)
    known = stack_transitions(exp.episodes[state["train_from_episode"] - 1:first - 1])
    if exp.config.max_data is not None:
        known = tuple(a[: exp.config.max_data] for a in known)
    if len(known[0]) == 0:  # --drop-old-data: no healthy transition to weigh
        return
    z2 = output_disagreement(exp.agent, known, exp.episodes[first - 1].transitions())
    changed = z2 > s.changed_output_threshold
    fields["output_disagreement"] = [float(v) for v in z2]
    state["older_noise_scale"] = [float(s.changed_output_noise if c else s.old_data_noise)
                                  for c in changed]
    exp.give_agent_data(exp.agent)
    logger.info("the healthy model on the first damaged episode: mean squared standardised "
                "error per state dimension %s; changed by the damage: %s", np.round(z2, 2),
                np.flatnonzero(changed).tolist())


def joint_follow_ratios(episodes, joint_dims: Sequence[int]) -> np.ndarray:
    """How far each joint followed its commands over ``episodes``: the sum of its measured
    rotations ``|Δq_j|`` over the sum of its commanded ones ``|u_j|``, [U] (about 1 for a
    healthy joint away from its limits, 0 for a stuck one; NaN for a joint never
    commanded). ``joint_dims`` [U]: the state dimension of each action's joint angle (the
    env's ``joint_dims``)."""
    moved = commanded = 0.0
    for episode in episodes:
        q = episode.states[:, list(joint_dims)]
        moved = moved + np.sum(np.abs(np.diff(q, axis=0)), axis=0)
        commanded = commanded + np.sum(np.abs(episode.actions), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(commanded > 0, moved / np.where(commanded > 0, commanded, 1.0),
                        np.nan)


def stuck_joints(healthy, damaged, ratio: float, joint_dims: Sequence[int]) -> List[int]:
    """Action indices of the joints that followed their commands in at least one of the
    ``healthy`` episodes (ratio at least :data:`HEALTHY_FOLLOW_RATIO`: a joint may spend
    whole healthy episodes at a limit) and moved less than ``ratio`` of their commanded
    rotation over the ``damaged`` ones (:func:`joint_follow_ratios`)."""
    before = np.nanmax([joint_follow_ratios([e], joint_dims) for e in healthy]
                       + [np.full(len(joint_dims), -np.inf)], axis=0)
    after = joint_follow_ratios(damaged, joint_dims)
    return [int(j) for j in np.flatnonzero((before >= HEALTHY_FOLLOW_RATIO) & (after < ratio))]


def _stop_commanding(agent, joints: Sequence[int]) -> None:
    """Action bound 0 for ``joints`` (the policy's output and its model both see 0 there);
    the agent's compiled functions are retraced for the new bounds."""
    controller = agent.controller
    bounds = np.array(controller.max_action, dtype=float)
    if np.all(bounds[list(joints)] == 0.0):
        return
    bounds[list(joints)] = 0.0
    controller.max_action = bounds
    agent.retrace()  # the compiled functions hold the old bounds as constants


class ReplanWhenStuck:
    """The policy of the first damaged episode, watching the joints as the episode runs
    (``--replan-stuck-joints``): from step ``--stuck-check-steps`` on, once a joint that
    followed its commands on the healthy arm has been commanded at least
    :data:`MIN_COMMANDED_ROTATION` rad and moved less than ``--stuck-joint-ratio`` of it
    (:func:`stuck_joints` on the steps so far), the episode pauses, as an arm can hold its
    pose: the joint is no longer commanded and the healthy arm's transitions describe the
    damaged arm (as :func:`stop_stuck_joints` does after an episode), the policy is searched
    again from the state reached (start mean the current state, the run's start
    covariance, the episode's policy budget and early stop), and the episode continues
    with the new policy. Replans at most once; the agent's start state is restored after
    the search. The episode's record gets a ``replanned`` note (step, joints, predicted
    return, seconds); the pause counts as the episode's policy time, its search's
    evaluations as the episode's. A replay of the run's learning (``python -m
    pilco.diagnose``) does not redo the pause: its next policy search starts from the
    policy before it.

    Use as the hooks' ``watch``: ``ReplanWhenStuck(exp, s, first, number)(policy)``."""

    def __init__(self, exp: Experiment, s: AdaptationSettings, first: int, number: int):
        self.exp, self.s, self.first, self.number = exp, s, first, number
        self.joint_dims = list(exp.make_env().unwrapped.joint_dims)
        self.states: List[np.ndarray] = []
        self.actions: List[np.ndarray] = []
        self.replanned = False

    def __call__(self, policy):
        def watched(x):
            x = np.asarray(x, dtype=np.float64).reshape(-1)
            self.states.append(x)
            if not self.replanned and len(self.actions) >= self.s.stuck_check_steps:
                joints = self._stuck()
                if joints:
                    self.replanned = True
                    self._replan(joints, x)
            u = np.asarray(policy(x), dtype=np.float64).reshape(-1)
            self.actions.append(u)
            return u

        return watched

    def _so_far(self) -> SimpleNamespace:
        """The episode's steps so far, as :func:`joint_follow_ratios` reads an episode."""
        return SimpleNamespace(states=np.array(self.states), actions=np.array(self.actions))

    def _stuck(self) -> List[int]:
        so_far = self._so_far()
        commanded = np.sum(np.abs(so_far.actions), axis=0)
        joints = stuck_joints(self.exp.episodes[:self.first - 1], [so_far],
                              self.s.stuck_joint_ratio, self.joint_dims)
        return [j for j in joints if commanded[j] >= MIN_COMMANDED_ROTATION]

    def _replan(self, joints: List[int], x: np.ndarray) -> None:
        exp, agent = self.exp, self.exp.agent
        t0 = time.perf_counter()
        step = len(self.actions)
        _mark_stuck(exp, joints, joint_follow_ratios([self._so_far()], self.joint_dims),
                    self.first)
        _stop_commanding(agent, joints)
        start = agent.m_init
        agent.m_init = x[None, :]
        try:
            expected = search_policy(exp, self.number, "policy (re-plan)")
        finally:
            agent.m_init = start
        seconds = time.perf_counter() - t0
        notes = exp.policy_notes
        notes["replanned"] = {"step": step, "stuck_joints": joints,
                              "predicted_return": float(expected), "seconds": round(seconds, 2)}
        # the pause is policy time, and its search's evaluations the episode's (the loop)
        notes["paused_seconds"] = notes.get("paused_seconds", 0.0) + seconds
        notes["extra_evaluations"] = (notes.get("extra_evaluations", 0)
                                      + int(getattr(agent, "policy_evaluations", 0) or 0))
        logger.info("episode %d: joint(s) %s stuck after %d steps; re-planned from the state "
                    "reached without them in %.1f s (predicted return %.3f)", self.number,
                    joints, step, seconds, expected)


#: a joint is judged stuck mid-episode only once it was commanded at least this far [rad]
MIN_COMMANDED_ROTATION = 0.05


def _mark_stuck(exp: Experiment, joints: List[int], ratios: np.ndarray, first: int) -> None:
    """Record ``joints`` (action indices) as stuck from the damaged episode ``first`` on:
    the summary's ``stuck_joints`` and ``joint_follow_ratio``, the data state's inert
    actions, the healthy transitions as equals (noise factor 1)."""
    exp.summary_fields["joint_follow_ratio"] = [float(r) for r in ratios]
    exp.summary_fields["stuck_joints"] = list(joints)
    if joints:
        track_damage_data(exp).update(inert_actions=list(joints), inert_from_episode=first,
                                      older_noise_scale=1.0)


def stop_stuck_joints(exp: Experiment, s: AdaptationSettings, first: int) -> None:
    """With ``--stop-stuck-joints``, once the first damaged episode (``first``) ran and
    before the model learns from it: the joints :func:`stuck_joints` finds are no longer
    commanded (action bound 0), the model sees their commands in the damaged episodes as 0
    (the data state's ``inert_actions`` from episode ``first``), and the healthy arm's
    transitions count as equals again (noise factor 1): with the stuck joints' commands at 0
    they describe the damaged arm. The env's ``joint_dims`` say which state dimension holds
    each action's joint. The summary holds ``joint_follow_ratio`` (first damaged episode, per
    action) and ``stuck_joints`` (action indices; the Fetch arm's elbow is 3). Applied again
    on resume (the saved agent keeps its bounds)."""
    fields, state = exp.summary_fields, track_damage_data(exp)
    if not s.stop_stuck_joints or len(exp.episodes) < first:
        return
    if fields.get("stuck_joints") is None:
        joint_dims = exp.make_env().unwrapped.joint_dims
        joints = stuck_joints(exp.episodes[:first - 1], exp.episodes[first - 1:first],
                              s.stuck_joint_ratio, joint_dims)
        ratios = joint_follow_ratios(exp.episodes[first - 1:first], joint_dims)
        _mark_stuck(exp, joints, ratios, first)
        logger.info("joints' measured over commanded rotation in the first damaged episode "
                    "%s; stuck (action indices): %s", np.round(ratios, 3), joints or "none")
        if joints:
            exp.give_agent_data(exp.agent)
    if state["inert_actions"]:
        _stop_commanding(exp.agent, state["inert_actions"])
