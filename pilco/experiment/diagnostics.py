"""Measurements of a learned episode for :mod:`pilco.experiment.diagnose`: the task
distance a saturating cost measures, the model's one-step and multi-step predictions
against the real episode, the objective's slope at the start, and the policy objective of
re-optimised policies on the same model."""
from __future__ import annotations

import dataclasses
import logging
import time
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np

from ..snapshots import restore, snapshot
from .episode import Episode, rollout
from .learning import improve_policy

__all__ = ["Thresholds", "slope_ratio", "CostGeometry", "cost_geometry", "distance_moments",
           "one_step_check", "mean_dynamics", "open_loop_check", "predicted_run",
           "multi_step_check", "objective_check", "optimiser_check"]

logger = logging.getLogger(__name__)


def slope_ratio(widths: float) -> float:
    """Slope of ``1 - exp(-d² / 2σ²)`` at ``d = widths · σ`` over its maximum (at d = σ)."""
    r = float(widths)
    return r * float(np.exp((1.0 - r * r) / 2.0))


@dataclasses.dataclass(frozen=True)
class Thresholds:
    """The numbers of the verdict rules (see the module docstring)."""

    #: a real value is "within the prediction" if within this many predicted std
    z: float = 2.0
    #: the model is wrong one step ahead if fewer one-step errors than this fraction are
    #: within ``z`` std (0.95 for a calibrated Gaussian) ...
    coverage: float = 0.90
    #: ... or fewer than this fraction in some state dimension (one mispredicted dimension,
    #: e.g. a joint held at its limit, is diluted in the overall fraction)
    coverage_dim: float = 0.70
    #: a candidate is clearly better if it lowers the predicted cost by at least
    #: ``max(gain_abs, gain_rel * run's predicted cost)``
    gain_abs: float = 1.0
    gain_rel: float = 0.10
    #: the cost is flat at start distances beyond this many cost widths
    flat_widths: float = 3.0

    def gain_needed(self, run_cost: float) -> float:
        """The predicted-cost decrease that counts as clearly better than ``run_cost``
        (also the clear margin of a real cost above its prediction)."""
        return max(self.gain_abs, self.gain_rel * abs(float(run_cost)))

    def one_step_wrong(self, coverage: float, worst_dim_coverage: float) -> bool:
        """Whether one-step coverages say the model is wrong along the real episode."""
        return coverage < self.coverage or worst_dim_coverage < self.coverage_dim


# -- the cost's geometry --------------------------------------------------------------------
@dataclasses.dataclass
class CostGeometry:
    """Where a saturating reward puts the target, in task units.

    ``offset(states [N, D]) -> [N, k]``: the vector from the target to the point the
    reward measures (the gripper, the pendulum tip), in the state's units when the reward's
    weight matrix is isotropic on the dimensions it reads (``width`` is then σ_c in those
    units), else in cost widths (``width`` 1); :meth:`distance` is its length. ``dims``: the
    state dimensions the reward reads; ``max_reward``: the reward at the target (cost =
    max_reward - reward).
    """

    width: float
    dims: Tuple[int, ...]
    offset: Callable[[np.ndarray], np.ndarray]
    max_reward: float = 1.0

    def distance(self, X) -> np.ndarray:
        """Task distance of states [N, D] -> [N]."""
        return np.linalg.norm(self.offset(X), axis=1)


def cost_geometry(reward) -> Optional[CostGeometry]:
    """The :class:`CostGeometry` of ``ExponentialReward``, ``CartPoleReward`` and
    ``CombinedRewards`` of them (the widest positively weighted part's; parts with a
    negative weight are penalties and left out); None for other rewards."""
    from ..rewards import CartPoleReward, CombinedRewards, ExponentialReward

    if isinstance(reward, ExponentialReward):
        W, t = np.asarray(reward.W.numpy()), np.asarray(reward.t.numpy())[0]
        lam, V = np.linalg.eigh(0.5 * (W + W.T))
        keep = lam > 1e-12 * max(lam.max(), 1e-300)
        iso = keep.any() and np.allclose(lam[keep], lam[keep][0], rtol=1e-6)
        width = float(1.0 / np.sqrt(lam[keep][0])) if iso else 1.0
        L = V[:, keep] * np.sqrt(lam[keep])  # W = L L^T on its range

        def offset(X):
            return width * (np.asarray(X, dtype=np.float64) - t) @ L

        dims = tuple(int(i) for i in np.nonzero(np.any(W != 0, axis=1))[0])
        return CostGeometry(width, dims, offset)
    if isinstance(reward, CartPoleReward):
        length = float(reward.pendulum_length)

        def tip_offset(X):
            X = np.asarray(X, dtype=np.float64)
            # the tip at (x + l sin θ, -l cos θ), the target at (0, l)
            return np.stack([X[:, 0] + length * np.sin(X[:, 3]),
                             -length * (np.cos(X[:, 3]) + 1.0)], axis=1)

        return CostGeometry(float(reward.width), (0, 3), tip_offset)
    if isinstance(reward, CombinedRewards):
        # parts with a negative weight are penalties (e.g. joint-limit bumps), ~0 at the
        # target: the geometry and the best reward are those of the positive parts
        coefs = np.asarray(reward.coefs.numpy(), dtype=np.float64)
        parts = [(c, cost_geometry(r)) for c, r in zip(coefs, reward.base_rewards) if c > 0]
        if not parts or any(p is None for _, p in parts):
            return None
        widest = max((p for _, p in parts), key=lambda p: p.width)
        return dataclasses.replace(
            widest, max_reward=float(sum(c * p.max_reward for c, p in parts)))
    return None


