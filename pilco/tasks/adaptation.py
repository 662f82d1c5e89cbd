"""Adaptation to damage: learn to reach on the healthy Fetch arm, then break a joint
mid-run and keep learning with the same agent (the paper's motivation, §5.2).

1. the random episodes and up to ``--healthy-episodes`` learned episodes on the healthy
   arm, stopping as soon as an episode has reached the target and at least
   ``--min-healthy-episodes`` were run;
2. :func:`damage`: ``env.damage(--damaged-joints, --damage-mode)`` (the agent is not
   told unless ``--damage-input``; by default the elbow is stuck at its angle,
   ``--damage-mode straight`` straightens it); the damaged arm's start state becomes the
   agent's ``m_init``;
3. up to ``--damaged-episodes`` learned episodes with the same agent, policy and data
   (``--drop-old-data``: the model then learns from the damaged episodes only;
   ``--old-data-noise F``, default 100: the healthy arm's transitions keep shaping the
   model, with F times the noise variance of the damaged arm's, so that they give way
   where the two disagree; ``--changed-output-noise G``: from the second damaged
   episode on, the state dimensions whose first damaged episode the healthy model
   explained badly (:func:`output_disagreement` above ``--changed-output-threshold``) see
   them with G times the noise variance instead, the others with F;
   ``--stop-stuck-joints``: from the second damaged episode on, the joints that did not
   follow their commands in the first one (:func:`stuck_joints`) are no longer commanded
   (their action bound becomes 0), the model sees their commands in the damaged episodes
   as 0, what reached the arm, and the healthy arm's transitions, which then describe the
   damaged arm too, count as equals again;
   ``--damaged-cost main``: the policy then optimises the main position cost only;
   ``--damaged-policy-restarts N``: from the second damaged episode on, the policy
   search also runs from N - 1 random policies and keeps the best predicted return),
   stopping once it reaches again (unless ``--no-stop-when-recovered``).

The summary adds ``damage_at_episode`` (first episode on the damaged arm) and
``episodes_to_recover`` (damaged episodes until one reaches, counting that one; null if
none did). "Success": recovered within :data:`RECOVER_WITHIN` damaged episodes.
"""
from __future__ import annotations

import dataclasses
import logging
import os
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from ..experiment import Experiment, stack_transitions
from . import reacher
from .settings import non_negative_int, positive_float, positive_int, setting, task_settings

__all__ = ["AdaptationSettings", "AdaptationTask", "ADAPTATION", "damage", "learn_the_flag",
           "output_disagreement", "per_output_noise", "replay_damage", "joint_follow_ratios",
           "stuck_joints", "stop_stuck_joints", "recovered_within",
           "run_healthy", "restart_after_damage", "run", "RECOVER_WITHIN"]

logger = logging.getLogger(__name__)

#: success: the damaged arm reaches again within this many damaged episodes
RECOVER_WITHIN = 3

#: a joint whose rotations summed to less than this share of its commanded ones in every
#: healthy episode never followed its commands there either (e.g. held at a limit)
HEALTHY_FOLLOW_RATIO = 0.5


# The healthy reacher's fine cost (--fine-cost-width 0.05) stays, it rewards precision near
# the target on the damaged arm too; not its joint-limit cost, with which the damaged
# episodes ended short of the target (docs/success-rates.md, "What was tried"), nor its
# wide start distribution in the first learned episode, its policy initialised near the
# start state or its early stop of the policy search (none helped the adaptation, or
# none was measured on it). The elbow breaks where it is (stuck at its start angle), so
# the arm starts where the healthy one did and the healthy cost width still applies
# (--damage-mode straight straightens it, 1.17 m from the target: add --cost-width 0.4).
# --episodes is derived: random + healthy + damaged episodes.
@task_settings(limit_cost=0.0, early_start_var=0.0, policy_init_var=0.0,
               policy_min_rel_improvement=None, policy_patience=10, episodes=None,
               output="runs/adaptation-seed{seed}")
