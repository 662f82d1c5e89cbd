"""Safe PILCO's loop: a learned policy runs on the system only when its predicted risk of
violating a state constraint is below a threshold.

:class:`SafeRun` is a :class:`~pilco.experiment.hooks.RunHooks` mixin. The agent's
reward holds a :class:`pilco.constraints.ViolationPenalty` of weight ``mu`` beside the
task's reward, so each policy search maximises the return minus ``mu`` times the risk.
After the loop's policy search of every learned episode (``after_policy_search``) the
policy's risk over the horizon is predicted; above the threshold ``mu`` is raised and the
search repeated, at most ``attempts`` searches in all, after which the run keeps the policy
of the episode before when it meets the threshold under the new model
(:func:`pilco.models.safe.safe_policy_search`). With ``first_search="plain"`` the loop's
own search of each episode maximises the return alone (the penalty's weight is 0 during
it), and ``mu`` weighs the risk only in the searches after a policy predicted above the
threshold, continuing from the unsafe policy, and when none gets below it nor does the
policy the episode started from, once more from that policy with the episode's first
``mu`` (the searched policies may lie where leaving is certain and the risk has no
slope): a risk that is already low then does not steer the learning (a penalty present
in every search made the cart-pole swing the pole up with less cart travel, a motion it
learned episodes later than without the penalty, if at all). When no policy meets it, the
episode does
**not** run the policy: it runs :attr:`Safety.safe_action` at every step (``watch``): a
constant action, or a fixed controller of the state (e.g. one that brakes a cart to the
middle of its track, where "no force" lets it roll on), and its record says so. Every
learned episode's record holds ``safety`` (the predicted risk, ``mu``, the searches,
``executed``, ``fallback``), and every episode's record ``violated`` (some real state
broke the constraint) and ``violation_steps``; the summary's ``safety`` counts them.
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Any, Callable, Dict, Optional, Sequence, Union

import numpy as np

from ..constraints import COMBINE, horizon_risk, violated_states
from ..models.safe import (predicted_risk, predicted_step_risks, risk_penalty,
                           safe_policy_search)
from ..snapshots import snapshot
from .hooks import RunHooks
from .learning import search_policy

__all__ = ["Safety", "SafeRun", "RecordsViolations", "safety_counts"]

logger = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class Safety:
    """What :class:`SafeRun` keeps: ``constraint`` (a :mod:`pilco.constraints` object on
    the raw state, the one the agent's ``ViolationPenalty`` holds), the ``threshold`` on
    the predicted risk over the horizon (combined by ``rule``: ``"independent"``, Safe
    PILCO's ``1 - Π(1 - p_t)``, or the ``"union"`` bound), at most ``attempts`` searches
    per episode, ``mu`` raised by ``raise_by`` above the threshold and lowered by
    ``lower_by`` below ``far_below`` times it, and ``safe_action``, what an episode runs
    when no policy is predicted safe: a constant action [U] (e.g. braking), or a
    controller ``x [D] -> u [U]`` of the observed state that is known to keep the system
    inside the constraint (:meth:`action_at`). ``first_search``: ``"penalised"`` (Safe
    PILCO's: every search on the return minus ``mu`` times the risk) or ``"plain"`` (the
    episode's first search on the return alone, the penalty in the searches after an
    unsafe policy only)."""

    constraint: Any
    threshold: float
    safe_action: Union[Sequence[float], Callable[[np.ndarray], Any]]
    attempts: int = 3
    rule: str = "independent"
    raise_by: float = 1.5
    lower_by: float = 0.75
    far_below: float = 0.25
    first_search: str = "penalised"

    def __post_init__(self):
        if not 0.0 < float(self.threshold) < 1.0:
            raise ValueError(f"threshold must be a probability in (0, 1), got {self.threshold}")
        if self.rule not in COMBINE:
            raise ValueError(f"rule must be one of {COMBINE}, got {self.rule!r}")
        if int(self.attempts) < 1:
            raise ValueError(f"attempts must be at least 1, got {self.attempts}")
        if self.first_search not in ("penalised", "plain"):
            raise ValueError(f"first_search must be 'penalised' or 'plain', got "
                             f"{self.first_search!r}")
        if callable(self.safe_action):
            return
        action = np.asarray(self.safe_action, dtype=np.float64).reshape(-1)
        if action.size == 0 or not np.all(np.isfinite(action)):
            raise ValueError(f"safe_action must be finite numbers, one per action, or a "
                             f"controller x -> u, got {self.safe_action!r}")

    def action_at(self, x: np.ndarray) -> np.ndarray:
        """The safe action at the observed state ``x`` [D]: [U], float64."""
        if callable(self.safe_action):
            action = np.asarray(self.safe_action(np.asarray(x, dtype=np.float64)),
                                dtype=np.float64).reshape(-1)
            if not np.all(np.isfinite(action)):
                raise ValueError(f"the safe action's controller returned {action} at {x}")
            return action
        return np.asarray(self.safe_action, dtype=np.float64).reshape(-1).copy()

    def describe(self) -> str:
        """The safe action in words, for logs."""
        if callable(self.safe_action):
            return repr(self.safe_action)
        return str(list(np.asarray(self.safe_action, dtype=np.float64).reshape(-1)))


class RecordsViolations(RunHooks):
    """A RunHooks mixin that records, after every episode, whether its real states broke
    :attr:`constraint` (the records' ``violated`` and ``violation_steps``; the summary's
    ``safety`` counts, :func:`safety_counts`), and before every learned episode the
    predicted risk of its policy under both combination rules (the record's
    ``predicted_risk``, ``{"independent": p, "union": q}``): the measurement of a run
    without Safe PILCO's loop beside one with it, and what a calibration of the predicted
    risk against real violations reads."""

    constraint: Any

    def watch(self, run, number: int, policy):
        policy = super().watch(run, number, policy)
        p = predicted_step_risks(run.agent, self.constraint)  # one prediction, both rules
        run.policy_notes["predicted_risk"] = {rule: float(horizon_risk(p, rule))
                                              for rule in COMBINE}
        return policy

    def after_episode(self, run, number: int) -> None:
        super().after_episode(run, number)
        violated = violated_states(self.constraint, run.episodes[-1].states)
        record = run.records[-1]
        record["violated"] = bool(violated.any())
        record["violation_steps"] = int(violated.sum())
        run.summary_fields["safety"] = safety_counts(run.records)
        run.save_progress()


class SafeRun(RecordsViolations):
    """Safe PILCO's episode rule for hooks with a :attr:`safety` (module docstring)."""

    safety: Safety

    #: the policy the episode's search started from and its predicted risk
    _start: Optional[tuple] = None
    #: the risk's weight the episode began with, kept while a plain first search runs
    _weight: Optional[float] = None

    @property
    def constraint(self):
        """The constraint of :attr:`safety` (what :class:`RecordsViolations` checks)."""
        return self.safety.constraint

    def before_policy_search(self, run, number: int) -> None:
        super().before_policy_search(run, number)
        agent = run.agent
        self._start = (snapshot(agent.controller),
                       predicted_risk(agent, self.constraint, self.safety.rule))
        if self.safety.first_search == "plain":
            penalty = risk_penalty(agent.reward)
            self._weight = float(penalty.weight.numpy())
            penalty.weight.assign(0.0)

    def after_policy_search(self, run, number: int, expected: float) -> None:
        super().after_policy_search(run, number, expected)
        safety, agent = self.safety, run.agent
        # a plain search is over: mu weighs the risk again, and a last repair from the
        # episode's first policy (plain only) uses the weight the episode began with
        repair_weight, self._weight = self._weight, None
        if repair_weight is not None:
            risk_penalty(agent.reward).weight.assign(repair_weight)
        extra = {"evaluations": 0}

        def search() -> float:  # each further search adds the one before's evaluations
            extra["evaluations"] += int(getattr(agent, "policy_evaluations", 0) or 0)
            return search_policy(run, number, "policy (safe)")

        result = safe_policy_search(
            agent, safety.threshold, attempts=safety.attempts, raise_by=safety.raise_by,
            lower_by=safety.lower_by, far_below=safety.far_below, rule=safety.rule,
            search=search, searched=expected, start=self._start,
            repair_weight=repair_weight)
        if safety.first_search == "plain":
            result.tries[0]["weight"] = 0.0  # the loop's own search weighed no risk
        notes = run.policy_notes
        notes["safety"] = dict(result.as_record(), executed=bool(result.safe),
                               threshold=float(safety.threshold))
        notes["extra_evaluations"] = notes.get("extra_evaluations", 0) + extra["evaluations"]
        if not result.safe:
            logger.warning("episode %d: no policy predicted safe (risk %.3g > %.3g): the "
                           "episode runs the safe action (%s)", number, result.risk,
                           safety.threshold, safety.describe())

    def watch(self, run, number: int, policy):
        policy = super().watch(run, number, policy)
        if run.policy_notes.get("safety", {}).get("executed", True):
            return policy
        return self.safety.action_at


def safety_counts(records) -> Dict[str, Any]:
    """The run's safety in numbers: learned episodes, those whose policy ran
    (``executed``), the executed ones that violated the constraint, the random ones that
    did, and the predicted risks of the executed ones."""
    learned = [r for r in records if not r["random"]]
    executed = [r for r in learned if r.get("safety", {}).get("executed", True)]
    return {"learned": len(learned), "executed": len(executed),
            "executed_violated": sum(bool(r.get("violated")) for r in executed),
            "random_violated": sum(bool(r.get("violated")) for r in records if r["random"]),
            "executed_risks": [r["safety"]["risk"] for r in executed if "safety" in r]}
