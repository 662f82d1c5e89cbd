"""The learning phases of one episode: train the dynamics model, improve the policy,
and the model's predictions kept for the figures."""
from __future__ import annotations

import logging
from typing import Dict, Optional

import numpy as np

from ..models.starts import flank_points, start_samples
from .episode import Episode
from .progress import optimizer_callback, progress_bar

__all__ = ["train_model", "start_policy", "improve_policy", "search_policy", "learn_policy",
           "predictions_before", "predictions_after"]

logger = logging.getLogger(__name__)


def train_model(exp, number: int) -> None:
    """``optimize_models`` on the training data, unless they are exactly those of the
    last training (``max_data`` reached) and ``retrain_unchanged_model`` is off: the
    optimum is then the same, the hyperparameters are kept."""
    cfg, agent = exp.config, exp.agent
    X, Y = exp.training_data()
    previous = exp.model_trained_on
    if (previous is not None and not cfg.retrain_unchanged_model
            and np.array_equal(previous[0], X) and np.array_equal(previous[1], Y)):
        logger.info("episode %d: the model's training data are unchanged (max_data=%s); "
                    "keeping its hyperparameters", number, cfg.max_data)
        return
    with progress_bar(cfg.model_iters * cfg.model_restarts, f"episode {number} model",
                      cfg.quiet) as bar:
        agent.optimize_models(maxiter=cfg.model_iters, restarts=cfg.model_restarts,
                              seed=exp.episode_seed(number), callback=optimizer_callback(bar),
                              min_rel_improvement=cfg.model_min_rel_improvement,
                              patience=cfg.model_patience)
        exp.hooks.after_model_fit(exp, number)
    exp.model_trained_on = (X.copy(), Y.copy())


def improve_policy(exp, number: int, runs: Optional[int] = None) -> float:
    """``optimize_policy`` with the run's settings; the relative early stop and the
    restarts as :meth:`ExperimentConfig.policy_early_stop_at` (always, or with
    ``policy_early_stop="solved"`` once an episode was solved) and
    :meth:`ExperimentConfig.policy_restarts_at` say (from episode ``policy_restart_from``
    on; with ``policy_restart_when="unsolved"`` until an episode was solved), the
    start mixture as :meth:`ExperimentConfig.start_mixture_at` says and the start points
    as :meth:`ExperimentConfig.start_points_at` says.
    The search starts from the agent's current policy (see :func:`learn_policy`);
    ``runs`` overrides the number of runs (1: that one search alone, no restarts).
    Returns the predicted return."""
    cfg, agent = exp.config, exp.agent
    solved = exp.solved_at_episode() is not None
    restarts = cfg.policy_restarts_at(number, solved) if runs is None else int(runs)
    spread = cfg.start_mixture_at(solved)
    if spread is not None or getattr(agent, "start_spread", None) is not None:
        agent.start_spread = spread
    wanted = cfg.start_points_at(solved)
    points = _start_points(agent, wanted, exp.episode_seed(number))
    if points is not None or getattr(agent, "start_points", None) is not None:
        agent.start_points = points
    scale = None if wanted is None else wanted[2]
    if scale is not None or getattr(agent, "start_scale", None) is not None:
        agent.start_scale = scale
    exp.policy_notes = {}
    exp.hooks.before_policy_search(exp, number)

    def search(what: str, runs: int) -> float:
        return search_policy(exp, number, what, runs)

    expected = search("policy", restarts)
    if restarts > 1 and cfg.policy_leave_repeat is not None and not solved:
        expected = _unless_repeating(exp, number, expected)
    check = cfg.fragile_check_at(solved)
    if check is not None:
        expected = _unless_fragile(exp, number, check, expected, search)
    logger.info("episode %d: predicted return %.3f over %d steps", number, expected,
                agent.horizon)
    return expected


def _start_points(agent, wanted, seed: int):
    """The policy objective's start points [T, P, D] for ``wanted`` (``(spread, samples,
    scale)`` of :meth:`ExperimentConfig.start_points_at`, or None): each task's flank
    points and its samples, drawn from the generator of ``seed`` (one per task); None
    when there are none."""
    if wanted is None or (wanted[0] is None and not wanted[1]):
        return None
    spread, samples = wanted[:2]
    m0, S0 = np.asarray(agent.m_init), np.asarray(agent.S_init)
    if S0.ndim == 2:
        S0 = np.broadcast_to(S0, (len(m0),) + S0.shape)
    tasks = []
    for i, (m, S) in enumerate(zip(m0, S0)):
        parts = [] if spread is None else [flank_points(m, S, spread)]
        if samples:
            parts.append(start_samples(m, S, samples, seed + i))
        tasks.append(np.concatenate(parts))
    return np.stack(tasks)


def search_policy(exp, number: int, what: str = "policy", runs: int = 1) -> float:
    """One ``optimize_policy`` of episode ``number``'s agent with the run's settings:
    its iterations, seed, method, compiler and early stop (relative, from the run's
    solved state), ``runs`` runs (restarts), a progress bar named ``what``. Returns the
    best predicted return."""
    cfg, agent = exp.config, exp.agent
    iters = cfg.policy_iterations(number)
    solved = exp.solved_at_episode() is not None
    # XLA is asked for only when chosen: agents without the option keep working
    compiler = {"jit_compile": True} if cfg.policy_compiler == "xla" else {}
    with progress_bar(iters * runs, f"episode {number} {what}", cfg.quiet) as bar:
        return agent.optimize_policy(
            maxiter=iters, restarts=runs, seed=exp.episode_seed(number),
            callback=optimizer_callback(bar), method=cfg.policy_optimizer,
            min_rel_improvement=cfg.policy_early_stop_at(solved),
            patience=cfg.policy_patience, **compiler)


