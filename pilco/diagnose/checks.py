"""The measurements of a learned episode: what the diagnosis knows before it judges.

Model
    - one step (:func:`one_step_check`): the predicted state change ``x_{t+1} - x_t`` at
      every real transition of the episode against the real one, standardised per state
      dimension (``z = (Δ - mean) / std``, the noise variance included). *Coverage* is the
      fraction of ``|z| <= 2`` (0.95 for a calibrated Gaussian), over all dimensions and
      over those the cost reads.
    - open loop (:func:`open_loop_check`): the episode's own actions applied to the
      model's mean from the real start; the error is the distance between the model's and
      the real point the cost measures (the gripper), per step.
    - multi-step (:func:`multi_step_check`): the task distance predicted from the start
      distribution under the episode's policy (mean and std per step, from samples of the
      moment-matched state Gaussians) against the real distance trace, and the predicted
      against the real cost per step.
Optimiser
    (:func:`optimiser_check`) the policy objective of the same model (the predicted cost
    summed over the planning horizon: what the policy optimiser minimises) of the run's
    policy, against ``restarts`` policy optimisations started from
    ``controller.randomize`` and one that continues from the run's policy, each one search
    (no restarts) with the run's settings for the episode (iterations, method, early
    stop). Each candidate policy
    is also run on the real system from the episode's start when an environment is given.
Objective
    (:func:`objective_check`) the slope of the saturating cost ``1 - exp(-d² / 2σ_c²)`` at
    the start distance d0, relative to its maximum (at d = σ_c):
    ``(d0/σ_c) exp((1 - d0²/σ_c²) / 2)``.

Every check takes the agent as it was when the episode ran (:mod:`pilco.diagnose.replay`)
and returns a JSON-ready dict; the distances are those of the cost's geometry
(:mod:`pilco.diagnose.geometry`).
"""
from __future__ import annotations

import contextlib
import logging
import time
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np

from ..experiment.episode import Episode, rollout
from ..experiment.learning import improve_policy
from ..experiment.scoring import episode_solved
from ..snapshots import restore, snapshot
from .geometry import CostGeometry, distance_moments, slope_ratio
from .thresholds import Thresholds

__all__ = ["one_step_check", "mean_dynamics", "open_loop_check", "predicted_run",
           "multi_step_check", "objective_check", "optimiser_check"]

logger = logging.getLogger(__name__)


def _cost_of_states(agent, geometry: CostGeometry, states: np.ndarray) -> np.ndarray:
    """The cost ``max_reward - reward(x)`` at known states [T, D] -> [T]."""
    zero = np.zeros((agent.state_dim, agent.state_dim))
    return np.array([geometry.max_reward - float(np.asarray(
        agent.reward.compute_reward(x[None], zero)[0])[0, 0]) for x in states])


def episode_task(agent, episode: Episode) -> Optional[int]:
    """The start distribution (task) of a multi-task agent that ``episode`` ran from: the
    one whose mean is closest to the episode's first state (its context, a target, is
    the task's); None for an agent with one start distribution."""
    if getattr(agent, "num_tasks", 1) <= 1:
        return None
    gaps = np.linalg.norm(np.asarray(agent.m_init) - np.asarray(episode.states[0])[None],
                          axis=1)
    return int(np.argmin(gaps))


def one_step_check(agent, episode: Episode, geometry: Optional[CostGeometry],
                   thresholds: Thresholds) -> Dict[str, Any]:
    """The model's one-step predictions along the real episode (see the module doc).
    Context dimensions (never predicted: change and variance 0) count as within and are
    left out of the overall coverage."""
    X, Y = episode.transitions()
    mean, var = agent.one_step_prediction(X)
    context = set(getattr(agent, "context_indices", ()))
    predicted = [d for d in range(Y.shape[1]) if d not in context]
    sd = np.sqrt(var)
    z = np.divide(Y - mean, sd, out=np.zeros_like(Y), where=sd > 0)
    within = np.abs(z) <= thresholds.z
    dims = list(geometry.dims) if geometry is not None else []
    per_dim = within.mean(axis=0)
    rms_change = np.sqrt(np.mean(Y ** 2, axis=0))
    # steps where a dimension did not move although the model predicts it moves (a limit or
    # a saturation the model does not know)
    still = (np.abs(Y) <= 1e-9 + 1e-6 * rms_change) & (np.abs(mean) > thresholds.z * np.sqrt(var))
    outside = ~within
    return {
        "coverage": float(within[:, predicted].mean()),
        "coverage_cost_dims": float(within[:, dims].mean()) if dims else None,
        "cost_dims": dims,
        "coverage_per_dim": per_dim,
        "worst_dim": int(np.argmin(per_dim)), "worst_dim_coverage": float(np.min(per_dim)),
        "first_outside_per_dim": [int(np.argmax(o)) if o.any() else None for o in outside.T],
        "still_but_predicted_moving_per_dim": still.sum(axis=0),
        "wrong": thresholds.one_step_wrong(float(within.mean()), float(np.min(per_dim))),
        "rms_z_per_dim": np.sqrt(np.mean(z ** 2, axis=0)),
        "rmse_per_dim": np.sqrt(np.mean((Y - mean) ** 2, axis=0)),
        "rms_change_per_dim": rms_change,
        "predicted_std_per_dim": np.sqrt(np.mean(var, axis=0)),
    }


