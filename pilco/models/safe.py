"""Safe PILCO's policy search: a policy runs only when its predicted risk is below a threshold.

:func:`safe_policy_search` searches the agent's policy on the risk-penalised objective
(the agent's reward holds a :class:`pilco.constraints.ViolationPenalty` of weight ``mu``),
predicts the horizon's risk of the policy it found and:

- accepts it when the risk is at most ``threshold``, and lowers ``mu`` (×``lower_by``) when
  the risk is below ``far_below × threshold`` (the penalty need not weigh so much; a
  quarter of the threshold by default, as the paper's published script);
- otherwise raises ``mu`` (×``raise_by``) and searches again, up to ``attempts`` searches;
- after the last, puts back the policy it started from when that one meets the threshold
  (a policy that ran safely before), else leaves the last one in place; either way the
  result says the search found no safe policy (``safe`` False), and the caller must not run
  an unsafe one on the system.

The risk is that of the agent's own start distribution, by ``rule`` (``"independent"``,
Safe PILCO's, or the ``"union"`` bound; :func:`pilco.constraints.horizon_risk`).
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np

from ..constraints import (COMBINE, ViolationPenalty, horizon_risk, step_violations,
                           violated_states)
from ..snapshots import restore, snapshot
from ..validation import check_positive_float, check_positive_int

__all__ = ["SafeSearch", "predicted_step_risks", "predicted_risk", "risk_penalty",
           "sampled_risk", "safe_policy_search"]

logger = logging.getLogger(__name__)


@dataclasses.dataclass
class SafeSearch:
    """What :func:`safe_policy_search` did.

    ``safe``: the policy in place meets the threshold; ``risk``: its predicted risk;
    ``fallback``: the policy in place is the one the search started from (the searched ones
    were all above the threshold); ``weight``: ``mu`` after the search; ``tries``: per
    search, ``{"weight", "risk", "expected_return"}``.
    """

    safe: bool
    risk: float
    fallback: bool
    weight: float
    tries: List[Dict[str, float]]

    def as_record(self) -> Dict[str, Any]:
        """JSON-ready, for an episode's record."""
        return dataclasses.asdict(self)


def predicted_step_risks(agent, constraint) -> np.ndarray:
    """The predicted probability that the agent's policy violates ``constraint`` at each
    step 1..H of its horizon, from its start distribution (of
    :meth:`~pilco.models.PILCO.predict_trajectory`), ``[H]``."""
    M, S = agent.predict_trajectory()
    return step_violations(constraint, M, S)[1:]


def predicted_risk(agent, constraint, rule: str = "independent") -> float:
    """The predicted probability that the agent's policy violates ``constraint`` at some
    step of its horizon (:func:`predicted_step_risks` combined by ``rule``)."""
    return float(horizon_risk(predicted_step_risks(agent, constraint), rule))


def sampled_risk(agent, constraint, samples: int = 1000, seed: int = 0,
                 horizon: Optional[int] = None) -> Tuple[float, float]:
    """The share of ``samples`` trajectories drawn through the agent's model that violate
    ``constraint`` at some step 1..H (``horizon``, default the agent's), and its standard
    error: each starts from the start distribution ``N(m_init, S_init)`` (the first
    task's), takes the policy's action at each sampled state and moves by a draw of the
    dynamics GPs' predictive distribution there (:meth:`~pilco.models.PILCO.one_step_prediction`:
    mean plus standard deviation times a standard normal, independent per step and
    output). What the moment-matched :func:`predicted_risk` approximates, up to the
    per-step independence of the draws."""
    samples = check_positive_int(samples, "samples")
    H = agent.horizon if horizon is None else check_positive_int(horizon, "horizon")
    rng = np.random.default_rng(seed)
    m = np.asarray(agent.m_init, dtype=np.float64)[0]
    S = np.asarray(agent.S_init, dtype=np.float64)
    S = S[0] if S.ndim == 3 else S
    vals, vecs = np.linalg.eigh(0.5 * (S + S.T))
    x = m + rng.standard_normal((samples, len(m))) @ (vecs * np.sqrt(np.clip(vals, 0, None))).T
    hit = np.zeros(samples, dtype=bool)
    for _ in range(H):
        u = agent.compute_action(x)
        mean, var = agent.one_step_prediction(np.hstack([x, u]))
        x = x + mean + np.sqrt(np.clip(var, 0.0, None)) * rng.standard_normal(x.shape)
        hit |= violated_states(constraint, x)
    share = float(hit.mean())
    return share, float(np.sqrt(max(share * (1.0 - share), 1e-12) / samples))


def risk_penalty(reward) -> ViolationPenalty:
    """The one :class:`~pilco.constraints.ViolationPenalty` of an agent's reward (itself,
    or one term of a :class:`~pilco.rewards.CombinedRewards`); ValueError otherwise."""
    if isinstance(reward, ViolationPenalty):
        return reward
    found = [p for r in getattr(reward, "base_rewards", ())
             for p in ([r] if isinstance(r, ViolationPenalty) else [])]
    if len(found) != 1:
        raise ValueError("the agent's reward must hold one ViolationPenalty (e.g. "
                         "CombinedRewards(D, [task_reward, ViolationPenalty(constraint, mu)]))"
                         f"; found {len(found)}")
    return found[0]