def _unless_repeating(exp, number: int, expected: float) -> float:
    """After a search with restarts in a run not yet solved (so the last episode failed):
    when its run continued from the last policy won with a predicted return within
    ``policy_leave_repeat`` of what the last episode really returned (``horizon * (1 -
    cost / steps)``), the model predicts the episode to repeat a failure it has already
    seen, and running it teaches the model nothing; the best of the fresh runs is used
    instead. Notes the choice in ``exp.policy_notes``; returns the predicted return of the
    policy left in place."""
    agent, last = exp.agent, exp.records[-1]
    returns = agent.policy_run_returns
    if len(returns) < 2 or int(np.argmax(returns)) != 0:
        return expected
    real = agent.horizon * (1.0 - last["cost"] / max(1, last["steps"]))
    if abs(returns[0] - real) >= exp.config.policy_leave_repeat:
        # the model expects more (the search found an improvement) or less (it does not
        # reproduce the last episode's outcome) than what the last episode got
        return expected
    fresh = 1 + int(np.argmax(returns[1:]))
    if not np.isfinite(returns[fresh]):
        return expected
    chosen = agent.use_policy_run(fresh)
    logger.info("episode %d: the search continued from the last policy predicts %.3f, "
                "the last episode returned %.3f: a known outcome; running fresh search "
                "%d instead (predicted %.3f)", number, returns[0], real, fresh, chosen)
    exp.policy_notes["left_repeat"] = {"continued_return": float(returns[0]),
                                       "last_real_return": float(real),
                                       "fresh_run": fresh, "fresh_return": float(chosen)}
    return chosen


def _unless_fragile(exp, number: int, spread: float, plain: float, search) -> float:
    """The fragility check after a plain policy search: the policy's expected return from
    the start mixture of ``spread``; when it falls short of the ``plain`` one by more than
    ``policy_fragile_gap``, the policy fails from the start distribution's flanks, and a
    search on the mixture's objective continues from it. Notes the check in
    ``exp.policy_notes``; returns the predicted return of the objective searched last."""
    agent, gap_allowed = exp.agent, exp.config.policy_fragile_gap
    evaluations = agent.policy_evaluations
    agent.start_spread = spread
    try:
        mixed = agent.expected_return()
        gap = plain - mixed
        note = {"plain_return": float(plain), "mixture_return": float(mixed),
                "searched": bool(gap > gap_allowed)}
        if gap > gap_allowed:
            logger.info("episode %d: the policy is fragile (expected return %.3f from the "
                        "start distribution, %.3f from its mixture): searching on the "
                        "mixture", number, plain, mixed)
            best = search("policy (start mixture)", 1)
            note["searched_return"] = float(best)
            # the record counts the plain search's evaluations too
            exp.policy_notes = {"start_mixture": note, "extra_evaluations": evaluations}
            return best
        exp.policy_notes = {"start_mixture": note}
        return plain
    finally:
        agent.start_spread = None


def start_policy(exp, number: int) -> None:
    """Choose where episode ``number``'s policy search starts: the policy of the episode
    before (kept in place), or, with ``policy_warm_start="solved"`` while no episode was
    solved, a fresh random policy (``controller.randomize``, seeded by the episode); the
    first learned episode always starts from the agent's initial policy."""
    cfg, agent = exp.config, exp.agent
    if (cfg.policy_warm_start == "always" or cfg.first_learned(number)
            or exp.solved_at_episode() is not None):
        return
    randomize = getattr(agent.controller, "randomize", None)
    if not callable(randomize):
        raise TypeError(f"policy_warm_start='solved' needs a controller with "
                        f"randomize(seed=...); {type(agent.controller).__name__} has none")
    randomize(seed=exp.episode_seed(number))
    logger.info("episode %d: no episode solved yet, the policy search starts from a fresh "
                "random policy", number)


def learn_policy(exp, number: int) -> float:
    """The policy phase of learned episode ``number``: :func:`start_policy`, then
    :func:`improve_policy`, then the hooks' ``after_policy_search``; returns the predicted
    return of the search."""
    start_policy(exp, number)
    expected = improve_policy(exp, number)
    exp.hooks.after_policy_search(exp, number, expected)
    return expected


def predictions_before(exp) -> Dict[str, np.ndarray]:
    """The model's multi-step prediction of the coming episode (``pred_mean [T+1, D]``,
    ``pred_var [T+1, D]``, ``pred_reward [T+1]``, ``pred_reward_var [T+1]``), when the
    config asks for predictions. A failure is logged, never stops learning."""
    if not exp.config.predictions:
        return {}
    try:
        M, S, R, Rv = exp.agent.predict_trajectory_with_rewards(horizon=exp.config.horizon)
        return {"pred_mean": np.asarray(M),
                "pred_var": np.stack([np.diag(s) for s in np.asarray(S)]),
                "pred_reward": np.asarray(R), "pred_reward_var": np.asarray(Rv)}
    except Exception as err:  # a figure must not stop learning
        logger.warning("multi-step prediction failed: %s", err)
        return {}


def predictions_after(exp, episode: Episode) -> Dict[str, np.ndarray]:
    """The model's one-step predictions along the episode that ran (``onestep_mean
    [T, D]``, ``onestep_var [T, D]`` of the state change, noise included)."""
    if not exp.config.predictions:
        return {}
    X, _ = episode.transitions()
    if len(X) == 0:
        return {}
    try:
        mean, var = exp.agent.one_step_prediction(X)
        return {"onestep_mean": np.asarray(mean), "onestep_var": np.asarray(var)}
    except Exception as err:
        logger.warning("one-step prediction failed: %s", err)
        return {}