def mean_dynamics(agent) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``(x [D], u [U]) -> x + mean predicted change``: the dynamics model's mean as a
    NumPy function (one factorisation, then a kernel row per call)."""
    f = agent.mgpr.factorize()
    C, B, ell, sf2 = (np.asarray(v, dtype=np.float64)
                      for v in (f.centers, f.beta, f.lengthscales, f.variance))

    def step(x, u):
        z = agent.gp_inputs(np.concatenate([x, u])[None])[0]
        k = sf2[:, None] * np.exp(-0.5 * np.sum(((z - C)[None] / ell[:, None, :]) ** 2, -1))
        return x + np.sum(k * B, axis=1)

    return step


def open_loop_check(agent, episode: Episode, geometry: Optional[CostGeometry],
                    threshold: float) -> Dict[str, Any]:
    """The episode's own actions applied to the model's mean from the episode's real start:
    how far the model's trajectory drifts from the real one (no policy, no uncertainty).

    ``error``: per step, the distance between the model's and the real point the cost
    measures; ``wrong``: at the step of the real closest approach the error exceeds
    ``threshold`` (the task's success distance: the model cannot tell reaching from
    missing there).
    """
    if geometry is None or episode.steps == 0:
        return {"wrong": None}
    step = mean_dynamics(agent)
    xs = [np.asarray(episode.states[0], dtype=np.float64)]
    for u in episode.actions:
        xs.append(step(xs[-1], u))
    xs = np.array(xs)
    error = np.linalg.norm(geometry.offset(xs) - geometry.offset(episode.states), axis=1)
    closest = int(np.argmin(episode.distances[1:])) + 1
    above = np.nonzero(error > threshold)[0]
    return {"distance": geometry.distance(xs), "error": error, "closest_step": closest,
            "error_at_closest": float(error[closest]), "max_error": float(error.max()),
            "first_step_above_threshold": int(above[0]) if len(above) else None,
            "threshold": float(threshold), "wrong": bool(error[closest] > threshold)}


def predicted_run(agent, steps: int, geometry: Optional[CostGeometry],
                  task: Optional[int] = None) -> Dict[str, Any]:
    """The multi-step prediction of ``steps`` steps from the start distribution (of
    ``task``, for a multi-task agent) under the agent's policy: predicted cost per step
    and, with a geometry, distance mean and std."""
    M, S, R, _ = (np.asarray(v) for v in
                  agent.predict_trajectory_with_rewards(horizon=steps, task=task))
    out: Dict[str, Any] = {"reward": R}
    if geometry is not None:
        out["cost"] = geometry.max_reward - R
        out["distance_mean"], out["distance_std"] = distance_moments(geometry, M, S)
    return out


def multi_step_check(exp, agent, episode: Episode, geometry: Optional[CostGeometry],
                     thresholds: Thresholds) -> Dict[str, Any]:
    """Predicted distance and cost per step against the real episode's."""
    steps = exp.config.horizon
    pred = predicted_run(agent, steps, geometry, episode_task(agent, episode))
    real_d = np.asarray(episode.distances, dtype=np.float64)
    out: Dict[str, Any] = {"steps": steps, "real_distance": real_d}
    if geometry is None:
        return out
    n = min(len(real_d), steps + 1)  # a real episode may stop early at the target
    pm, ps = pred["distance_mean"], pred["distance_std"]
    inside = np.abs(real_d[1:n] - pm[1:n]) <= thresholds.z * ps[1:n]
    real_cost = _cost_of_states(agent, geometry, episode.states)
    last = n - 1
    solved = episode_solved(Episode(states=np.zeros((steps + 1, 0)),
                                    actions=np.zeros((steps, 0)), rewards=np.zeros(steps),
                                    distances=pm), exp.config)
    out.update({
        "pred_distance_mean": pm, "pred_distance_std": ps,
        "pred_cost": pred["cost"], "real_cost": real_cost,
        "coverage": float(inside.mean()) if len(inside) else None,
        "pred_final_distance": float(pm[last]), "pred_final_std": float(ps[last]),
        "real_final_distance": float(real_d[last]),
        "final_inside": bool(abs(real_d[last] - pm[last]) <= thresholds.z * ps[last]),
        "pred_min_distance": float(np.min(pm[1:])), "real_min_distance": float(np.min(real_d[1:n])),
        # a prediction runs every step: whether the env would have ended the episode (a
        # rule of surviving so many steps) is not something the model predicts
        "pred_solved": None if exp.config.solved_rule == "survive" else bool(solved),
        "pred_cost_sum": float(np.sum(pred["cost"][1:n])),
        "real_cost_sum": float(np.sum(real_cost[1:n])),
    })
    out["optimism"] = out["real_cost_sum"] - out["pred_cost_sum"]
    return out