class AdaptationSettings(reacher.ReacherSettings):
    """The adaptation's settings: the reacher's, the damage and the episode budgets."""

    healthy_episodes: int = setting(4, "at most this many learned episodes before the damage",
                                    kind=non_negative_int, group="adaptation")
    min_healthy_episodes: int = setting(
        1, "learned episodes on the healthy arm before the damage even when an earlier one "
        "reached (more healthy data for the model; at most --healthy-episodes)",
        kind=positive_int, group="adaptation")
    damaged_episodes: int = setting(4, "at most this many learned episodes after it",
                                    kind=positive_int, group="adaptation")
    damaged_cost: str = setting(
        "all", "after the damage keep every cost term ('all') or only the main position cost "
        "('main': without --fine-cost-width and --limit-cost)", choices=("all", "main"),
        group="adaptation")
    damage_input: bool = setting(
        False, "tell the agent when the arm broke: the state gains a last dimension, 0 before "
        "the damage and 1 after, so that the dynamics GPs can learn how far the damaged "
        "arm's transitions follow the healthy arm's (not which joint broke)",
        group="adaptation")
    # the healthy transitions give way where the damaged arm's disagree with them, and keep
    # shaping the model where the two agree (docs/success-rates.md)
    old_data_noise: float = setting(
        100.0, "after the damage the model sees the healthy arm's transitions with F times "
        "the noise variance of the damaged arm's, so that they give way where the two "
        "disagree (1: as equals; once --stop-stuck-joints found a stuck joint: 1)",
        kind=positive_float, metavar="F", group="adaptation")
    changed_output_noise: Optional[float] = setting(
        None, "from the second damaged episode on, the state dimensions whose first damaged "
        "episode the healthy model explained badly (mean squared standardised one-step "
        "error above --changed-output-threshold) see the healthy arm's transitions with G "
        "times the noise variance, the others with --old-data-noise (None: off, "
        "--old-data-noise for all)", kind=positive_float, metavar="G", group="adaptation")
    changed_output_threshold: float = setting(
        10.0, "mean squared standardised one-step error of the healthy model on the first "
        "damaged episode above which a state dimension counts as changed by the damage",
        kind=positive_float, metavar="Z2", group="adaptation")
    # once a joint is known to be stuck, commanding it only adds actions that do nothing;
    # with its commands seen as 0 the healthy transitions describe the damaged arm too
    stop_stuck_joints: bool = setting(
        True, "from the second damaged episode on, stop commanding the joints that moved "
        "less than --stuck-joint-ratio of their commanded rotation in the first one (and "
        "followed their commands in a healthy episode); the model sees their commands after "
        "the damage as 0 and the healthy arm's transitions as equals again "
        "(--no-stop-stuck-joints: the healthy data keep --old-data-noise)", negatable=True,
        group="adaptation")
    stuck_joint_ratio: float = setting(
        0.1, "a joint counts as stuck when the sum of its measured rotations over the first "
        "damaged episode is below R times the sum of its commanded ones", kind=positive_float,
        metavar="R", group="adaptation")
    damaged_policy_restarts: int = setting(
        1, "from the second damaged episode on (the first one's model knows only the "
        "healthy arm), run each policy search from the previous policy and from N - 1 "
        "random ones, keeping the best predicted return (1: no restarts; replaces "
        "--policy-restarts then)", kind=positive_int, metavar="N", group="adaptation")
    drop_old_data: bool = setting(False, "after the damage, learn the model from damaged "
                                  "episodes only", group="adaptation")
    no_stop_when_recovered: bool = setting(False, "run all --damaged-episodes even after "
                                           "reaching again", group="adaptation")


def recovered_within(episodes: int):
    """``summary -> bool``: the damaged arm reached again within ``episodes`` episodes."""

    def success(summary: Dict[str, Any]) -> bool:
        recover = summary.get("episodes_to_recover")
        return recover is not None and recover <= episodes

    return success


