"""The PILCO loop of the paper (Algorithm 1) on a gymnasium environment.

Collect ``random_episodes`` episodes with random actions, build the agent on their
transitions, then for every learned episode

1. ``optimize_models``: fit the dynamics GPs to the transitions so far (the first
   ``max_data`` of them, when set);
2. ``optimize_policy``: improve the policy on the model's predicted long-term cost;
3. interact: run the policy for one episode and keep its transitions
   (``X = [x_t, u_t]``, ``Y = x_{t+1} - x_t``).

Each phase is timed ("interaction", "model", "policy") and shows a progress bar unless
``quiet``. Everything is saved to the run directory after every episode
(:class:`~pilco.experiment.store.RunStore`); Ctrl-C and SIGTERM stop the run at the next
safe point after saving. Episodes are numbered from 1 (episode 1 is the first random one).
"""
from __future__ import annotations

import contextlib
import functools
import logging
import time
from typing import Any, Dict, Iterator, Optional

import numpy as np

from ..portable import portability_warning
from .config import ExperimentConfig
from .episode import Episode, rollout
from .hooks import RunHooks
from .learning import learn_policy, predictions_after, predictions_before, train_model
from .signals import (interrupts_deferred, raise_if_stop_requested,
                      sigterm_as_keyboard_interrupt, stop_requested)
from .record import RunRecord
from .store import restore_progress

__all__ = ["Experiment"]

logger = logging.getLogger(__name__)


@functools.lru_cache(maxsize=1)
def _warn_unless_portable() -> None:
    """Once per process: warn when its arithmetic is its CPU's own although the CPU could
    run the paths every x86-64 CPU with AVX2 runs alike (:mod:`pilco.portable`)."""
    message = portability_warning()
    if message:
        logger.warning(message)