def objective_check(agent, episode: Episode, geometry: Optional[CostGeometry],
                    thresholds: Thresholds) -> Dict[str, Any]:
    """The saturating cost's slope at the start distance (the objective's start
    distribution's mean) relative to its maximum."""
    if geometry is None:
        return {"cost_width": None, "start_distance": None, "start_widths": None,
                "slope_ratio": None, "flat": None}
    d0 = float(geometry.distance(np.asarray(agent.m_init))[0])
    widths = d0 / geometry.width
    return {"cost_width": geometry.width, "start_distance": d0,
            "real_start_distance": float(episode.distances[0]), "start_widths": widths,
            "slope_ratio": slope_ratio(widths),
            "flat_slope_ratio": slope_ratio(thresholds.flat_widths),
            "flat": bool(widths > thresholds.flat_widths)}


def _on_system(view, number: int, env, seed: int) -> Episode:
    """Episode ``number``'s setting (its reset options) run on the real system ``env`` with
    the agent's current policy from the start of ``seed``."""
    agent = view.agent
    return rollout(env, lambda x: agent.compute_action(x)[0], view.config.horizon, seed=seed,
                   distance_fn=view.hooks.distance, quiet=True,
                   reset_options=view.hooks.reset_options(number))


def _max_cost(agent, geometry: Optional[CostGeometry]) -> float:
    """The horizon's largest predicted cost: its steps times the reward at the target."""
    return agent.horizon * (geometry.max_reward if geometry is not None else 1.0)


def _candidate(view, number: int, geometry: Optional[CostGeometry], kind: str,
               seed: Optional[int], env, seconds: float = 0.0,
               task: Optional[int] = None) -> Dict[str, Any]:
    """Predicted cost (the policy objective) and, with ``env``, the real outcome of the
    agent's current policy."""
    agent, cfg = view.agent, view.config
    out: Dict[str, Any] = {"start": kind, "seed": seed, "seconds": seconds,
                           "pred_cost": _max_cost(agent, geometry) - agent.expected_return()}
    if geometry is not None:
        pred = predicted_run(agent, cfg.horizon, geometry, task)
        out["pred_final_distance"] = float(pred["distance_mean"][-1])
        out["pred_min_distance"] = float(np.min(pred["distance_mean"][1:]))
    if env is not None:
        ep = _on_system(view, number, env, view.episode_seed(number))
        out["real_distance"] = ep.distances
        out["real_final_distance"] = float(ep.distances[-1])
        out["real_min_distance"] = float(np.min(ep.distances[1:])) if ep.steps else None
        out["real_solved"] = bool(view.episode_solved(ep))
    return out


