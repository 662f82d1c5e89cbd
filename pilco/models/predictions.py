"""What the agent predicts and does: one GP step, moment-matched horizons, trajectories, actions.

:class:`AgentPredictions` holds these methods of :class:`pilco.models.pilco.PILCO` (its
base class): one-step GP predictions, moment-matched steps, horizons and trajectories
from a start distribution, and the policy's action at measured states. They read the
agent's ``mgpr``, ``layout``, ``state_dim``, ``horizon``, ``num_tasks`` and compiled
:class:`~pilco.models.rollout.Rollout`. Inputs are checked (:mod:`pilco.validation`)
before TensorFlow sees them; the results are NumPy arrays.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Optional

import numpy as np
import tensorflow as tf
from check_shapes import check_shapes

from ..validation import (
    check_columns,
    check_gaussian,
    check_positive_int,
    check_states,
    checked_arguments,
)
from .starts import check_task

if TYPE_CHECKING:
    from .pilco import PILCO

__all__ = ["AgentPredictions"]

#: shapes of a Gaussian state m [1, D], s [D, D] mapped to the next (or the last) one
_STEP_SHAPES = ("m: [1, D]", "s: [D, D]", "return[0]: [1, D]", "return[1]: [D, D]")
#: shapes of a Gaussian start mapped to its predicted states 0..H
_TRAJECTORY_SHAPES = ("m: [1, D]", "s: [D, D]", "return[0]: [H1, D]", "return[1]: [H1, D, D]")


def _check_start(agent: "PILCO", arguments) -> None:
    """The start of a prediction checked, the missing half from the task's start."""
    m, s = agent._start(arguments["m"], arguments["s"], arguments["task"])
    arguments.update(m=m, s=s, task=None)


def _check_state_gaussian(agent: "PILCO", arguments) -> None:
    arguments["m"], arguments["s"] = check_gaussian(arguments["m"], arguments["s"],
                                                    agent.state_dim, "state")


def _check_transition_inputs(agent: "PILCO", arguments) -> None:
    arguments["X"] = check_columns(arguments["X"], agent.state_dim + agent.control_dim, "X",
                                   "(state, then action)")


def _check_measured_states(agent: "PILCO", arguments) -> None:
    x = check_states(arguments["x"], agent.state_dim, "state")
    arguments["x"] = x.reshape(1, -1) if x.ndim == 1 else x


class AgentPredictions:
    """The predicting and acting methods of :class:`~pilco.models.pilco.PILCO`."""

    # -- one step of the GP -----------------------------------------------------------------
    @checked_arguments(_check_transition_inputs)
    @check_shapes(
        "X: [N, DU]",
        "return[0]: [N, D]",
        "return[1]: [N, D]",
    )
    def one_step_prediction(self, X):
        """Predicted state differences ``x_{t+1} - x_t`` at raw transition inputs.

        Shapes: X [N, D + U] (raw states, angles as angles, then actions) -> mean [N, D],
        variance [N, D] (NumPy), the GP's latent variance plus its noise variance (0 and
        0 in the context dimensions, which do not change).
        """
        mean, var = self.mgpr.predict_f(self.gp_inputs(X))
        var = np.asarray(var) + np.asarray(self.mgpr.noise_variance)
        return self.layout.to_state(np.asarray(mean)), self.layout.to_state(var)

    # -- from a start distribution ----------------------------------------------------------
    def _start(self, m, s, task):
        """The start of a prediction checked: ``m``, ``s`` as given, the missing ones
        from the start distribution of ``task`` (which may be omitted with one task)."""
        if m is None or s is None:
            if task is None:
                if self.num_tasks > 1:
                    raise ValueError(
                        f"the agent has {self.num_tasks} start distributions (tasks): pass "
                        f"task=i or the start (m, s) to predict from")
                task = 0
            task = check_task(task, self.num_tasks)
            if m is None:
                m = self._rollout.m_init.numpy()[task : task + 1]
            if s is None:
                s = self._rollout.S_init.numpy()[task]
        elif task is not None:
            raise ValueError("give either task or the start (m, s), not both")
        return check_gaussian(m, s, self.state_dim, "initial state")

    def _horizon_tensor(self, horizon):
        H = self.horizon if horizon is None else check_positive_int(horizon, "horizon")
        self._rollout.refresh(self.mgpr)
        return tf.constant(H)

    @checked_arguments(_check_state_gaussian)
    @check_shapes(*_STEP_SHAPES)
    def propagate(self, m, s):
        """One predicted step. Shapes: m [1, D], s [D, D] -> m' [1, D], s' [D, D]."""
        self._rollout.refresh(self.mgpr)
        out = self._rollout.step(m, s, self._rollout.dynamics(), self.controller.prepare())
        return tuple(t.numpy() for t in out)

    @checked_arguments(_check_start)
    @check_shapes(*_STEP_SHAPES, "return[2]: [1, 1]")
    def predict(self, m=None, s=None, horizon: Optional[int] = None,
                task: Optional[int] = None):
        """Predicted final state and total expected reward of steps 1..H.

        Shapes: m [1, D], s [D, D] (default: the start distribution of ``task``, which
        may be omitted when there is one) -> m_H [1, D], S_H [D, D], total_reward [1, 1].
        """
        out = self._rollout.total_reward(m, s, self._horizon_tensor(horizon))
        return tuple(t.numpy() for t in out)

    @checked_arguments(_check_start)
    @check_shapes(*_TRAJECTORY_SHAPES)
    def predict_trajectory(self, m=None, s=None, horizon: Optional[int] = None,
                           task: Optional[int] = None):
        """Predicted state distributions of steps 0..H.

        Shapes: m [1, D], s [D, D] -> M [H+1, D], S [H+1, D, D] (index 0 is the start);
        defaults as :meth:`predict`.
        """
        M, S, _, _ = self.predict_trajectory_with_rewards(m, s, horizon)
        return M, S

    @checked_arguments(_check_start)
    @check_shapes(*_TRAJECTORY_SHAPES, "return[2]: [H1]", "return[3]: [H1]")
    def predict_trajectory_with_rewards(self, m=None, s=None, horizon: Optional[int] = None,
                                        task: Optional[int] = None):
        """As :meth:`predict_trajectory`, plus the reward mean [H+1] and variance [H+1]."""
        out = self._rollout.trajectory(m, s, self._horizon_tensor(horizon))
        return tuple(t.numpy() for t in out)

    # -- acting -----------------------------------------------------------------------------
    @checked_arguments(_check_measured_states)
    @check_shapes(
        "x: [N, D]",
        "return: [N, U]",
    )
    def compute_action(self, x) -> np.ndarray:
        """The policy's action at measured states: x [N, D] -> u [N, U], one state [D]
        or [1, D] -> [1, U] (the whole state, context included; the policy reads its
        dimensions). The same actions as the exported policy
        (:func:`pilco.deploy.load_policy`), row by row."""
        rows = [self._rollout.action(tf.convert_to_tensor(row[None, :])).numpy() for row in x]
        return np.concatenate(rows, axis=0)
