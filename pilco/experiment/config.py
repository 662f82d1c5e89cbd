"""The settings of one PILCO run: :class:`ExperimentConfig`."""
from __future__ import annotations

import dataclasses
from typing import Any, Dict, Optional

__all__ = ["ExperimentConfig"]


@dataclasses.dataclass
class ExperimentConfig:
    """Settings of a run (everything a command line sets).

    Attributes:
        task: name written in the summary.
        env_id: gymnasium id; ``env_kwargs`` go to ``gymnasium.make``.
        seed: base seed (env resets, random actions, restarts).
        episodes: total number of episodes, random ones included.
        random_episodes: episodes with random actions at the start.
        steps: steps per episode (the env may end an episode earlier).
        random_action_scale: random actions uniform in ``±scale`` (``None``: uniform
            over the env's action space).
        max_data: the dynamics model learns from the first ``max_data`` transitions
            only (``None`` or 0: all of them).
        model_iters, model_restarts: L-BFGS iterations / restarts of GP training.
        model_min_rel_improvement, model_patience: stop GP training once its loss fell by less
            than ``model_min_rel_improvement`` (relative) over the last ``model_patience``
            iterations
            (``None``: always ``model_iters``).
        policy_iters, policy_restarts: the same for the policy.
        policy_method: ``"L-BFGS-B"`` or ``"BFGS"`` (see ``PILCO.optimize_policy``).
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
        cost_width: width of the saturating cost of the distance (summary ``cost``).
        success_threshold: distance [m] counted as "at the target".
        solved_rule: ``"reach"``: an episode is solved when any state is within the
            threshold; ``"hold"``: when the last ``hold_steps`` states all are.
        retrain_unchanged_model: train the GPs again even when their training data did
            not change since the last training (``max_data`` reached); by default the
            trained hyperparameters are kept (the optimum is the same).
        render: record frames of the final episode.
        predictions: before each learned episode, store the model's multi-step
            predictions and, after it, its one-step predictions (for the figures).
        quiet: no progress bars.
    """

    task: str
    env_id: str
    seed: int = 0
    episodes: int = 4
    random_episodes: int = 1
    steps: int = 50
    env_kwargs: Dict[str, Any] = dataclasses.field(default_factory=dict)
    random_action_scale: Optional[float] = None
    max_data: Optional[int] = None
    model_iters: int = 1000
    model_restarts: int = 1
    model_min_rel_improvement: Optional[float] = None
    model_patience: int = 10
    policy_iters: int = 50
    policy_restarts: int = 1
    policy_method: str = "L-BFGS-B"
    policy_compiler: str = "graph"
    policy_min_rel_improvement: Optional[float] = None
    policy_patience: int = 10
    policy_iters_first: Optional[int] = None
    policy_early_stop: str = "always"
    policy_restart_when: str = "always"
    policy_restart_from: int = 1
    policy_restart_step: int = 0
    policy_leave_repeat: Optional[float] = None
    policy_warm_start: str = "always"
    policy_start_mixture: Optional[float] = None
    policy_start_mixture_when: str = "solved"
    policy_fragile_gap: float = 1.0
    policy_flank_points: Optional[float] = None
    policy_start_samples: int = 0
    policy_start_scale: Optional[float] = None
    policy_start_points_when: str = "solved"
    cost_width: float = 0.25
    success_threshold: float = 0.05
    solved_rule: str = "reach"
    hold_steps: int = 10
    retrain_unchanged_model: bool = False
    render: bool = True
    predictions: bool = True
    quiet: bool = False

    def __post_init__(self):
        """Check each setting and the relations between them (a ``ValueError`` naming the
        setting). Every way a run is configured builds this dataclass, so these checks
        cover command-line flags and the settings a resumed run reads back alike."""
        for name in ("episodes", "steps", "model_iters", "policy_iters", "model_restarts",
                     "policy_restarts", "policy_patience", "hold_steps",
                     "policy_restart_from"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a whole number >= 1, got {value!r}")
        if self.policy_iters_first is not None and (
                not isinstance(self.policy_iters_first, int) or self.policy_iters_first < 1):
            raise ValueError(f"policy_iters_first must be a whole number >= 1 or None, got "
                             f"{self.policy_iters_first!r}")
        for name, (a, b) in (("policy_early_stop", ("always", "solved")),
                             ("policy_restart_when", ("always", "unsolved")),
                             ("policy_warm_start", ("always", "solved")),
                             ("policy_start_points_when", ("always", "solved")),
                             ("solved_rule", ("reach", "hold")),
                             ("policy_compiler", ("graph", "xla"))):
            value = getattr(self, name)
            if value not in (a, b):
                raise ValueError(f"{name} must be {a!r} or {b!r}, got {value!r}")
        if self.random_episodes < 1:
            raise ValueError("at least one random episode is needed to build the model")
        if self.episodes < self.random_episodes:
            raise ValueError(f"episodes ({self.episodes}) must be >= random_episodes "
                             f"({self.random_episodes})")
        if self.policy_start_mixture_when not in ("always", "solved", "fragile"):
            raise ValueError(f"policy_start_mixture_when must be 'always', 'solved' or "
                             f"'fragile', got {self.policy_start_mixture_when!r}")
        if (isinstance(self.policy_fragile_gap, bool)
                or not isinstance(self.policy_fragile_gap, (int, float))
                or not self.policy_fragile_gap >= 0):
            raise ValueError(f"policy_fragile_gap must be a number >= 0, got "
                             f"{self.policy_fragile_gap!r}")
        for name in ("policy_start_mixture", "policy_flank_points", "policy_start_scale",
                     "policy_leave_repeat"):
            value = getattr(self, name)
            if value == 0:
                setattr(self, name, None)
            elif value is not None and (isinstance(value, bool)
                                        or not isinstance(value, (int, float)) or value < 0):
                raise ValueError(f"{name} must be a number >= 0 or None, got {value!r}")
        for name in ("policy_start_samples", "policy_restart_step"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name} must be a whole number >= 0, got {value!r}")
        if self.max_data == 0:
            self.max_data = None
        if self.max_data is not None and self.max_data < 2:
            raise ValueError(f"max_data must be at least 2 (or None), got {self.max_data}")

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