class Experiment(RunRecord):
    """A PILCO run on one env, stored in ``directory``.

    Args:
        config: the run's :class:`ExperimentConfig`.
        directory: the run directory (created).
        hooks: what the task tells the loop (:class:`~pilco.experiment.hooks.RunHooks`):
            its environment and agent, the episode schedule, what happens between the
            phases, its success rule.
        settings: the task's settings as a JSON-ready dict, stored for ``--resume``.
        resume: read the run saved in ``directory`` back (its episodes, records, fields,
            task state and agent) to continue with its next episode; the agent comes from
            ``agent.npz`` when it can be read, otherwise ``hooks.build_agent`` rebuilds it
            on the saved data (its policy then starts afresh). ``config`` may differ from
            the saved one (e.g. more ``episodes``).

    Once opened (new or read back), ``hooks.opened(self)`` is called. The collected
    episodes, records, timings, task state, saving and the summary are those of
    :class:`~pilco.experiment.record.RunRecord`.
    """

    def __init__(self, config: ExperimentConfig, directory: str, hooks: RunHooks,
                 settings: Optional[Dict[str, Any]] = None, resume: bool = False):
        if not isinstance(hooks, RunHooks):
            raise TypeError(f"hooks must be a pilco.experiment.RunHooks (subclass it, or use "
                            f"FunctionHooks(build_agent, ...)), not {type(hooks).__name__}")
        super().__init__(config, directory, settings, hooks)
        self.env = None
        if resume:
            restore_progress(self, self.store.load_progress())
            if len(self.episodes) >= config.random_episodes:
                agent = self.store.load_agent()
                if agent is None:
                    agent = hooks.build_agent(self.training_data(), self.start_states())
                self.give_agent_data(agent)
                self.agent = agent
            logger.info("resuming %s after episode %d", directory, len(self.episodes))
        hooks.opened(self)

    def make_env(self):
        """Create (once, ``hooks.make_env``) and return the environment."""
        if self.env is None:
            self.env = self.hooks.make_env(self)
        return self.env

    @classmethod
    def resume(cls, directory: str, config: ExperimentConfig, hooks: RunHooks,
               settings: Optional[Dict[str, Any]] = None) -> "Experiment":
        """The run saved in ``directory``, read back to continue with its next episode
        (``Experiment(..., resume=True)``)."""
        return cls(config, directory, hooks, settings, resume=True)

    def _interact(self, number: int, policy_fn, random_action=None) -> Episode:
        """Run episode ``number`` (random when ``policy_fn`` is None); the final episode is
        rendered. An interrupted rollout is kept as partial data and re-raised."""
        cfg, last = self.config, number == self.config.episodes
        options = self.hooks.reset_options(number)
        draws = self.hooks.draws_frames
        ep = rollout(self.make_env(), policy_fn, cfg.horizon, seed=self.episode_seed(number),
                     reset_options=options,
                     random=policy_fn is None, random_action=random_action,
                     distance_fn=self.hooks.distance,
                     render=cfg.render and last and not draws, quiet=cfg.quiet,
                     desc=f"episode {number} interaction"
                          + (" (random)" if policy_fn is None else ""))
        if ep.interrupted:
            self._partial = ep
            raise KeyboardInterrupt
        if last and cfg.render and draws:
            try:
                ep.frames = list(self.hooks.render(self, ep))
            except Exception as err:  # frames are optional
                logger.warning("rendering the final episode failed: %s", err)
        return ep

    def run_random_episode(self) -> Dict[str, Any]:
        """Collect one episode with random actions; builds the agent after the last one."""
        cfg = self.config
        number = len(self.episodes) + 1
        random_action = None
        if cfg.random_action_scale is not None:
            U = int(np.prod(self.make_env().action_space.shape))
            scale = float(cfg.random_action_scale)
            random_action = lambda g: g.uniform(-scale, scale, U)  # noqa: E731
        ep = self._interact(number, None, random_action)
        if self.agent is None and number >= cfg.random_episodes:
            self.episodes.append(ep)  # build_agent sees this episode's data
            try:
                self.agent = self.hooks.build_agent(self.training_data(), self.start_states())
            finally:
                self.episodes.pop()
        return self._add_episode(ep, {"interaction": ep.seconds}, {})

    def run_learned_episode(self) -> Dict[str, Any]:
        """Train the model, optimise the policy, run it for one episode, store everything.

        The episode runs ``hooks.watch(self, number, policy)``, the agent's policy
        ``x [D] -> u [U]`` or a wrapper that watches the states as they come (and may
        change the agent mid-episode, e.g. re-plan). Seconds it notes in
        ``policy_notes["paused_seconds"]`` (a pause to re-plan) count as policy time, not
        interaction; ``policy_notes["extra_evaluations"]`` as the episode's policy
        evaluations."""
        if self.agent is None:
            raise RuntimeError("no agent yet: run the random episodes first")
        number = len(self.episodes) + 1
        seconds: Dict[str, float] = {}
        cpu: Dict[str, float] = {}
        self._learning = True  # an interrupt until the search ends keeps the last agent.npz
        for phase, step in (("model", train_model), ("policy", learn_policy)):
            t0, c0 = time.perf_counter(), time.process_time()
            step(self, number)
            seconds[phase] = time.perf_counter() - t0
            cpu[phase] = time.process_time() - c0
            raise_if_stop_requested()
        self._learning = False
        self.cpu_seconds[number] = cpu
        evaluations = getattr(self.agent, "policy_evaluations", None)
        prediction = predictions_before(self)
        agent = self.agent

        def policy(x):  # the agent's policy of the moment (a watch may change it)
            return agent.compute_action(x)[0]

        ep = self._interact(number, self.hooks.watch(self, number, policy))
        paused = float(self.policy_notes.pop("paused_seconds", 0.0))
        seconds["interaction"] = ep.seconds - paused
        seconds["policy"] += paused
        prediction.update(predictions_after(self, ep))
        return self._add_episode(ep, seconds, prediction, evaluations)

    def run_episode(self) -> Dict[str, Any]:
        """The next episode: random while fewer than ``random_episodes``, else learned."""
        if len(self.episodes) < self.config.random_episodes:
            return self.run_random_episode()
        return self.run_learned_episode()

    # -- the run ------------------------------------------------------------------------
    @contextlib.contextmanager
    def session(self) -> Iterator["Experiment"]:
        """Time the session and, on Ctrl-C or SIGTERM, save everything and stop cleanly.

        A run without episodes writes its progress first, so that ``--resume`` finds its
        settings even after a kill in the first episode. After an interrupt
        ``self.interrupted`` is True and the block is left without the exception.
        """
        self._t_start = time.perf_counter()
        _warn_unless_portable()
        try:
            with sigterm_as_keyboard_interrupt():
                try:
                    if not self.episodes:
                        self.save_progress()
                    yield self
                    # a SIGTERM after the last safe point: everything is saved already
                    if stop_requested():
                        self.interrupted = True
                except KeyboardInterrupt:
                    self.interrupted = True
                    logger.warning("interrupted: saving %d episodes to %s%s", len(self.episodes),
                                   self.directory, " (the agent as the last episode left it: "
                                   "--resume redoes the episode in progress)"
                                   if self._learning else " and the agent")
                    with interrupts_deferred():
                        self.save()
        finally:
            self.wall_seconds = self.wall()
            self._t_start = None
            with contextlib.suppress(Exception):
                self.save_progress()

    def run(self) -> Dict[str, Any]:
        """Run (or continue) the episodes of the task's schedule (``hooks.before_episode``,
        by default until ``config.episodes``), calling ``hooks.after_episode`` after each
        and ``hooks.finished`` at its end; returns the summary."""
        self.complete = False
        with self.session():
            while self.hooks.before_episode(self, len(self.episodes) + 1):
                self.run_episode()
                self.hooks.after_episode(self, len(self.episodes))
                raise_if_stop_requested()
            self.complete = True
            self.hooks.finished(self)
        return self.summary()

    def close(self) -> None:
        """Close the environment."""
        if self.env is not None:
            with contextlib.suppress(Exception):
                self.env.close()
            self.env = None