def replay_damage(exp: Experiment, s: AdaptationSettings):
    """``(view, episode) -> None`` for :attr:`Experiment.before_replayed_episode`: when a
    replay of the run's learning (``python -m pilco.diagnose --episode N``) reaches the
    first damaged episode, the replayed agent gets what :func:`damage` gave the run's
    agent: the damaged arm's start state (that episode's first state) as ``m_init``, the
    main position cost alone with ``--damaged-cost main``, the flag's listener with
    ``--damage-input``, the restarts of ``--damaged-policy-restarts``. The data's factors
    after the damage come from the run's state, and so do the joints that
    ``--stop-stuck-joints`` stopped commanding from the next episode on."""

    def before(view, episode: int) -> None:
        first = exp.summary_fields.get("damage_at_episode")
        if first is not None and episode > first and exp.inert_actions:
            _stop_commanding(view.agent, exp.inert_actions)  # --stop-stuck-joints
        if first is None or episode != first:
            return
        agent = view.agent
        agent.m_init = exp.episodes[first - 1].states[0][None, :]
        if s.damaged_cost == "main":
            agent.reward = reacher.main_position_reward(agent.reward)
        if s.damage_input:
            learn_the_flag(agent, ignored=s.constant_input_lengthscale)
        restart_after_damage(view, s, first)

    return before


def damage(exp: Experiment, s: AdaptationSettings) -> None:
    """Break the arm's joints; the agent's ``m_init`` becomes the damaged start state;
    with ``--damaged-cost main`` its reward becomes the main position cost alone, with
    ``--damage-input`` :func:`learn_the_flag` watches its model's data. Called again on a
    run resumed after the damage."""
    env = exp.make_env()
    env.unwrapped.damage(tuple(s.damaged_joints), s.damage_mode)
    obs, _ = env.reset(seed=exp.episode_seed(len(exp.episodes) + 1))
    exp.agent.m_init = obs[None, :]  # the damaged arm may start elsewhere
    if s.damaged_cost == "main":
        exp.agent.reward = reacher.main_position_reward(exp.agent.reward)
    if s.damage_input:
        learn_the_flag(exp.agent, ignored=s.constant_input_lengthscale)


