"""Running PILCO experiments on a gymnasium environment.

The loop of the paper (Algorithm 1): collect ``random_episodes`` episodes with random
actions, build the agent on those transitions, then for every learned episode

1. ``optimize_models``: fit the dynamics GPs to all transitions so far (optionally only
   the first ``max_data`` of them, as the paper did for the reacher);
2. ``optimize_policy``: improve the policy on the model's predicted long-term cost;
3. interact: run the policy on the environment for one episode and keep its transitions
   (``X = [x_t, u_t]``, ``Y = x_{t+1} - x_t``).

Each phase is timed ("interaction", "model", "policy") and shows a tqdm bar unless
``quiet``. A run lives in a directory ``DIR``:

- ``DIR/data.npz``: every transition collected so far (``X [N, D+U]``, ``Y [N, D]``,
  ``episode [N]``) and every episode's states, actions, distances and the model's
  predictions made before it ran; rewritten atomically after every episode (and, on an
  interrupt, with the interrupted episode's partial transitions as ``partial_*``);
- ``DIR/agent.npz``: the agent (``PILCO.save``), after every episode, when
  :mod:`pilco.persistence` is available;
- ``DIR/progress.json``: per-episode records, phase times, settings and task state, so
  that :meth:`Experiment.resume` continues with the next episode;
- ``DIR/summary.json``: the run's summary (see :meth:`Experiment.summary`).

Episodes are numbered from 1 (episode 1 is the first random one). Ctrl-C and SIGTERM
(turned into ``KeyboardInterrupt`` by :func:`sigterm_as_keyboard_interrupt`) stop the
run after saving the agent and the data.

This module logs through :mod:`logging` and never prints; the example scripts print.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import importlib.util
import json
import logging
import os
import signal
import sys
import time
from typing import Any, Callable, Dict, Iterator, List, Optional, Sequence, Tuple

import numpy as np

from .files import write_json_atomic, write_npz_atomic

__all__ = [
    "Episode",
    "ExperimentConfig",
    "Experiment",
    "rollout",
    "saturating_cost",
    "format_timing_table",
    "sigterm_as_keyboard_interrupt",
    "stop_requested",
    "add_common_arguments",
    "learning_settings",
    "parse_args_with_resume",
    "write_json_atomic",
    "write_npz_atomic",
    "persistence_available",
]

logger = logging.getLogger(__name__)

PHASES = ("interaction", "model", "policy")


# ----------------------------------------------------------------------------- files
def persistence_available() -> bool:
    """True when :mod:`pilco.persistence` (``PILCO.save`` / ``PILCO.load``) exists."""
    try:
        return importlib.util.find_spec("pilco.persistence") is not None
    except (ImportError, ValueError):
        return False


# --------------------------------------------------------------------------- signals
#: number of the termination signal received inside ``sigterm_as_keyboard_interrupt``
_stop_signal: Optional[int] = None


def stop_requested() -> bool:
    """True once SIGTERM arrived inside :func:`sigterm_as_keyboard_interrupt`."""
    return _stop_signal is not None


def raise_if_stop_requested() -> None:
    """Raise ``KeyboardInterrupt`` if SIGTERM arrived inside
    :func:`sigterm_as_keyboard_interrupt` (called at the run's safe points)."""
    if _stop_signal is not None:
        raise KeyboardInterrupt(f"signal {_stop_signal}")


@contextlib.contextmanager
def sigterm_as_keyboard_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM stops the run like Ctrl-C, at the next safe point.

    The handler only remembers the signal (:func:`stop_requested`); the run raises
    ``KeyboardInterrupt`` at its next check (every environment step, every optimiser
    iteration, between phases). An exception raised by the handler itself could land in
    a library's finaliser or weak-reference callback, where Python drops it. The
    previous handler is restored afterwards. Only the main thread can install signal
    handlers; elsewhere this does nothing.
    """
    global _stop_signal

    def handler(signum, frame):  # noqa: ARG001 - signal handler signature
        global _stop_signal
        _stop_signal = signum

    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread
        yield
        return
    _stop_signal = None
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
        _stop_signal = None


# -------------------------------------------------------------------------- progress
def _bar(total: Optional[int], desc: str, quiet: bool, unit: str = "it"):
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit=unit, disable=quiet, leave=False,
                dynamic_ncols=True, file=sys.stderr)


def _optimizer_callback(bar) -> Callable[[int], None]:
    """``callback(iteration)`` for the optimisers: ticks ``bar`` and stops on SIGTERM."""

    def callback(iteration: int) -> None:  # noqa: ARG001 - one tick per iteration
        bar.update(1)
        raise_if_stop_requested()

    return callback


# --------------------------------------------------------------------------- episodes
def saturating_cost(distance, width: float) -> np.ndarray:
    """PILCO's saturating cost ``1 - exp(-d^2 / (2 width^2))`` of distances ``[...]``."""
    d = np.asarray(distance, dtype=np.float64)
    return 1.0 - np.exp(-(d ** 2) / (2.0 * float(width) ** 2))


@dataclasses.dataclass
class Episode:
    """One episode's record.

    Attributes:
        states: observations ``[T+1, D]`` (index 0 is the start).
        actions: actions applied ``[T, U]``.
        rewards: environment rewards ``[T]``.
        distances: task distance ``[T+1]`` of every state (NaN without a ``distance_fn``).
        frames: rendered RGB frames ``[T+1]`` of ``uint8 [H, W, 3]`` (empty unless rendered).
        seconds: wall time of the interaction.
        random: whether the actions were random.
        terminated: the environment ended the episode (e.g. target reached).
        interrupted: the rollout was stopped by ``KeyboardInterrupt``.
    """

    states: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    distances: np.ndarray
    frames: List[np.ndarray] = dataclasses.field(default_factory=list)
    seconds: float = 0.0
    random: bool = False
    terminated: bool = False
    interrupted: bool = False

    @property
    def steps(self) -> int:
        """Number of transitions ``T``."""
        return int(len(self.actions))

    def transitions(self) -> Tuple[np.ndarray, np.ndarray]:
        """Training pairs: ``X [T, D+U] = [x_t, u_t]`` and ``Y [T, D] = x_{t+1} - x_t``."""
        X = np.concatenate([self.states[:-1], self.actions], axis=1)
        Y = self.states[1:] - self.states[:-1]
        return X, Y


def rollout(env, policy_fn: Optional[Callable[[np.ndarray], np.ndarray]], steps: int,
            seed: Optional[int] = None, random: bool = False,
            random_action: Optional[Callable[[np.random.Generator], np.ndarray]] = None,
            distance_fn: Optional[Callable[[Any, dict], float]] = None,
            render: bool = False, quiet: bool = True, desc: str = "interaction",
            reset_options: Optional[dict] = None) -> Episode:
    """Run one episode of at most ``steps`` steps.

    Args:
        env: a gymnasium env (observation ``[D]``, action ``[U]``).
        policy_fn: ``x [D] -> u [U]`` (or ``[1, U]``); ignored when ``random``.
        steps: maximum number of steps (the episode also ends when the env terminates
            or truncates).
        seed: seed of ``env.reset`` and of the random actions.
        random: draw actions with ``random_action(rng)`` (default: uniform over
            ``env.action_space``) instead of ``policy_fn``.
        distance_fn: ``(env, info) -> float`` task distance, recorded for every state.
        render: keep ``env.render()`` frames (the env needs ``render_mode="rgb_array"``).
        quiet: no progress bar.
        reset_options: passed to ``env.reset(options=...)``.

    Returns:
        An :class:`Episode`. A ``KeyboardInterrupt`` during the steps returns the partial
        episode with ``interrupted=True`` (the caller decides what to do with it).
    """
    rng = np.random.default_rng(seed)
    if random and random_action is None:
        space = env.action_space
        low, high = np.asarray(space.low, float), np.asarray(space.high, float)
        random_action = lambda g: g.uniform(low, high)  # noqa: E731
    t0 = time.perf_counter()
    x, info = env.reset(seed=seed, options=reset_options)
    x = np.asarray(x, dtype=np.float64).reshape(-1)
    states, actions, rewards = [x], [], []
    distances = [distance_fn(env, info) if distance_fn else np.nan]
    frames = [env.render()] if render else []
    terminated = interrupted = False
    bar = _bar(steps, desc, quiet, unit="step")
    try:
        for _ in range(int(steps)):
            raise_if_stop_requested()
            if random:
                u = np.asarray(random_action(rng), dtype=np.float64).reshape(-1)
            else:
                u = np.asarray(policy_fn(x), dtype=np.float64).reshape(-1)
            x_next, r, terminated, truncated, info = env.step(u)
            x = np.asarray(x_next, dtype=np.float64).reshape(-1)
            actions.append(u)
            states.append(x)
            rewards.append(float(r))
            distances.append(distance_fn(env, info) if distance_fn else np.nan)
            if render:
                frames.append(env.render())
            bar.update(1)
            if terminated or truncated:
                break
    except KeyboardInterrupt:
        interrupted = True
        # keep only complete transitions
        states = states[: len(actions) + 1]
        distances = distances[: len(actions) + 1]
    finally:
        bar.close()
    U = int(np.prod(env.action_space.shape))
    return Episode(
        states=np.array(states),
        actions=np.array(actions).reshape(-1, U),
        rewards=np.array(rewards),
        distances=np.array(distances, dtype=np.float64),
        frames=frames,
        seconds=time.perf_counter() - t0,
        random=bool(random),
        terminated=bool(terminated),
        interrupted=interrupted,
    )


# ------------------------------------------------------------------------ the config
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
            than ``model_min_rel_improvement`` (relative) over the last ``model_patience`` iterations
            (``None``: always ``model_iters``).
        policy_iters, policy_restarts: the same for the policy.
        policy_method: ``"L-BFGS-B"`` or ``"BFGS"`` (see ``PILCO.optimize_policy``).
        policy_min_rel_improvement, policy_patience: stop a policy optimisation run when its
            predicted return grew by less than ``policy_min_rel_improvement`` (relative)
            over the last ``policy_patience`` iterations (``None``: always ``policy_iters``).
        policy_early_stop: ``"always"``, or ``"solved"``: the early stop applies only once
            an episode has been solved (refining a policy that works needs few
            iterations; before that, a slow stretch often precedes a large gain).
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
    policy_min_rel_improvement: Optional[float] = None
    policy_patience: int = 10
    policy_early_stop: str = "always"
    cost_width: float = 0.25
    success_threshold: float = 0.05
    solved_rule: str = "reach"
    hold_steps: int = 10
    retrain_unchanged_model: bool = False
    render: bool = True
    predictions: bool = True
    quiet: bool = False

    def __post_init__(self):
        if self.policy_early_stop not in ("always", "solved"):
            raise ValueError(f"policy_early_stop must be 'always' or 'solved', got "
                             f"{self.policy_early_stop!r}")
        if self.solved_rule not in ("reach", "hold"):
            raise ValueError(f"solved_rule must be 'reach' or 'hold', got {self.solved_rule!r}")
        if self.random_episodes < 1:
            raise ValueError("at least one random episode is needed to build the model")
        if self.episodes < self.random_episodes:
            raise ValueError(f"episodes ({self.episodes}) must be >= random_episodes "
                             f"({self.random_episodes})")
        if self.max_data == 0:
            self.max_data = None
        if self.max_data is not None and self.max_data < 2:
            raise ValueError(f"max_data must be at least 2 (or None), got {self.max_data}")


# ------------------------------------------------------------------------ experiment
def _distance_from_info(env, info) -> float:
    for key in ("distance", "tip_distance"):
        if key in info:
            return float(info[key])
    return float("nan")


class Experiment:
    """A PILCO run on one env, stored in ``directory`` (see the module docstring).

    Args:
        config: the run's :class:`ExperimentConfig`.
        directory: the run directory (created).
        build_agent: ``(data (X [N, D+U], Y [N, D]), start_states [E, D]) -> PILCO``;
            called once the random episodes are in (``start_states`` are the first
            states of the episodes so far), and on resume when no saved agent exists.
        make_env: ``() -> env``; default ``gymnasium.make(config.env_id,
            render_mode="rgb_array" if config.render else None, **config.env_kwargs)``.
        distance_fn: ``(env, info) -> float``; default ``info["distance"]`` or
            ``info["tip_distance"]``.
        args: the command-line settings, stored for ``--resume``.
        render_fn: ``Episode -> frames`` drawing the final episode after it ran (e.g. a
            replay in another process); when given, the env is made without a
            ``render_mode`` and never renders during the rollout.
        after_model_fit: ``agent -> None`` called after every ``optimize_models`` (e.g. to
            adjust hyperparameters the evidence cannot determine).
    """

    def __init__(self, config: ExperimentConfig, directory: str,
                 build_agent: Callable[[Tuple[np.ndarray, np.ndarray], np.ndarray], Any],
                 make_env: Optional[Callable[[], Any]] = None,
                 distance_fn: Optional[Callable[[Any, dict], float]] = None,
                 args: Optional[Dict[str, Any]] = None,
                 render_fn: Optional[Callable[[Episode], List[np.ndarray]]] = None,
                 after_model_fit: Optional[Callable[[Any], None]] = None):
        self.config = config
        self.after_model_fit = after_model_fit
        self.render_fn = render_fn
        self.directory = os.path.abspath(directory)
        os.makedirs(self.directory, exist_ok=True)
        self.build_agent = build_agent
        self.distance_fn = distance_fn or _distance_from_info
        self.args = dict(args or {})
        self._make_env = make_env
        self.env = None
        self.agent = None
        self.episodes: List[Episode] = []
        self.records: List[Dict[str, Any]] = []
        # model predictions attached to episodes (NaN-filled for random episodes)
        self.predictions: List[Dict[str, np.ndarray]] = []
        self.seconds = {p: 0.0 for p in PHASES}
        self.wall_seconds = 0.0
        #: free-form task state persisted in progress.json (e.g. damage events); the
        #: key ``"train_from_episode"`` (1-based) drops earlier episodes from the model's
        #: training data, ``"summary"`` holds extra summary fields
        self.extra: Dict[str, Any] = {}
        self.interrupted = False
        self._partial: Optional[Episode] = None
        self._t_start: Optional[float] = None
        self._model_fingerprint = None
        self.cpu_seconds: Dict[int, Dict[str, float]] = {}

    # -- paths ----------------------------------------------------------------------------
    @property
    def data_path(self) -> str:
        return os.path.join(self.directory, "data.npz")

    @property
    def agent_path(self) -> str:
        return os.path.join(self.directory, "agent.npz")

    @property
    def progress_path(self) -> str:
        return os.path.join(self.directory, "progress.json")

    @property
    def summary_path(self) -> str:
        return os.path.join(self.directory, "summary.json")

    # -- environment ----------------------------------------------------------------------
    def make_env(self):
        """Create (once) and return the environment."""
        if self.env is None:
            if self._make_env is not None:
                self.env = self._make_env()
            else:
                import gymnasium

                import pilco.envs  # noqa: F401 - registers the ids

                self.env = gymnasium.make(
                    self.config.env_id,
                    render_mode=("rgb_array" if self.config.render and self.render_fn is None
                                 else None),
                    **self.config.env_kwargs,
                )
        return self.env

    # -- data -----------------------------------------------------------------------------
    def all_transitions(self) -> Tuple[np.ndarray, np.ndarray]:
        """Every collected transition: ``X [N, D+U]``, ``Y [N, D]``, episode order."""
        pairs = [e.transitions() for e in self.episodes]
        return (np.concatenate([p[0] for p in pairs]), np.concatenate([p[1] for p in pairs]))

    def training_data(self) -> Tuple[np.ndarray, np.ndarray]:
        """The transitions the dynamics model learns from: those of episodes from
        ``extra["train_from_episode"]`` on (default all), the first ``max_data`` of them."""
        first = int(self.extra.get("train_from_episode", 1))
        pairs = [e.transitions() for e in self.episodes[first - 1:]] or [
            self.episodes[-1].transitions()]
        X = np.concatenate([p[0] for p in pairs])
        Y = np.concatenate([p[1] for p in pairs])
        if self.config.max_data is not None:
            X, Y = X[: self.config.max_data], Y[: self.config.max_data]
        return X, Y

    def start_states(self) -> np.ndarray:
        """First state of every episode so far, ``[E, D]``."""
        return np.stack([e.states[0] for e in self.episodes])

    # -- persistence ----------------------------------------------------------------------
    def save_data(self) -> None:
        """Rewrite ``data.npz`` with every transition and episode so far (atomically)."""
        arrays: Dict[str, np.ndarray] = {}
        if self.episodes:
            X, Y = self.all_transitions()
            arrays["X"], arrays["Y"] = X, Y
            arrays["episode"] = np.concatenate(
                [np.full(e.steps, i + 1) for i, e in enumerate(self.episodes)])
        for i, e in enumerate(self.episodes):
            n = i + 1
            arrays[f"states_{n}"] = e.states
            arrays[f"actions_{n}"] = e.actions
            arrays[f"rewards_{n}"] = e.rewards
            arrays[f"distances_{n}"] = e.distances
            for key, value in self.predictions[i].items():
                arrays[f"{key}_{n}"] = value
        if self._partial is not None and self._partial.steps > 0:
            X, Y = self._partial.transitions()
            arrays["partial_X"], arrays["partial_Y"] = X, Y
            arrays["partial_states"] = self._partial.states
            arrays["partial_actions"] = self._partial.actions
        write_npz_atomic(self.data_path, arrays)

    def save_agent(self) -> bool:
        """``agent.save(DIR/agent.npz)`` when :mod:`pilco.persistence` exists; True if saved."""
        if self.agent is None:
            return False
        if not persistence_available():
            logger.info("pilco.persistence is not available: the agent is not saved")
            return False
        try:
            self.agent.save(self.agent_path)
            return True
        except Exception as err:  # noqa: BLE001 - data are already safe; keep running
            logger.warning("could not save the agent to %s: %s", self.agent_path, err)
            return False

    def save_progress(self) -> None:
        """Write ``progress.json`` and ``summary.json``."""
        wall = self.wall_seconds + (time.perf_counter() - self._t_start if self._t_start else 0)
        write_json_atomic(self.progress_path, {
            "config": dataclasses.asdict(self.config),
            "args": self.args,
            "episodes_done": len(self.episodes),
            "records": self.records,
            "seconds": self.seconds,
            # process CPU time of the model / policy phases per episode number: a check
            # on wall times measured on a busy machine
            "cpu_seconds": self.cpu_seconds,
            "wall_seconds": wall,
            "extra": self.extra,
            "interrupted": self.interrupted,
            "agent_saved": os.path.exists(self.agent_path),
        })
        write_json_atomic(self.summary_path, self.summary())

    def save(self) -> None:
        """Save data first (never lose transitions), then the agent, then progress."""
        self.save_data()
        self.save_agent()
        self.save_progress()

    @classmethod
    def resume(cls, directory: str, config: ExperimentConfig,
               build_agent: Callable, **kwargs) -> "Experiment":
        """Reload a run from ``directory`` to continue with its next episode.

        The agent comes from ``DIR/agent`` (``PILCO.load``) when it was saved; otherwise it
        is rebuilt with ``build_agent`` on the saved data (its policy then starts afresh).
        ``config`` may differ from the saved one (e.g. more ``episodes``).
        """
        exp = cls(config, directory, build_agent, **kwargs)
        with open(exp.progress_path, encoding="utf-8") as f:
            progress = json.load(f)
        with np.load(exp.data_path) as data:
            n = int(progress["episodes_done"])
            for i in range(1, n + 1):
                ep = Episode(states=data[f"states_{i}"], actions=data[f"actions_{i}"],
                             rewards=data[f"rewards_{i}"], distances=data[f"distances_{i}"],
                             random=bool(progress["records"][i - 1]["random"]))
                exp.episodes.append(ep)
                exp.predictions.append({
                    k[: -len(f"_{i}")]: data[k] for k in data.files
                    if k.endswith(f"_{i}") and k.startswith(("pred_", "onestep_"))
                })
        exp.records = list(progress["records"])
        exp.seconds = {p: float(progress["seconds"].get(p, 0.0)) for p in PHASES}
        exp.wall_seconds = float(progress.get("wall_seconds", 0.0))
        exp.extra = dict(progress.get("extra", {}))
        exp.cpu_seconds = {int(k): v for k, v in progress.get("cpu_seconds", {}).items()}
        if len(exp.episodes) >= config.random_episodes:
            agent = None
            if persistence_available() and os.path.exists(exp.agent_path):
                try:
                    from pilco.models import PILCO

                    agent = PILCO.load(exp.agent_path)
                    logger.info("resumed the agent from %s", exp.agent_path)
                except Exception as err:  # noqa: BLE001
                    logger.warning("could not load the agent from %s (%s); rebuilding it",
                                   exp.agent_path, err)
            if agent is None:
                agent = build_agent(exp.training_data(), exp.start_states())
            agent.set_data(exp.training_data())
            exp.agent = agent
        logger.info("resuming %s after episode %d", directory, len(exp.episodes))
        return exp

    # -- records --------------------------------------------------------------------------
    def episode_solved(self, episode: Episode) -> bool:
        """Whether an episode meets the task's success rule."""
        d = episode.distances[1:]
        if len(d) == 0 or not np.all(np.isfinite(d)):
            return False
        thr = self.config.success_threshold
        if self.config.solved_rule == "reach":
            return bool(np.any(d < thr))
        k = self.config.hold_steps
        return bool(len(d) >= k and np.all(d[-k:] < thr))

    def _record(self, episode: Episode, seconds: Dict[str, float]) -> Dict[str, Any]:
        d = episode.distances
        within = np.nonzero(d[1:] < self.config.success_threshold)[0]
        cost = float(np.sum(saturating_cost(d[1:], self.config.cost_width)))
        return {
            "episode": len(self.episodes),
            "random": bool(episode.random),
            "steps": int(episode.steps),
            "cost": cost,
            "final_distance": float(d[-1]),
            "min_distance": float(np.min(d[1:])) if episode.steps else float(d[0]),
            "steps_to_target": int(within[0] + 1) if len(within) else None,
            "seconds": {p: float(seconds.get(p, 0.0)) for p in PHASES},
        }

    def solved_at_episode(self) -> Optional[int]:
        """Number of the first learned episode that solved the task, or None."""
        for rec, ep in zip(self.records, self.episodes):
            if not rec["random"] and self.episode_solved(ep):
                return int(rec["episode"])
        return None

    def summary(self) -> Dict[str, Any]:
        """``{"task", "seed", "solved", "solved_at_episode", "episodes": [...], "seconds"}``.

        ``seconds`` sums every episode's phases; ``total`` is the wall time of the run
        (all sessions, setup and saving included, figures excluded).
        """
        at = self.solved_at_episode()
        wall = self.wall_seconds + (time.perf_counter() - self._t_start if self._t_start else 0)
        return {
            "task": self.config.task,
            "seed": int(self.config.seed),
            "solved": at is not None,
            "solved_at_episode": at,
            "episodes": self.records,
            "seconds": {**{p: float(self.seconds[p]) for p in PHASES}, "total": float(wall)},
            **self.extra.get("summary", {}),
        }

    # -- the loop -------------------------------------------------------------------------
    def _episode_seed(self, number: int) -> int:
        return int(self.config.seed) * 1000 + int(number)

    def _add_episode(self, episode: Episode, seconds: Dict[str, float],
                     prediction: Dict[str, np.ndarray]) -> Dict[str, Any]:
        self.episodes.append(episode)
        self.predictions.append(prediction)
        rec = self._record(episode, seconds)
        self.records.append(rec)
        for p in PHASES:
            self.seconds[p] += float(seconds.get(p, 0.0))
        self._partial = None
        if self.agent is not None:
            self.agent.set_data(self.training_data())
        self.save()
        logger.info("episode %d (%s): %d steps, final distance %.4f, min %.4f, cost %.2f, "
                    "to target %s; %.1f s interaction, %.1f s model, %.1f s policy",
                    rec["episode"], "random" if rec["random"] else "learned", rec["steps"],
                    rec["final_distance"], rec["min_distance"], rec["cost"],
                    rec["steps_to_target"], *(rec["seconds"][p] for p in PHASES))
        return rec

    def _render_after(self, episode: Episode, last: bool) -> None:
        if last and self.config.render and self.render_fn is not None:
            try:
                episode.frames = list(self.render_fn(episode))
            except Exception as err:  # noqa: BLE001 - frames are optional
                logger.warning("rendering the final episode failed: %s", err)

    def _check_rollout(self, episode: Episode) -> None:
        if episode.interrupted:
            self._partial = episode
            raise KeyboardInterrupt

    def run_random_episode(self) -> Dict[str, Any]:
        """Collect one episode with random actions; builds the agent after the last one."""
        cfg = self.config
        env = self.make_env()
        number = len(self.episodes) + 1
        random_action = None
        if cfg.random_action_scale is not None:
            U = int(np.prod(env.action_space.shape))
            scale = float(cfg.random_action_scale)
            random_action = lambda g: g.uniform(-scale, scale, U)  # noqa: E731
        last = number == cfg.episodes
        ep = rollout(env, None, cfg.steps, seed=self._episode_seed(number), random=True,
                     random_action=random_action, distance_fn=self.distance_fn,
                     render=cfg.render and last and self.render_fn is None, quiet=cfg.quiet,
                     desc=f"episode {number} interaction (random)")
        self._check_rollout(ep)
        self._render_after(ep, last)
        nan = {}
        if self.agent is None and number >= cfg.random_episodes:
            self.episodes.append(ep)  # build_agent sees this episode's data
            try:
                self.agent = self.build_agent(self.training_data(), self.start_states())
            finally:
                self.episodes.pop()
        return self._add_episode(ep, {"interaction": ep.seconds}, nan)

    def _multi_step_prediction(self) -> Dict[str, np.ndarray]:
        agent = self.agent
        M, S, R, Rv = agent.predict_trajectory_with_rewards(horizon=self.config.steps)
        S = np.asarray(S)
        return {
            "pred_mean": np.asarray(M),
            "pred_var": np.stack([np.diag(s) for s in S]),
            "pred_reward": np.asarray(R),
            "pred_reward_var": np.asarray(Rv),
        }

    def _one_step_prediction(self, episode: Episode) -> Dict[str, np.ndarray]:
        X, _ = episode.transitions()
        if len(X) == 0:
            return {}
        mean, var = self.agent.mgpr.predict_f(self.agent.gp_inputs(X))
        noise = np.asarray(self.agent.mgpr.noise_variance)
        return {"onestep_mean": np.asarray(mean),
                "onestep_var": np.asarray(var) + noise[None, :]}

    def run_learned_episode(self) -> Dict[str, Any]:
        """Train the model, optimise the policy, run it for one episode, store everything."""
        cfg = self.config
        if self.agent is None:
            raise RuntimeError("no agent yet: run the random episodes first")
        env = self.make_env()
        number = len(self.episodes) + 1
        seed = self._episode_seed(number)
        seconds: Dict[str, float] = {}

        t0, c0 = time.perf_counter(), time.process_time()
        X, Y = self.training_data()
        fingerprint = (X.shape, float(np.sum(X)), float(np.sum(Y)), float(np.sum(X * X)))
        if fingerprint == self._model_fingerprint and not cfg.retrain_unchanged_model:
            logger.info("episode %d: the model's training data are unchanged (max_data=%s); "
                        "keeping its hyperparameters", number, cfg.max_data)
        else:
            with _bar(cfg.model_iters * cfg.model_restarts, f"episode {number} model",
                      cfg.quiet) as bar:
                self.agent.optimize_models(maxiter=cfg.model_iters,
                                           restarts=cfg.model_restarts, seed=seed,
                                           callback=_optimizer_callback(bar),
                                           min_rel_improvement=cfg.model_min_rel_improvement,
                                           patience=cfg.model_patience)
                if self.after_model_fit is not None:
                    self.after_model_fit(self.agent)
            self._model_fingerprint = fingerprint
        seconds["model"] = time.perf_counter() - t0
        cpu = {"model": time.process_time() - c0}
        raise_if_stop_requested()

        t0, c0 = time.perf_counter(), time.process_time()
        with _bar(cfg.policy_iters * cfg.policy_restarts, f"episode {number} policy",
                  cfg.quiet) as bar:
            expected = self.agent.optimize_policy(
                maxiter=cfg.policy_iters, restarts=cfg.policy_restarts, seed=seed,
                callback=_optimizer_callback(bar), method=cfg.policy_method,
                min_rel_improvement=(cfg.policy_min_rel_improvement
                                 if cfg.policy_early_stop == "always"
                                 or self.solved_at_episode() is not None else None),
                patience=cfg.policy_patience)
        seconds["policy"] = time.perf_counter() - t0
        cpu["policy"] = time.process_time() - c0
        self.cpu_seconds[number] = cpu
        raise_if_stop_requested()
        logger.info("episode %d: predicted return %.3f over %d steps", number, expected,
                    self.agent.horizon)

        prediction: Dict[str, np.ndarray] = {}
        if cfg.predictions:
            try:
                prediction.update(self._multi_step_prediction())
            except Exception as err:  # noqa: BLE001 - a figure must not stop learning
                logger.warning("multi-step prediction failed: %s", err)

        agent = self.agent
        ep = rollout(env, lambda x: agent.compute_action(x)[0], cfg.steps, seed=seed,
                     distance_fn=self.distance_fn,
                     render=cfg.render and number == cfg.episodes and self.render_fn is None,
                     quiet=cfg.quiet, desc=f"episode {number} interaction")
        self._check_rollout(ep)
        self._render_after(ep, number == cfg.episodes)
        seconds["interaction"] = ep.seconds
        if cfg.predictions:
            try:
                prediction.update(self._one_step_prediction(ep))
            except Exception as err:  # noqa: BLE001
                logger.warning("one-step prediction failed: %s", err)
        return self._add_episode(ep, seconds, prediction)

    def run_episode(self) -> Dict[str, Any]:
        """The next episode: random while fewer than ``random_episodes``, else learned."""
        if len(self.episodes) < self.config.random_episodes:
            return self.run_random_episode()
        return self.run_learned_episode()

    @contextlib.contextmanager
    def session(self) -> Iterator["Experiment"]:
        """Time the session and, on Ctrl-C or SIGTERM, save everything and stop cleanly.

        After an interrupt ``self.interrupted`` is True and the block is left without the
        exception.
        """
        self._t_start = time.perf_counter()
        try:
            with sigterm_as_keyboard_interrupt():
                try:
                    yield self
                    # a SIGTERM after the last safe point: everything is saved already
                    if stop_requested():
                        self.interrupted = True
                except KeyboardInterrupt:
                    self.interrupted = True
                    logger.warning("interrupted: saving the agent and %d episodes to %s",
                                   len(self.episodes), self.directory)
                    # a second signal while saving must not lose the data
                    signal.signal(signal.SIGINT, signal.SIG_IGN)
                    try:
                        self.save()
                    finally:
                        signal.signal(signal.SIGINT, signal.default_int_handler)
        finally:
            self.wall_seconds += time.perf_counter() - self._t_start
            self._t_start = None
            with contextlib.suppress(Exception):
                self.save_progress()

    def run(self) -> Dict[str, Any]:
        """Run (or continue) until ``config.episodes`` episodes; returns the summary."""
        with self.session():
            while len(self.episodes) < self.config.episodes:
                self.run_episode()
                raise_if_stop_requested()
        return self.summary()

    def close(self) -> None:
        """Close the environment."""
        if self.env is not None:
            with contextlib.suppress(Exception):
                self.env.close()
            self.env = None

    def last_frames(self) -> List[np.ndarray]:
        """Frames of the most recent episode that was rendered (may be empty)."""
        for ep in reversed(self.episodes):
            if ep.frames:
                return ep.frames
        return []


# ------------------------------------------------------------------------------ report
def format_timing_table(seconds: Dict[str, float], title: str = "Timing",
                        reference: Optional[Dict[str, float]] = None) -> str:
    """The paper's timing table: interaction, model training, controller optimisation,
    whole program, in seconds (optionally next to a ``reference`` column)."""
    rows = [("Interaction", "interaction"), ("Model training", "model"),
            ("Controller optimisation", "policy"), ("Whole program", "total")]
    head = f"{'Phase':<26}{'this run [s]':>14}"
    if reference:
        head += f"{'paper [s]':>12}"
    lines = [title, head, "-" * len(head)]
    for label, key in rows:
        line = f"{label:<26}{seconds.get(key, float('nan')):>14.2f}"
        if reference:
            ref = reference.get(key)
            line += f"{ref:>12.2f}" if ref is not None else f"{'':>12}"
        lines.append(line)
    return "\n".join(lines)


def format_episode_table(summary: Dict[str, Any]) -> str:
    """One line per episode: steps, cost, final/min distance, steps to target, times."""
    head = (f"{'ep':>3} {'kind':<7}{'steps':>6}{'cost':>8}{'final d':>9}{'min d':>8}"
            f"{'to tgt':>7}{'inter':>7}{'model':>7}{'policy':>8}")
    lines = [head, "-" * len(head)]
    for r in summary["episodes"]:
        s = r["seconds"]
        lines.append(
            f"{r['episode']:>3} {'random' if r['random'] else 'learned':<7}{r['steps']:>6}"
            f"{r['cost']:>8.2f}{r['final_distance']:>9.3f}{r['min_distance']:>8.3f}"
            f"{str(r['steps_to_target']) if r['steps_to_target'] is not None else '-':>7}"
            f"{s['interaction']:>7.1f}{s['model']:>7.1f}{s['policy']:>8.1f}")
    return "\n".join(lines)


# ---------------------------------------------------------------------- command line
def add_common_arguments(parser: argparse.ArgumentParser, *, episodes: int, steps: int,
                         basis_functions: int, policy_iters: int, model_iters: int,
                         policy_restarts: int = 1, model_restarts: int = 1,
                         policy_method: str = "L-BFGS-B",
                         policy_min_rel_improvement: Optional[float] = None,
                         model_min_rel_improvement: Optional[float] = None,
                         policy_early_stop: str = "always",
                         max_data: Optional[int] = None, random_episodes: int = 1,
                         output: str = "runs/run-seed{seed}") -> None:
    """Flags shared by the example scripts (defaults given per task)."""
    g = parser.add_argument_group("experiment")
    g.add_argument("--seed", type=int, default=0, help="random seed (default %(default)s)")
    g.add_argument("--episodes", type=int, default=episodes,
                   help="total episodes including the random ones (default %(default)s)")
    g.add_argument("--random-episodes", type=int, default=random_episodes,
                   help="episodes with random actions first (default %(default)s)")
    g.add_argument("--horizon", type=int, default=steps,
                   help="steps per episode and planning horizon (default %(default)s)")
    g.add_argument("--output", default=output,
                   help="run directory (default %(default)s; {seed} is replaced)")
    g.add_argument("--resume", metavar="DIR", default=None,
                   help="continue the run saved in DIR with its next episode")
    g.add_argument("--quiet", action="store_true", help="no progress bars")
    g.add_argument("--no-render", action="store_true", help="do not render the last episode")
    g.add_argument("--no-figures", action="store_true", help="do not draw figures")
    g.add_argument("--log-level", default="WARNING", help="logging level (default %(default)s)")
    g = parser.add_argument_group("learning")
    g.add_argument("--basis-functions", type=int, default=basis_functions,
                   help="RBF policy basis functions (default %(default)s)")
    g.add_argument("--policy-iters", type=int, default=policy_iters,
                   help="optimiser iterations per policy optimisation (default %(default)s)")
    g.add_argument("--policy-restarts", type=int, default=policy_restarts,
                   help="policy optimisation restarts (default %(default)s)")
    g.add_argument("--policy-optimizer", choices=("L-BFGS-B", "BFGS"), type=str.upper,
                   default=policy_method,
                   help="policy optimiser (BFGS: dense update, as the MATLAB release; "
                        "default %(default)s)")
    g.add_argument("--policy-min-rel-improvement", type=float, default=policy_min_rel_improvement,
                   help="stop a policy optimisation once its predicted return grew by less "
                        "than this fraction of it over the last --policy-patience iterations "
                        "(default %(default)s; 0 or None: never)")
    g.add_argument("--policy-patience", type=int, default=10,
                   help="iterations for --policy-min-rel-improvement (default %(default)s)")
    g.add_argument("--policy-early-stop", choices=("always", "solved"),
                   default=policy_early_stop,
                   help="apply --policy-min-rel-improvement always, or only once an episode "
                        "was solved (default %(default)s)")
    g.add_argument("--model-iters", type=int, default=model_iters,
                   help="L-BFGS iterations of GP training (default %(default)s)")
    g.add_argument("--model-restarts", type=int, default=model_restarts,
                   help="GP training restarts (default %(default)s)")
    g.add_argument("--model-min-rel-improvement", type=float, default=model_min_rel_improvement,
                   help="stop GP training once its loss fell by less than this fraction of "
                        "it over the last 10 iterations (default %(default)s; 0 or None: never)")
    g.add_argument("--max-data", type=int, default=max_data,
                   help="GP learns from the first N transitions only (0 or None: all; "
                        "default %(default)s)")
    g.add_argument("--retrain-unchanged-model", action="store_true",
                   help="train the GPs again even if their training data did not change")


def learning_settings(args: argparse.Namespace) -> Dict[str, Any]:
    """The :class:`ExperimentConfig` fields set by :func:`add_common_arguments`' learning
    flags, as keyword arguments."""
    return dict(
        max_data=args.max_data, model_iters=args.model_iters,
        model_restarts=args.model_restarts,
        model_min_rel_improvement=args.model_min_rel_improvement,
        retrain_unchanged_model=args.retrain_unchanged_model,
        policy_iters=args.policy_iters, policy_restarts=args.policy_restarts,
        policy_method=args.policy_optimizer,
        policy_min_rel_improvement=args.policy_min_rel_improvement,
        policy_patience=args.policy_patience, policy_early_stop=args.policy_early_stop,
    )


def parse_args_with_resume(parser: argparse.ArgumentParser,
                           argv: Optional[Sequence[str]] = None) -> argparse.Namespace:
    """Parse ``argv``; with ``--resume DIR`` the settings saved in ``DIR/progress.json``
    become the defaults, so only flags given again (e.g. ``--episodes``) change."""
    args = parser.parse_args(argv)
    if args.resume:
        path = os.path.join(args.resume, "progress.json")
        if not os.path.exists(path):
            parser.error(f"--resume {args.resume}: no progress.json there")
        with open(path, encoding="utf-8") as f:
            saved = json.load(f).get("args", {})
        known = {a.dest for a in parser._actions}  # noqa: SLF001 - argparse has no API
        parser.set_defaults(**{k: v for k, v in saved.items() if k in known})
        args = parser.parse_args(argv)
        args.output = args.resume
    else:
        args.output = args.output.format(seed=args.seed)
    return args


def configure_logging(level: str) -> None:
    """Basic logging to stderr for the example scripts (also quiets TensorFlow's C++)."""
    logging.basicConfig(level=getattr(logging, str(level).upper(), logging.WARNING),
                        format="%(asctime)s %(name)s %(levelname)s: %(message)s")
