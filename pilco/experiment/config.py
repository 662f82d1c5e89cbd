"""The settings of one PILCO run: :class:`LoopSettings`, the loop's own, each declared
once with its command-line flag, and :class:`ExperimentConfig`, those plus what a task
fixes (its environment, its distance's cost width, its solved rule)."""
from __future__ import annotations

import dataclasses
from typing import Any, Dict, Mapping, Optional

from .settings import (check_declared, non_negative_float, non_negative_int, positive_int,
                       setting, task_settings, whole)

__all__ = ["LoopSettings", "ExperimentConfig"]


@task_settings()
class LoopSettings:
    """The loop's settings, each declared once: its default, its flag (``policy_iters`` is
    ``--policy-iters``, :func:`pilco.tasks.settings.build_parser`) and its check (a
    ``ValueError`` naming the setting when the object is made). A task's settings extend
    them (:class:`pilco.tasks.settings.RunSettings`), and the loop reads them, by the same
    names, from its :class:`ExperimentConfig`.

    Attributes:
        seed: base seed (env resets, random actions, restarts).
        episodes: total number of episodes, random ones included.
        random_episodes: episodes with random actions at the start.
        horizon: steps per episode (the env may end an episode earlier) and the
            planning horizon.
        max_data: the dynamics model learns from the first ``max_data`` transitions
            only (``None`` or 0: all of them).
        model_iters, model_restarts: L-BFGS iterations / restarts of GP training.
        model_min_rel_improvement: stop GP training once its loss fell by less than this
            (relative) over the last ``model_patience`` iterations (``None``: always
            ``model_iters``).
        policy_iters, policy_restarts: the same for the policy.
        policy_optimizer: ``"L-BFGS-B"`` or ``"BFGS"`` (see ``PILCO.optimize_policy``).
        policy_compiler: ``"graph"`` (TensorFlow) or ``"xla"`` (``optimize_policy``'s
            ``jit_compile``).
        policy_iters_first: iterations of the first policy optimisation (``None``: as
            ``policy_iters``; the paper's code ran its 30 twice the first time).
        policy_min_rel_improvement, policy_patience: stop a policy optimisation run when its
            predicted return grew by less than ``policy_min_rel_improvement`` (relative)
            over the last ``policy_patience`` iterations (``None``: always ``policy_iters``).
        policy_early_stop: ``"always"``, or ``"solved"``: the early stop applies only once
            an episode has been solved (refining a policy that works needs few
            iterations; before that, a slow stretch often precedes a large gain).
        policy_restart_when: ``"always"``, or ``"unsolved"``: the ``policy_restarts - 1``
            restarts from random policies run only while no episode has been solved (a
            policy stuck in a poor optimum, e.g. the cart-pole's "swing over the top and
            round again", is left for a better one; once solved, the warm start is kept).
        policy_restart_from: the restarts run only from episode ``policy_restart_from``
            on (1-based, random episodes counted; 1: from the first learned episode). With
            ``policy_restart_when="unsolved"`` a run solved before that episode never
            restarts, so it costs and learns exactly as without restarts; one still
            unsolved there gets them (a stuck warm start is what they fix).
        policy_restart_step: restarts added in each episode after
            ``policy_restart_from`` in which the restarts still run (0: the same
            ``policy_restarts`` in every one): with ``policy_restart_when="unsolved"``, the
            longer a run stays unsolved, the wider its search.
        policy_leave_repeat: while no episode was solved, in an episode whose policy
            search runs restarts, when the run continued from the last policy wins with a
            predicted return within ``policy_leave_repeat`` of the last episode's real
            return (scaled to the horizon: ``horizon * (1 - cost / steps)``), the best of
            the fresh runs is used instead: the model already knows the winner's outcome,
            a failure, and a fresh policy gathers data where the model has none (``None``
            or 0: off).
        policy_warm_start: ``"always"``: every policy search starts from the policy of
            the episode before; ``"solved"``: only once an episode was solved; before
            that, each learned episode after the first starts from a fresh random policy
            (``controller.randomize``), the same number of searches as the warm start.
        policy_start_mixture: the spread of the policy objective's start mixture
            (:attr:`pilco.models.PILCO.start_spread`; ``None`` or 0: one Gaussian start).
        policy_start_mixture_when: ``"always"``; ``"solved"``: the start mixture is used
            only once an episode has been solved (it keeps a policy that works working
            from the whole start distribution; before that, the plain objective);
            ``"fragile"``: once solved, the plain search runs first and the mixture's
            search follows only when the policy it found is fragile, its plain expected
            return above the mixture's by more than ``policy_fragile_gap``.
        policy_fragile_gap: the gap (in reward, i.e. steps at full cost) between the
            plain and the mixture's expected return above which a policy is fragile.
        policy_flank_points: the spread of the policy objective's flank points (known
            start states, :attr:`pilco.models.PILCO.start_points`, from
            :func:`pilco.models.starts.flank_points`; ``None`` or 0: none).
        policy_start_samples: the number of known start states drawn from the start
            distribution for the policy objective (:func:`pilco.models.starts.start_samples`,
            drawn again in every episode; 0: none).
        policy_start_scale: a wide start beside the start distribution, this many times
            its standard deviations (:attr:`pilco.models.PILCO.start_scale`; ``None`` or 0:
            none).
        policy_start_points_when: ``"always"``; ``"solved"``: the start points and the wide
            start are used
            only once an episode has been solved (the plain objective learns the task;
            the points keep the policy working from the whole start distribution).
        retrain_unchanged_model: train the GPs again even when their training data did
            not change since the last training (``max_data`` reached); by default the
            trained hyperparameters are kept (the optimum is the same).
        quiet: no progress bars.
    """

    seed: int = setting(0, "random seed", kind=non_negative_int, group="experiment")
    episodes: Optional[int] = setting(4, "total episodes including the random ones",
                                      kind=positive_int, group="experiment")
    random_episodes: int = setting(1, "episodes with random actions first",
                                   kind=positive_int, group="experiment")
    horizon: int = setting(50, "steps per episode and planning horizon", kind=positive_int,
                           group="experiment")
    quiet: bool = setting(False, "no progress bars", group="experiment")
    policy_iters: int = setting(50, "optimiser iterations per policy optimisation",
                                kind=positive_int, group="learning")
    policy_restarts: int = setting(1, "policy optimisation restarts", kind=positive_int,
                                   group="learning")
    policy_restart_from: int = setting(
        1, "episode (1-based, random ones counted) from which --policy-restarts apply",
        kind=positive_int, group="learning")
    policy_restart_step: int = setting(
        0, "restarts added in each episode after --policy-restart-from in which restarts "
        "run (with --policy-restart-when unsolved: the longer a run stays unsolved, the "
        "wider its search)", kind=non_negative_int, group="learning")
    policy_patience: int = setting(10, "iterations for --policy-min-rel-improvement",
                                   kind=positive_int, group="learning")
    policy_iters_first: Optional[int] = setting(
        None, "iterations of the first policy optimisation", kind=positive_int,
        group="learning", unset="as --policy-iters")
    model_iters: int = setting(1000, "L-BFGS iterations of GP training", kind=positive_int,
                               group="learning")
    model_restarts: int = setting(1, "GP training restarts", kind=positive_int,
                                  group="learning")
    max_data: Optional[int] = setting(
        None, "GP learns from the first N transitions only (0: all)",
        kind=non_negative_int, group="learning", unset="all")
    policy_optimizer: str = setting(
        "L-BFGS-B", "policy optimiser (BFGS: dense update, as the MATLAB release)",
        kind=str.upper, choices=("L-BFGS-B", "BFGS"), group="learning")
    policy_compiler: str = setting(
        "graph", "compile the policy objective and its gradient as a TensorFlow graph, or "
        "whole by XLA (faster on small problems; compiled once per data-size bucket and "
        "cached on disk: $PILCO_XLA_CACHE, default ~/.cache/pilco/xla; TensorFlow logs "
        "'Error parsing text-format tensorflow.XlaSerializedCacheEntry' for each program it "
        "loads from there: harmless, the load succeeds)",
        choices=("graph", "xla"), group="learning")
    policy_min_rel_improvement: Optional[float] = setting(
        None, "stop a policy optimisation once its predicted return grew by less than this "
        "fraction of it over the last --policy-patience iterations (0: never)",
        kind=float, group="learning", unset="never")
    policy_early_stop: str = setting(
        "always", "apply --policy-min-rel-improvement always, or only once an episode was "
        "solved", choices=("always", "solved"), group="learning")
    policy_restart_when: str = setting(
        "always", "run the --policy-restarts restarts from random policies in every policy "
        "optimisation, or only until an episode was solved", choices=("always", "unsolved"),
        group="learning")
    policy_warm_start: str = setting(
        "always", "start each policy search from the previous episode's policy always, or "
        "only once an episode was solved (before: from a fresh random policy)",
        choices=("always", "solved"), group="learning")
    policy_start_mixture: Optional[float] = setting(
        None, "split the policy objective's start distribution into 2D+1 narrower Gaussians "
        "of the same mean and covariance, two of them this many standard deviations out "
        "along each principal axis, so that a policy failing from the flanks of the start "
        "distribution is seen to fail (0: off; costs 2D+1 times per evaluation)",
        kind=non_negative_float, group="learning", unset="off")
    policy_start_mixture_when: str = setting(
        "solved", "use --policy-start-mixture in every policy search; only once an episode "
        "was solved (keeping a policy that works); or, once solved, only when the plain "
        "search's policy is fragile (its plain expected return above the mixture's by more "
        "than --policy-fragile-gap)", choices=("always", "solved", "fragile"),
        group="learning")
    policy_fragile_gap: float = setting(
        1.0, "gap between the plain and the start mixture's expected return (in steps at "
        "full cost) above which a policy is fragile", kind=non_negative_float,
        group="learning")
    policy_flank_points: Optional[float] = setting(
        None, "beside the policy objective's start distribution (one moment-matched "
        "Gaussian), roll out the 2D known states this many standard deviations out along "
        "each of its principal axes through the model's mean dynamics and weigh their "
        "return with the Gaussian's, so that a policy failing from the flanks of the start "
        "distribution is seen to fail (0: off)", kind=non_negative_float, group="learning",
        unset="off")
    policy_start_samples: int = setting(
        0, "the same with this many known states drawn from the start distribution (drawn "
        "again in every episode; 0: off)", kind=non_negative_int, group="learning")
    policy_leave_repeat: Optional[float] = setting(
        None, "while no episode was solved, in an episode whose policy search runs "
        "restarts: when the search continued from the last policy wins but is predicted to "
        "return within this much of what the last episode really did (a failure the model "
        "already knows), run the best of the fresh searches instead (0: off; returns "
        "summed over the horizon)", kind=non_negative_float, group="learning", unset="off")
    policy_start_scale: Optional[float] = setting(
        None, "beside the policy objective's start distribution, propagate one this many "
        "times as wide (its standard deviations) and average their expected returns, so "
        "that the objective sees the flanks of the start distribution with the model's "
        "uncertainty there (0: off; twice the cost per evaluation)",
        kind=non_negative_float, group="learning", unset="off")
    policy_start_points_when: str = setting(
        "solved", "use --policy-flank-points, --policy-start-samples and "
        "--policy-start-scale in every policy search, or only once an episode was solved",
        choices=("always", "solved"), group="learning")
    model_min_rel_improvement: Optional[float] = setting(
        None, "stop GP training once its loss fell by less than this fraction of it over "
        "the last 10 iterations (0: never)", kind=float, group="learning", unset="never")
    retrain_unchanged_model: bool = setting(
        False, "train the GPs again even if their training data did not change",
        group="learning")

    def __post_init__(self):
        """Check each setting and the relations between them (a ``ValueError`` naming the
        setting). Settings from the command line, a preset, a resumed run's saved ones
        and a config made in code are all checked here."""
        _check_loop(self)