def learn_the_flag(agent, lengthscale: float = 1.0, ignored: float = 100.0) -> None:
    """With ``--damage-input``: when the model's data first hold transitions of the
    damaged arm (the state's last dimension, the flag, is 1), the flag's GP input gets
    ``lengthscale`` in every output GP instead of the ``ignored`` value that
    :func:`~pilco.tasks.reacher.ignore_constant_inputs` gave it while it was constant, so
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
    known = stack_transitions(exp.episodes[exp.train_from_episode - 1:first - 1])
    if exp.config.max_data is not None:
        known = tuple(a[: exp.config.max_data] for a in known)
    if len(known[0]) == 0:  # --drop-old-data: no healthy transition to weigh
        return
    z2 = output_disagreement(exp.agent, known, exp.episodes[first - 1].transitions())
    changed = z2 > s.changed_output_threshold
    fields["output_disagreement"] = [float(v) for v in z2]
    exp.older_noise_scale = [float(s.changed_output_noise if c else s.old_data_noise)
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


def stop_stuck_joints(exp: Experiment, s: AdaptationSettings, first: int) -> None:
    """With ``--stop-stuck-joints``, once the first damaged episode (``first``) ran and
    before the model learns from it: the joints :func:`stuck_joints` finds are no longer
    commanded (action bound 0), the model sees their commands in the damaged episodes as 0
    (``exp.inert_actions`` from episode ``first``), and the healthy arm's transitions count
    as equals again (noise factor 1): with the stuck joints' commands at 0 they describe the
    damaged arm. The env's ``joint_dims`` say which state dimension holds each action's
    joint. The summary holds ``joint_follow_ratio`` (first damaged episode, per action) and
    ``stuck_joints`` (action indices; the Fetch arm's elbow is 3). Applied again on resume
    (the saved agent keeps its bounds)."""
    fields = exp.summary_fields
    if not s.stop_stuck_joints or len(exp.episodes) < first:
        return
    if fields.get("stuck_joints") is None:
        joint_dims = exp.make_env().unwrapped.joint_dims
        joints = stuck_joints(exp.episodes[:first - 1], exp.episodes[first - 1:first],
                              s.stuck_joint_ratio, joint_dims)
        ratios = joint_follow_ratios(exp.episodes[first - 1:first], joint_dims)
        fields["joint_follow_ratio"] = [float(r) for r in ratios]
        fields["stuck_joints"] = joints
        logger.info("joints' measured over commanded rotation in the first damaged episode "
                    "%s; stuck (action indices): %s", np.round(ratios, 3), joints or "none")
        if joints:
            exp.inert_actions, exp.inert_from_episode = joints, first
            exp.older_noise_scale = 1.0
            exp.give_agent_data(exp.agent)
    if exp.inert_actions:
        _stop_commanding(exp.agent, exp.inert_actions)


def restart_after_damage(exp: Experiment, s: AdaptationSettings, first: int) -> None:
    """With ``--damaged-policy-restarts N`` > 1: the policy searches of episodes
    ``first + 1`` on (``first``: the first damaged episode, whose model has seen only the
    healthy arm) run N times, the last policy and N - 1 random ones, in every episode.
    Applied again on resume; without the flag the run's own restart settings stay."""
    if s.damaged_policy_restarts <= 1:
        return
    exp.config = dataclasses.replace(exp.config, policy_restarts=s.damaged_policy_restarts,
                                     policy_restart_when="always",
                                     policy_restart_from=first + 1)


def _learned_solved(exp: Experiment) -> bool:
    return any(not r["random"] and exp.episode_solved(e)
               for r, e in zip(exp.records, exp.episodes))


def _recovered_after(exp: Experiment, first: int) -> Optional[int]:
    """Damaged episodes until the first one that reached (counting it), or None; episode
    ``first`` is the first on the damaged arm."""
    for k, episode in enumerate(exp.episodes[first - 1:], start=1):
        if exp.episode_solved(episode):
            return k
    return None


def run_healthy(exp: Experiment, s: AdaptationSettings) -> None:
    """Learned episodes on the healthy arm until one has reached the target and at least
    ``--min-healthy-episodes`` ran, at most ``--healthy-episodes`` (a resumed run's
    episodes count)."""
    healthy = sum(not r["random"] for r in exp.records)
    solved = _learned_solved(exp)
    while healthy < s.healthy_episodes and (
            not solved or healthy < s.min_healthy_episodes):
        exp.run_learned_episode()
        healthy += 1
        solved = solved or exp.episode_solved(exp.episodes[-1])


def run(exp: Experiment, s: AdaptationSettings) -> Dict[str, Any]:
    """Healthy episodes until one reaches, the damage, damaged episodes until the arm
    reaches again (or their budget is spent); resumable at any episode."""
    fields = exp.summary_fields
    exp.complete = False
    with exp.session():
        while len(exp.episodes) < s.random_episodes:
            exp.run_random_episode()
        if fields["damage_at_episode"] is None:
            run_healthy(exp, s)
            damage(exp, s)
            fields["damage_at_episode"] = len(exp.episodes) + 1
            if s.drop_old_data:
                exp.train_from_episode = fields["damage_at_episode"]
            exp.older_noise_scale = s.old_data_noise
            exp.older_before_episode = fields["damage_at_episode"]
            exp.save_progress()
        else:
            damage(exp, s)  # resuming after the damage: break the fresh env again
        first = fields["damage_at_episode"]
        restart_after_damage(exp, s, first)
        # also on resume: a run killed after an episode's files but before this field's
        # save counts its recovery from the episodes themselves
        fields["episodes_to_recover"] = _recovered_after(exp, first)
        per_output_noise(exp, s, first)  # a run resumed after the first damaged episode
        stop_stuck_joints(exp, s, first)
        while len(exp.episodes) - first + 1 < s.damaged_episodes:
            if fields["episodes_to_recover"] is not None and not s.no_stop_when_recovered:
                break
            exp.run_learned_episode()
            fields["episodes_to_recover"] = _recovered_after(exp, first)
            per_output_noise(exp, s, first)
            stop_stuck_joints(exp, s, first)
            exp.save_progress()
        exp.complete = True
    return exp.summary()


class AdaptationTask(reacher.ReacherTask):
    """The healthy reacher, the damage mid-run, the damaged arm with the same agent."""

    name = "adaptation"
    settings = AdaptationSettings
    description = "PILCO on the Fetch reacher, adapting to a joint damaged mid-run"
    # the paper code's arm reports its commanded joint angles, in which no joint sticks
    presets = {"paper-code": dict(reacher.PAPER_CODE, stop_stuck_joints=False)}
    paper_seconds = None

    def check(self, s: AdaptationSettings) -> AdaptationSettings:
        if s.stop_stuck_joints and s.changed_output_noise is not None:
            raise ValueError(
                "--stop-stuck-joints (the default) and --changed-output-noise both set the "
                "healthy data's noise factors after the first damaged episode: add "
                "--no-stop-stuck-joints to use --changed-output-noise")
        if s.stop_stuck_joints and s.joint_state != "measured":
            raise ValueError("--stop-stuck-joints (the default) reads the measured joint "
                             "angles: with --joint-state commanded add --no-stop-stuck-joints")
        return dataclasses.replace(s, episodes=s.random_episodes + s.healthy_episodes
                                   + s.damaged_episodes)

    def make_env(self, s: AdaptationSettings, config):
        """The healthy arm; with ``--damage-input`` its state gains the damage flag."""
        env = super().make_env(s, config)
        if s.damage_input:
            from ..envs import DamageFlag

            env = DamageFlag(env)
        return env

    def hooks(self, s: AdaptationSettings, env) -> Dict[str, Any]:
        return dict(super().hooks(s, env), success_fn=recovered_within(RECOVER_WITHIN))

    def prepare(self, exp: Experiment, s: AdaptationSettings) -> None:
        """The adaptation's summary fields, and the damage redone by a replay."""
        super().prepare(exp, s)
        exp.summary_fields = {"damage_at_episode": None, "episodes_to_recover": None,
                              **exp.summary_fields}
        exp.before_replayed_episode = replay_damage(exp, s)

    def run(self, exp: Experiment, s: AdaptationSettings) -> Dict[str, Any]:
        return run(exp, s)

    def notes(self, summary: Dict[str, Any]) -> List[str]:
        return [f"\ndamage at episode {summary['damage_at_episode']}; episodes to recover: "
                f"{summary['episodes_to_recover']}"]

    def figures(self, exp: Experiment, s: AdaptationSettings) -> List[str]:
        """``adaptation_distance.png`` (healthy and damaged episodes) and the reacher's."""
        from .. import plotting

        first = exp.summary_fields["damage_at_episode"]
        kinds = ["random" if e.random else "healthy" if i + 1 < first else "damaged"
                 for i, e in enumerate(exp.episodes)]
        paths = [plotting.plot_distances(
            [e.distances for e in exp.episodes],
            os.path.join(exp.directory, "adaptation_distance.png"),
            random=[e.random for e in exp.episodes], threshold=s.threshold,
            ylabel="distance to target [m]",
            labels=[f"episode {i + 1} ({k})" for i, k in enumerate(kinds)], marks=[first],
            title=f"damage ({', '.join(s.damaged_joints)}, {s.damage_mode}) "
                  f"before episode {first}")]
        return paths + super().figures(exp, s)


ADAPTATION = AdaptationTask()