def optimiser_check(view, number: int, geometry: Optional[CostGeometry], restarts: int,
                    seed: int, env, thresholds: Thresholds,
                    task: Optional[int] = None) -> Dict[str, Any]:
    """The run's policy against ``restarts`` re-optimisations from random policies and one
    continuing from the run's policy, all on the same model with the run's settings
    (``task``: the start distribution the episode ran from, for a multi-task agent)."""
    agent, cfg = view.agent, view.config
    iters = cfg.policy_iterations(number)
    run_policy = snapshot(agent.controller)
    candidates = [_candidate(view, number, geometry, "run", None, env, task=task)]
    starts: List[Tuple[str, Optional[int]]] = [("continued", None)]
    if restarts and callable(getattr(agent.controller, "randomize", None)):
        seeds = np.random.default_rng([int(seed), int(cfg.seed), number]).integers(
            2 ** 31, size=restarts)
        starts += [("random", int(s)) for s in seeds]
    elif restarts:
        logger.warning("%s has no randomize(): no restarts", type(agent.controller).__name__)
    try:
        for i, (kind, s) in enumerate(starts, start=1):
            restore(agent.controller, run_policy)
            if kind == "random":
                agent.controller.randomize(seed=s)
            logger.info("optimiser check %d/%d: %s policy, %d iterations (%s)", i, len(starts),
                        "the run's" if kind == "continued" else f"random (seed {s})", iters,
                        cfg.policy_optimizer)
            t0 = time.perf_counter()
            # one search per candidate: the run's restarts would draw the same further
            # starts for every candidate, and the best of them would hide the candidate's
            improve_policy(view, number, runs=1)
            candidates.append(_candidate(view, number, geometry, kind, s, env,
                                         time.perf_counter() - t0, task))
            logger.info("optimiser check %d/%d: predicted cost %.3f (run's %.3f) in %.1f s", i,
                        len(starts), candidates[-1]["pred_cost"], candidates[0]["pred_cost"],
                        candidates[-1]["seconds"])
    finally:
        restore(agent.controller, run_policy)
    run_cost = candidates[0]["pred_cost"]
    others = candidates[1:]
    best = min(others, key=lambda c: c["pred_cost"]) if others else None
    gain = run_cost - best["pred_cost"] if best else None
    needed = thresholds.gain_needed(run_cost)
    better = [c for c in others if run_cost - c["pred_cost"] >= needed]
    solves = (any(c["real_solved"] for c in better)
              if better and all("real_solved" in c for c in better) else None)
    return {"iterations": iters, "method": cfg.policy_optimizer, "horizon": agent.horizon,
            "max_cost": _max_cost(agent, geometry),
            "candidates": candidates, "run_pred_cost": run_cost,
            "best": others.index(best) + 1 if best else None,
            "best_pred_cost": best["pred_cost"] if best else None, "gain": gain,
            "gain_needed": needed, "better_exists": bool(better),
            "better_solves_real": solves}


@contextlib.contextmanager
def _objective(agent, **settings):
    """Set those of the agent's objective ``settings`` (``start_spread``, ``start_points``,
    ``start_scale``) it has, and put the previous values back on the way out."""
    before = {name: getattr(agent, name) for name in settings if hasattr(agent, name)}
    try:
        for name in before:
            setattr(agent, name, settings[name])
        yield
    finally:
        for name, value in before.items():
            setattr(agent, name, value)


def start_check(view, number: int, env, starts: int, spread: float = 1.5) -> Dict[str, Any]:
    """How the episode's policy fares from the whole start distribution: run on the real
    system from ``starts`` fresh start states (seeds drawn from the run's seed and the
    episode), the fraction that meets the task's rule; and the policy objective's expected
    return from the start distribution as one Gaussian (``plain_return``) against its
    start mixture of ``spread`` (at most sqrt(D); ``mixture_return``,
    :attr:`pilco.models.PILCO.start_spread`;
    None for an agent without one). A policy that meets the rule from the episode's own
    start but from few of the others, with a mixture return well below the plain one, is
    fragile: the one-Gaussian objective averaged its failing flanks away."""
    agent, cfg = view.agent, view.config
    # at most sqrt(D) standard deviations out: the mixture needs spread < sqrt(D + 1/2)
    spread = min(float(spread), float(np.sqrt(agent.state_dim)))
    # the plain objective: without the start points and wide start the run's search had
    with _objective(agent, start_points=None, start_scale=None):
        out: Dict[str, Any] = {"starts": int(starts), "solved": None,
                               "solved_fraction": None,
                               "plain_return": float(agent.expected_return()),
                               "mixture_return": None, "spread": float(spread)}
        if hasattr(agent, "start_spread"):
            with _objective(agent, start_spread=spread):
                out["mixture_return"] = float(agent.expected_return())
    if env is None or starts <= 0:
        return out
    seeds = np.random.default_rng([int(cfg.seed), number, 7]).integers(2 ** 31, size=starts)
    solved = [bool(view.episode_solved(_on_system(view, number, env, int(s)))) for s in seeds]
    out["solved"] = int(sum(solved))
    out["solved_fraction"] = float(np.mean(solved))
    return out
