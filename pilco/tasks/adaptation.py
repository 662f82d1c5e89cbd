"""Adaptation to damage: learn to reach on the healthy Fetch arm, then break a joint
mid-run and keep learning with the same agent (the paper's motivation, §5.2).

1. the random episodes and up to ``--healthy-episodes`` learned episodes on the healthy
   arm, stopping as soon as an episode has reached the target and at least
   ``--min-healthy-episodes`` were run;
2. :func:`damage`: ``env.damage(--damaged-joints, --damage-mode)`` (the agent is not
   told unless ``--damage-input``; by default the elbow is stuck at its angle,
   ``--damage-mode straight`` straightens it); the damaged arm's start state becomes the
   agent's ``m_init``;
3. up to ``--damaged-episodes`` learned episodes with the same agent, policy and data;
   the first one watches the joints (``--replan-stuck-joints``, the default): once a joint
   that followed its commands on the healthy arm stops following them, the episode pauses,
   the joint is no longer commanded and the policy is searched again from the state
   reached (:class:`~pilco.tasks.adaptation_model.ReplanWhenStuck`)
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

The summary adds ``healthy_reached_at_episode`` (the first healthy episode that reached,
null if none did), ``damage_at_episode`` (first episode on the damaged arm) and
``episodes_to_recover`` (damaged episodes until one reaches, counting that one; null if
none did). "Success": recovered within :data:`RECOVER_WITHIN` damaged episodes.
"""
from __future__ import annotations

import dataclasses
import logging
import os
from typing import Any, Dict, List, Optional

from ..experiment import Experiment, RunHooks
from . import reacher, reacher_agent
from .adaptation_model import (ReplanWhenStuck, _stop_commanding, damaged_arm_data,
                               learn_the_flag, per_output_noise, stop_stuck_joints,
                               track_damage_data)
from .settings import non_negative_int, positive_float, positive_int, setting, task_settings

__all__ = ["AdaptationSettings", "AdaptationTask", "AdaptationHooks", "AdaptationSchedule",
           "ADAPTATION", "damage", "replay_damage", "recovered_within", "restart_after_damage",
           "RECOVER_WITHIN"]

logger = logging.getLogger(__name__)

#: success: the damaged arm reaches again within this many damaged episodes
RECOVER_WITHIN = 3


# The healthy phase is the reacher task's learning: every setting below not named here
# is the reacher's default (its costs, its wide first start distribution, its policy
# initialised near the start, its early stop), and the healthy episodes are the reacher's
# learned-episode budget. --episodes is derived: random + healthy + damaged episodes.
@task_settings(episodes=None, output="runs/adaptation-seed{seed}")
class AdaptationSettings(reacher.ReacherSettings):
    """The adaptation's settings: the reacher's, the damage and the episode budgets."""

    healthy_episodes: int = setting(
        reacher.LEARNED_EPISODES, "at most this many learned episodes before the damage "
        "(the reacher's budget)", kind=non_negative_int, group="adaptation")
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
        "times the noise variance, the others with --old-data-noise", kind=positive_float,
        metavar="G", group="adaptation", unset="off: --old-data-noise for all")
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
    replan_stuck_joints: bool = setting(
        True, "in the first damaged episode, watch the joints: once one that followed its "
        "commands on the healthy arm stops following them (as --stop-stuck-joints judges, "
        "on the steps so far), pause the episode, stop commanding it and search the policy "
        "again from the state reached, then go on (--no-replan-stuck-joints: wait for the "
        "episode's end)", negatable=True, group="adaptation")
    stuck_check_steps: int = setting(
        3, "steps of the first damaged episode before its joints are judged",
        kind=positive_int, metavar="K", group="adaptation")
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


def replay_damage(s: AdaptationSettings):
    """``(run, view, episode) -> None``, the run's ``before_replayed_episode``: when a
    replay of the run's learning (``python -m pilco.diagnose --episode N``) reaches the
    first damaged episode, the replayed agent gets what :func:`damage` gave the run's
    agent: the damaged arm's start state (that episode's first state) as ``m_init``, the
    main position cost alone with ``--damaged-cost main``, the flag's listener with
    ``--damage-input``, the restarts of ``--damaged-policy-restarts``. The data's factors
    after the damage come from the run's state, and so do the joints that
    ``--stop-stuck-joints`` stopped commanding from the next episode on."""

    def before(exp: Experiment, view, episode: int) -> None:
        first = exp.summary_fields.get("damage_at_episode")
        inert = exp.task_state.get("inert_actions")
        if first is not None and episode > first and inert:
            _stop_commanding(view.agent, inert)  # --stop-stuck-joints
        if first is not None and episode == first + 1 and "replanned" in exp.records[first - 1]:
            logger.warning("episode %d re-planned mid-episode, which a replay does not redo: "
                           "the replayed policy search of episode %d starts from the policy "
                           "before the re-plan", first, episode)
        if first is None or episode != first:
            return
        agent = view.agent
        agent.m_init = exp.episodes[first - 1].states[0][None, :]
        if s.damaged_cost == "main":
            agent.reward = reacher_agent.main_position_reward(agent.reward)
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
        exp.agent.reward = reacher_agent.main_position_reward(exp.agent.reward)
    if s.damage_input:
        learn_the_flag(exp.agent, ignored=s.constant_input_lengthscale)


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