def _check_loop(s: LoopSettings) -> None:
    # each setting against its declaration (choices, whole-number and number ranges),
    # then what a declaration cannot say: the relations between settings
    if whole(s.random_episodes, 0) and s.random_episodes < 1:
        raise ValueError("at least one random episode is needed to build the model")
    check_declared(s)
    if s.episodes is not None and s.episodes < s.random_episodes:
        raise ValueError(f"episodes ({s.episodes}) must be >= random_episodes "
                         f"({s.random_episodes})")
    if s.max_data not in (None, 0) and s.max_data < 2:
        raise ValueError(f"max_data must be at least 2 (or 0 or None: all), got "
                         f"{s.max_data!r}")


#: settings for which 0 means off, as None does (the config keeps None)
OFF_WHEN_ZERO = ("policy_start_mixture", "policy_flank_points", "policy_start_scale",
                 "policy_leave_repeat")

#: names a saved run's config may use for today's settings (runs saved before the loop's
#: settings were declared once)
RENAMED = {"steps": "horizon", "policy_method": "policy_optimizer"}


@dataclasses.dataclass(frozen=True, kw_only=True)
class ExperimentConfig(LoopSettings):
    """A run's settings as the loop reads them: the :class:`LoopSettings` and what the task
    fixes (made by :meth:`pilco.tasks.base.Task.loop_config` from a task's settings, or in
    code). Frozen: a task that changes a setting mid-run replaces the config
    (:func:`dataclasses.replace`). ``0`` of a setting in :data:`OFF_WHEN_ZERO` and of
    ``max_data`` is kept as None.

    Attributes:
        task: how the run's task is found again (its name or ``module:ATTRIBUTE``),
            written in the summary.
        env_id: gymnasium id; ``env_kwargs`` go to ``gymnasium.make``.
        random_action_scale: random actions uniform in ``±scale`` (``None``: uniform
            over the env's action space).
        model_patience: iterations of GP training's early stop
            (``model_min_rel_improvement``).
        cost_width: width of the saturating cost of the distance (summary ``cost``).
        success_threshold: distance [m] counted as "at the target".
        solved_rule: ``"reach"``: an episode is solved when any state is within the
            threshold; ``"hold"``: when the last ``hold_steps`` states all are;
            ``"survive"``: when it lasted ``hold_steps`` steps (an env that terminates on
            failure).
        render: record frames of the final episode.
        predictions: before each learned episode, store the model's multi-step
            predictions and, after it, its one-step predictions (for the figures).
    """

    task: str
    env_id: str
    env_kwargs: Dict[str, Any] = dataclasses.field(default_factory=dict)
    random_action_scale: Optional[float] = None
    model_patience: int = 10
    cost_width: float = 0.25
    success_threshold: float = 0.05
    solved_rule: str = "reach"
    hold_steps: int = 10
    render: bool = True
    predictions: bool = True

    def __post_init__(self):
        super().__post_init__()
        if self.episodes is None:
            raise ValueError("episodes must be a whole number >= 1, got None")
        for name in ("model_patience", "hold_steps"):
            if not whole(getattr(self, name), 1):
                raise ValueError(f"{name} must be a whole number >= 1, got "
                                 f"{getattr(self, name)!r}")
        if self.solved_rule not in ("reach", "hold", "survive"):
            raise ValueError(f"solved_rule must be 'reach', 'hold' or 'survive', got "
                             f"{self.solved_rule!r}")
        for name in (*OFF_WHEN_ZERO, "max_data"):
            if getattr(self, name) == 0:
                object.__setattr__(self, name, None)

    @classmethod
    def from_saved(cls, values: Mapping[str, Any]) -> "ExperimentConfig":
        """The config saved in a run's ``progress.json``: settings under a name of before
        (:data:`RENAMED`) read under today's, settings since removed dropped, settings added
        since at their default."""
        names = {f.name for f in dataclasses.fields(cls)}
        kept = {RENAMED.get(k, k): v for k, v in values.items()}
        return cls(**{k: v for k, v in kept.items() if k in names})

    def first_learned(self, number: int) -> bool:
        """Whether episode ``number`` (1-based) is the first one with a learned policy."""
        return number == self.random_episodes + 1

    def policy_iterations(self, number: int) -> int:
        """The policy search's iteration budget of episode ``number``:
        ``policy_iters_first`` for the first learned episode when set, else ``policy_iters``."""
        if self.first_learned(number) and self.policy_iters_first:
            return self.policy_iters_first
        return self.policy_iters

    def policy_early_stop_at(self, solved: bool) -> Optional[float]:
        """The relative early stop of a policy search (its ``min_rel_improvement``),
        given whether an earlier episode was solved: ``policy_min_rel_improvement``
        always, or with ``policy_early_stop="solved"`` only once solved (else None: every
        iteration runs)."""
        if self.policy_early_stop == "always" or solved:
            return self.policy_min_rel_improvement
        return None

    def start_mixture_at(self, solved: bool) -> Optional[float]:
        """The spread of the policy objective's start mixture in a search, given whether an
        earlier episode was solved (None: the plain objective; with ``"fragile"`` the
        search is plain and :meth:`fragile_check_at` says whether a mixture's follows)."""
        when = self.policy_start_mixture_when
        if when == "always" or (when == "solved" and solved):
            return self.policy_start_mixture
        return None

    def start_points_at(self, solved: bool):
        """The policy objective's start points and wide start in a search, given whether
        an earlier episode was solved: ``(spread of the flank points or None, number of
        samples, start scale or None)``, or None when there are none."""
        wanted = (self.policy_flank_points is not None or self.policy_start_samples > 0
                  or self.policy_start_scale is not None)
        if wanted and (self.policy_start_points_when == "always" or solved):
            return self.policy_flank_points, self.policy_start_samples, self.policy_start_scale
        return None

    def fragile_check_at(self, solved: bool) -> Optional[float]:
        """The start mixture's spread when the plain search's policy is to be checked for
        fragility (``"fragile"`` once solved), else None."""
        if self.policy_start_mixture_when == "fragile" and solved:
            return self.policy_start_mixture
        return None

    def policy_restarts_at(self, number: int, solved: bool) -> int:
        """The policy search's runs (``policy_restarts``, or 1 without restarts) in
        episode ``number`` (1-based), given whether an earlier episode was solved: the
        restarts run from episode ``policy_restart_from`` on, and with
        ``policy_restart_when="unsolved"`` only while nothing was solved; each episode
        after ``policy_restart_from`` adds ``policy_restart_step`` more."""
        if number < self.policy_restart_from:
            return 1
        if self.policy_restart_when == "unsolved" and solved:
            return 1
        later = number - self.policy_restart_from
        return self.policy_restarts + self.policy_restart_step * later