def distance_moments(geometry: CostGeometry, M: np.ndarray, S: np.ndarray,
                     samples: int = 4000, seed: int = 0) -> Tuple[np.ndarray, np.ndarray]:
    """Mean and std [T] of the task distance under the Gaussians ``N(M[t], S[t])``
    (M [T, D], S [T, D, D]), from ``samples`` draws (the same normal draws at every step)."""
    z = np.random.default_rng(seed).standard_normal((samples, M.shape[1]))
    mean, std = np.empty(len(M)), np.empty(len(M))
    for i, (m, s) in enumerate(zip(M, S)):
        w, V = np.linalg.eigh(0.5 * (s + s.T))
        d = geometry.distance(m + (z * np.sqrt(np.clip(w, 0.0, None))) @ V.T)
        mean[i], std[i] = d.mean(), d.std()
    return mean, std


def _cost_of_states(agent, geometry: CostGeometry, states: np.ndarray) -> np.ndarray:
    """The cost ``max_reward - reward(x)`` at known states [T, D] -> [T]."""
    zero = np.zeros((agent.state_dim, agent.state_dim))
    return np.array([geometry.max_reward - float(np.asarray(
        agent.reward.compute_reward(x[None], zero)[0])[0, 0]) for x in states])


def one_step_check(agent, episode: Episode, geometry: Optional[CostGeometry],
                   thresholds: Thresholds) -> Dict[str, Any]:
    """The model's one-step predictions along the real episode (see the module doc)."""
    X, Y = episode.transitions()
    mean, var = agent.one_step_prediction(X)
    z = (Y - mean) / np.sqrt(var)
    within = np.abs(z) <= thresholds.z
    dims = list(geometry.dims) if geometry is not None else []
    per_dim = within.mean(axis=0)
    rms_change = np.sqrt(np.mean(Y ** 2, axis=0))
    # steps where a dimension did not move although the model predicts it moves (a limit or
    # a saturation the model does not know)
    still = (np.abs(Y) <= 1e-9 + 1e-6 * rms_change) & (np.abs(mean) > thresholds.z * np.sqrt(var))
    outside = ~within
    return {
        "coverage": float(within.mean()),
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


def predicted_run(agent, steps: int, geometry: Optional[CostGeometry]) -> Dict[str, Any]:
    """The multi-step prediction of ``steps`` steps from the start distribution under the
    agent's policy: predicted cost per step and, with a geometry, distance mean and std."""
    M, S, R, _ = (np.asarray(v) for v in agent.predict_trajectory_with_rewards(horizon=steps))
    out: Dict[str, Any] = {"reward": R}
    if geometry is not None:
        out["cost"] = geometry.max_reward - R
        out["distance_mean"], out["distance_std"] = distance_moments(geometry, M, S)
    return out


def multi_step_check(exp, agent, episode: Episode, geometry: Optional[CostGeometry],
                     thresholds: Thresholds) -> Dict[str, Any]:
    """Predicted distance and cost per step against the real episode's."""
    from .scoring import episode_solved

    steps = exp.config.steps
    pred = predicted_run(agent, steps, geometry)
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
        "pred_solved": bool(solved),
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


def _candidate(view, number: int, geometry: Optional[CostGeometry], kind: str,
               seed: Optional[int], env, seconds: float = 0.0) -> Dict[str, Any]:
    """Predicted cost (the policy objective) and, with ``env``, the real outcome of the
    agent's current policy."""
    agent, cfg = view.agent, view.config
    max_reward = geometry.max_reward if geometry is not None else 1.0
    out: Dict[str, Any] = {"start": kind, "seed": seed, "seconds": seconds,
                           "pred_cost": agent.horizon * max_reward - agent.expected_return()}
    if geometry is not None:
        pred = predicted_run(agent, cfg.steps, geometry)
        out["pred_final_distance"] = float(pred["distance_mean"][-1])
        out["pred_min_distance"] = float(np.min(pred["distance_mean"][1:]))
    if env is not None:
        ep = rollout(env, lambda x: agent.compute_action(x)[0], cfg.steps,
                     seed=view.episode_seed(number), distance_fn=view.distance_fn, quiet=True)
        out["real_distance"] = ep.distances
        out["real_final_distance"] = float(ep.distances[-1])
        out["real_min_distance"] = float(np.min(ep.distances[1:])) if ep.steps else None
        out["real_solved"] = bool(view.episode_solved(ep))
    return out


def optimiser_check(view, number: int, geometry: Optional[CostGeometry], restarts: int,
                    seed: int, env, thresholds: Thresholds) -> Dict[str, Any]:
    """The run's policy against ``restarts`` re-optimisations from random policies and one
    continuing from the run's policy, all on the same model with the run's settings."""
    agent, cfg = view.agent, view.config
    iters = cfg.policy_iterations(number)
    run_policy = snapshot(agent.controller)
    candidates = [_candidate(view, number, geometry, "run", None, env)]
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
                        cfg.policy_method)
            t0 = time.perf_counter()
            improve_policy(view, number)
            candidates.append(_candidate(view, number, geometry, kind, s, env,
                                         time.perf_counter() - t0))
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
    return {"iterations": iters, "method": cfg.policy_method, "horizon": agent.horizon,
            "candidates": candidates, "run_pred_cost": run_cost,
            "best": others.index(best) + 1 if best else None,
            "best_pred_cost": best["pred_cost"] if best else None, "gain": gain,
            "gain_needed": needed, "better_exists": bool(better),
            "better_solves_real": solves}
