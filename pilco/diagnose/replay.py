"""The agent as it was when a learned episode ran: its dynamics model (fitted on the
data of the episodes before it) and its policy (the one that ran it).

The run saves its agent after adding an episode's data and before fitting the next model,
so for the last episode ``agent.npz`` with its data cut back is exact; an earlier episode's
agent is rebuilt by replaying the run's learning with its own settings and seeds (the
experiment's own model and policy phases, :mod:`pilco.experiment.learning`, and the task's
hooks' ``before_replayed_episode``). Either way the policy
is checked against the actions the episode recorded (:func:`action_error`).
"""
from __future__ import annotations

import copy
import logging
import time

import numpy as np

from ..experiment.episode import Episode
from ..experiment.learning import learn_policy, train_model

__all__ = ["view_before", "action_error", "replay_learning", "agent_of_episode"]

logger = logging.getLogger(__name__)


def view_before(exp, done: int):
    """A shallow copy of ``exp`` that has collected only its first ``done`` episodes (the
    learning phases of episode ``done + 1`` see what they saw during the run)."""
    view = copy.copy(exp)
    view.episodes = list(exp.episodes[:done])
    view.records = list(exp.records[:done])
    view.predictions = list(exp.predictions[:done])
    view.model_trained_on = None
    return view


def action_error(agent, episode: Episode) -> float:
    """Largest difference between the agent's actions at an episode's states and the
    actions the episode applied (0 when the agent holds the policy that ran it)."""
    if episode.steps == 0:
        return 0.0
    actions = np.vstack([agent.compute_action(x[None]) for x in episode.states[:-1]])
    return float(np.max(np.abs(actions - episode.actions)))


def replay_learning(exp, episode: int):
    """Repeat the run's learning up to episode ``episode``'s policy: build the agent on
    the random episodes with the task's ``exp.hooks.build_agent``, then for every learned
    episode j <= ``episode`` fit the model on the data of episodes before j and optimise the
    policy, with the run's settings and seeds; the task's
    ``exp.hooks.before_replayed_episode(exp, view, j)`` runs before each fit. Returns the
    view of ``exp`` (:func:`view_before`) holding the agent; on the same arithmetic the
    policy is the run's own (see :func:`action_error`)."""
    first = exp.config.random_episodes
    view = view_before(exp, first)
    try:
        view.agent = exp.hooks.build_agent(view.training_data(), view.start_states())
    except NotImplementedError as err:
        raise ValueError(f"replaying a run's learning needs its agent builder (the "
                         f"task's): {err}") from err
    for j in range(first + 1, episode + 1):
        t0 = time.perf_counter()
        view.episodes = list(exp.episodes[: j - 1])
        view.records = list(exp.records[: j - 1])
        view.give_agent_data(view.agent)
        exp.hooks.before_replayed_episode(exp, view, j)
        train_model(view, j)
        learn_policy(view, j)
        logger.info("replayed the model fit and policy optimisation of episode %d in %.1f s",
                    j, time.perf_counter() - t0)
    return view


def agent_of_episode(exp, episode: int, replay: bool = False, tolerance: float = 1e-6):
    """The model and policy of learned episode ``episode`` (1-based): ``(view, info)``.

    ``view`` is :func:`view_before` of ``exp`` before that episode, ``view.agent`` the agent
    whose dynamics model is the one fitted for the episode (on the data of the episodes
    before it) and whose policy is the one that ran it. For the last episode the saved
    ``agent.npz`` is exactly that once its data are cut back to the episodes before it
    (the run saves the agent after adding the episode's data, without refitting), unless
    the run stopped later in the learning phases: its policy must reproduce the episode's
    actions to ``tolerance``. Otherwise (or with ``replay``) the learning is replayed with
    :func:`replay_learning`. ``info``: ``source`` ("agent.npz" or "replay") and
    ``action_error`` (:func:`action_error` against the recorded actions).
    """
    records = exp.records
    if not 1 <= episode <= len(exp.episodes) or records[episode - 1]["random"]:
        raise ValueError(f"episode {episode} is not a learned episode of this run "
                         f"(learned: {[r['episode'] for r in records if not r['random']]})")
    ep = exp.episodes[episode - 1]
    view = view_before(exp, episode - 1)
    if not replay and episode == len(exp.episodes):
        agent = exp.store.load_agent()
        if agent is not None:
            view.give_agent_data(agent)
            err = action_error(agent, ep)
            if err <= tolerance:
                view.agent = agent
                return view, {"source": "agent.npz", "action_error": err}
            logger.warning("the saved agent's policy did not run episode %d (actions differ by "
                           "up to %.3g); replaying the run's learning instead", episode, err)
    logger.info("replaying the run's learning up to episode %d", episode)
    view = replay_learning(exp, episode)
    err = action_error(view.agent, ep)
    if err > tolerance:
        logger.warning("the replayed policy differs from the run's (actions differ by up to "
                       "%.3g; another machine or thread count changes the optimiser's "
                       "path%s): the diagnosis is of the replayed policy", err,
                       _arithmetic_hint(exp))
    return view, {"source": "replay", "action_error": err}


def _arithmetic_hint(exp) -> str:
    """When the run did not record the portable arithmetic (:mod:`pilco.portable`) and this
    process runs it, how to replay with the run's own."""
    from ..portable import SWITCH, arithmetic_state

    try:
        ran = exp.store.load_summary().get("provenance", {}).get("arithmetic") or {}
    except (OSError, ValueError, AttributeError):
        return ""
    if ran.get("portable") is True or arithmetic_state()["portable"] is not True:
        return ""
    return (f"; the run did not run the portable arithmetic this process runs: "
            f"{SWITCH}=0 replays with its CPU's own")