def safe_policy_search(agent, threshold: float, *, attempts: int = 3, raise_by: float = 1.5,
                       lower_by: float = 0.75, far_below: float = 0.25,
                       rule: str = "independent", search: Optional[Callable[[], float]] = None,
                       searched: Optional[float] = None,
                       start: Optional[Tuple[Dict[str, np.ndarray], float]] = None,
                       repair_weight: Optional[float] = None,
                       **optimize: Any) -> SafeSearch:
    """Search the agent's policy until its predicted risk is at most ``threshold`` (module
    docstring); returns a :class:`SafeSearch`.

    ``search``: one policy search, ``() -> expected return`` (default
    :meth:`~pilco.models.PILCO.optimize_policy` with the keyword arguments ``optimize``).
    ``searched``: the expected return of a search that already ran (a run loop's own): the
    policy in place is checked first and counts as the first of ``attempts``; ``start``
    is then ``(pilco.snapshots.snapshot of the controller, predicted risk)`` of the policy
    that search started from (the fallback), else the policy in place when called is the
    start. ``repair_weight``: when every search and the start policy are above the
    threshold, one more search from the start policy with ``mu`` at this weight (the
    searched policies may lie where leaving is certain and the risk has no slope; near
    the start, which met the threshold under the model before, it has one); its policy
    runs if it meets the threshold (``fallback`` True)."""
    threshold = check_positive_float(threshold, "threshold")
    if threshold >= 1.0:
        raise ValueError(f"threshold must be below 1 (a probability), got {threshold}")
    attempts = check_positive_int(attempts, "attempts")
    raise_by = check_positive_float(raise_by, "raise_by")
    lower_by = check_positive_float(lower_by, "lower_by")
    far_below = check_positive_float(far_below, "far_below")
    if raise_by <= 1.0 or lower_by >= 1.0 or far_below >= 1.0:
        raise ValueError("raise_by must be above 1, lower_by and far_below below 1")
    if rule not in COMBINE:
        raise ValueError(f"rule must be one of {COMBINE}, got {rule!r}")
    if searched is None and start is not None:
        raise ValueError("start is the policy a search already run started from: give "
                         "searched (its expected return) with it")
    if repair_weight is not None:
        repair_weight = check_positive_float(repair_weight, "repair_weight")
    penalty = risk_penalty(agent.reward)
    constraint = penalty.constraint
    if start is None:
        start = (snapshot(agent.controller), predicted_risk(agent, constraint, rule))
    if search is None:
        def search() -> float:
            return agent.optimize_policy(**optimize)
    tries: List[Dict[str, float]] = []
    for attempt in range(attempts):
        weight = float(penalty.weight.numpy())
        value = float(searched) if attempt == 0 and searched is not None else search()
        risk = predicted_risk(agent, constraint, rule)
        tries.append({"weight": weight, "risk": risk, "expected_return": float(value)})
        if risk <= threshold:
            if risk < far_below * threshold:
                penalty.weight.assign(weight * lower_by)
            return SafeSearch(True, risk, False, float(penalty.weight.numpy()), tries)
        logger.info("policy predicted to violate the constraint with probability %.3g > "
                    "%.3g: mu %.3g -> %.3g%s", risk, threshold, weight, weight * raise_by,
                    ", searched again" if attempt + 1 < attempts else "")
        penalty.weight.assign(weight * raise_by)
    params, start_risk = start
    if start_risk > threshold and repair_weight is not None:
        restore(agent.controller, params)
        raised = float(penalty.weight.numpy())
        penalty.weight.assign(repair_weight)
        value = search()
        penalty.weight.assign(raised)  # mu stays as the unsafe searches left it
        risk = predicted_risk(agent, constraint, rule)
        tries.append({"weight": repair_weight, "risk": risk,
                      "expected_return": float(value), "from_start": True})
        if risk <= threshold:
            logger.warning("no policy below the risk threshold %.3g in %d searches; one "
                           "more from the policy the search started from: risk %.3g, run",
                           threshold, attempts, risk)
            return SafeSearch(True, risk, True, float(penalty.weight.numpy()), tries)
    if start_risk <= threshold:
        restore(agent.controller, params)
        logger.warning("no policy below the risk threshold %.3g in %d searches: the policy "
                       "the search started from (risk %.3g) is kept", threshold, attempts,
                       start_risk)
        return SafeSearch(True, start_risk, True, float(penalty.weight.numpy()), tries)
    logger.warning("no policy below the risk threshold %.3g in %d searches, and the one the "
                   "search started from is above it too (risk %.3g): do not run it",
                   threshold, attempts, start_risk)
    return SafeSearch(False, float(tries[-1]["risk"]), False, float(penalty.weight.numpy()),
                      tries)