class AdaptationSchedule(RunHooks):
    """The adaptation's schedule and what it changes between episodes, for hooks whose
    :attr:`settings` are :class:`AdaptationSettings` (:class:`AdaptationHooks` adds them
    to the reacher's run): healthy episodes until one reached the target and at least
    ``--min-healthy-episodes`` ran (at most ``--healthy-episodes``), then the damage
    (:func:`damage`) before the first damaged episode, then damaged episodes until the arm
    reaches again or their budget is spent; the first damaged episode watches the joints
    (:class:`~pilco.tasks.adaptation_model.ReplanWhenStuck`), and after each damaged one
    the healthy data's noise factors and the joints found stuck are updated
    (:func:`per_output_noise`, :func:`stop_stuck_joints`). Resumable at any episode: a run
    read back after the damage breaks its fresh env again before its next episode."""

    settings: AdaptationSettings
    #: whether this process's env is broken (set once :meth:`before_episode` broke it)
    _damaged: bool = False

    def opened(self, run) -> None:
        """The adaptation's summary fields and the data it tracks."""
        super().opened(run)
        run.summary_fields = {"healthy_reached_at_episode": None, "damage_at_episode": None,
                              "episodes_to_recover": None, **run.summary_fields}
        track_damage_data(run)

    def model_data(self, run):
        return damaged_arm_data(run)

    def before_episode(self, run, number: int) -> bool:
        s, fields = self.settings, run.summary_fields
        if number <= s.random_episodes:
            return True
        if fields["damage_at_episode"] is None:
            healthy = sum(not r["random"] for r in run.records)
            if healthy < s.healthy_episodes and (
                    not _learned_solved(run) or healthy < s.min_healthy_episodes):
                return True  # one more healthy episode
            fields["healthy_reached_at_episode"] = run.solved_at_episode()
            damage(run, s)
            fields["damage_at_episode"] = number
            state = track_damage_data(run)
            if s.drop_old_data:
                state["train_from_episode"] = number
            state["older_noise_scale"] = s.old_data_noise
            state["older_before_episode"] = number
            run.save_progress()
        elif not self._damaged:  # read back after the damage: break the fresh env again
            damage(run, s)
        first = fields["damage_at_episode"]
        if not self._damaged:
            self._damaged = True
            restart_after_damage(run, s, first)
            self._after_damaged_episode(run)
        if number - first >= s.damaged_episodes:
            return False
        return fields["episodes_to_recover"] is None or s.no_stop_when_recovered

    def _after_damaged_episode(self, run) -> None:
        """The recovery count, the healthy data's noise factors and the joints found
        stuck, from the damaged episodes so far (none yet right after the damage)."""
        s, first = self.settings, run.summary_fields["damage_at_episode"]
        # also on resume: a run killed after an episode's files but before this field's
        # save counts its recovery from the episodes themselves
        run.summary_fields["episodes_to_recover"] = _recovered_after(run, first)
        per_output_noise(run, s, first)
        stop_stuck_joints(run, s, first)

    def after_episode(self, run, number: int) -> None:
        super().after_episode(run, number)
        first = run.summary_fields["damage_at_episode"]
        if first is not None and number >= first:
            self._after_damaged_episode(run)
            run.save_progress()

    def watch(self, run, number: int, policy):
        """The first damaged episode's :class:`ReplanWhenStuck` (with
        ``--replan-stuck-joints`` and ``--stop-stuck-joints``, while no joint was judged
        yet); otherwise the policy of the hooks it is mixed with."""
        policy = super().watch(run, number, policy)
        s, first = self.settings, run.summary_fields["damage_at_episode"]
        if (first is not None and number >= first and s.replan_stuck_joints
                and s.stop_stuck_joints and run.summary_fields.get("stuck_joints") is None):
            return ReplanWhenStuck(run, s, first, number)(policy)
        return policy

    def before_replayed_episode(self, run, view, number: int) -> None:
        replay_damage(self.settings)(run, view, number)

    def success(self, summary: Dict[str, Any]) -> bool:
        return recovered_within(RECOVER_WITHIN)(summary)


class AdaptationHooks(AdaptationSchedule, reacher.ReacherHooks):
    """The reacher's run (:class:`~pilco.tasks.reacher.ReacherHooks`) on the adaptation's
    schedule (:class:`AdaptationSchedule`)."""


class AdaptationTask(reacher.ReacherTask):
    """The healthy reacher, the damage mid-run, the damaged arm with the same agent."""

    name = "adaptation"
    settings = AdaptationSettings
    description = "PILCO on the Fetch reacher, adapting to a joint damaged mid-run"
    # the paper code's arm reports its commanded joint angles, in which no joint sticks
    presets = {"paper-code": dict(reacher.PAPER_CODE, stop_stuck_joints=False)}
    paper_seconds = None
    system_from_settings = False  # the arm breaks during the run

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

    run_hooks = AdaptationHooks

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
