"""The agent's raw transitions: the one source of the data its dynamics model learns from.

The dynamics model reads GP inputs (angles as sin, cos; only the dimensions of the
agent's ``dynamics_indices``, see :class:`~pilco.models.layout.StateLayout`) and
predicts the non-context dimensions; raw states cannot be recovered from them, so the
agent keeps the raw transitions ``(X [N, D + U], Y [N, D])`` for
:attr:`pilco.models.PILCO.data` and its files. :class:`Transitions` keeps both in step
whichever way data arrive:

- ``PILCO.set_data`` (raw data) sets both;
- ``agent.mgpr.set_data`` (GP inputs; also on a sparse model or on a model shared by
  several agents) is seen through the model's data listener: when the layout is the
  identity (no angles, no context, the GP reads every dimension) the GP inputs are the
  raw data and are adopted; otherwise data that do not match the raw transitions are
  refused with a :class:`ValueError` naming ``PILCO.set_data``;
- assigning ``agent.mgpr = model`` checks the model's data the same way;
- ``PILCO.set_gp_data`` gives GP inputs and targets ``(X [N, Fd + U], Y [N, E])`` that
  need not come from any raw state (e.g. a reference model's inputs): the raw
  transitions are then unknown, and reading
  ``PILCO.data`` or saving the agent raises a :class:`ValueError` until ``set_data``.
"""
from __future__ import annotations

import logging
from typing import Tuple

import numpy as np

from ..validation import check_data
from .layout import StateLayout

__all__ = ["Transitions"]

logger = logging.getLogger(__name__)


class Transitions:
    """Raw transitions ``X [N, D + U]`` (``[x_t, u_t]``), ``Y [N, D]`` (``x_{t+1} - x_t``)
    of an agent whose state has the index sets ``layout`` (a :class:`StateLayout`)."""

    def __init__(self, X: np.ndarray, Y: np.ndarray, layout: StateLayout):
        self.layout = layout
        self.state_dim = layout.state_dim
        self._X, self._Y = X, Y
        self._model = None
        self._raw_known = True
        self._accept_any = False
        self.check_context(Y)

    @property
    def data(self) -> Tuple[np.ndarray, np.ndarray]:
        """Copies of ``(X [N, D + U], Y [N, D])``."""
        if not self._raw_known:
            raise ValueError("the agent's dynamics model holds GP inputs given by "
                             "PILCO.set_gp_data: its raw transitions are unknown (give them "
                             "to PILCO.set_data to save the agent or read PILCO.data)")
        return self._X.copy(), self._Y.copy()

    def gp_inputs(self, X) -> np.ndarray:
        """Raw ``[x, u]`` rows [N, D + U] -> GP inputs [N, Fd + U] (the features of the
        dynamics dimensions, angles as sin, cos; then the actions)."""
        return self.layout.gp_inputs(X)

    def gp_data(self, X, Y) -> Tuple[np.ndarray, np.ndarray]:
        """Raw transitions -> the dynamics model's data ``(X [N, Fd + U], Y [N, E])``."""
        return self.layout.gp_inputs(X), self.layout.gp_targets(Y)

    def check_context(self, Y: np.ndarray) -> None:
        """Warn when a context dimension changes within a transition (``Y [N, D]``): the
        model takes it as constant and ignores that column."""
        context = list(self.layout.context_indices)
        if not context or not len(Y):
            return
        change = np.max(np.abs(Y[:, context]), axis=0)
        if np.any(change > 0):
            moved = {d: float(c) for d, c in zip(context, change) if c > 0}
            logger.warning("context dimensions change within transitions (largest |x_{t+1} "
                           "- x_t| per dimension: %s); the dynamics model takes them as "
                           "constant through an episode", moved)

    def replace(self, model, data, noise_scales=None) -> None:
        """Set new raw transitions and the matching GP data of ``model`` (an MGPR), with
        ``noise_scales`` [N] (see ``MGPR.set_data``)."""
        X, Y = check_data(data, "data", x_dim=self._X.shape[1], y_dim=self.state_dim)
        self.check_context(Y)
        old = self._X, self._Y, self._raw_known
        self._X, self._Y, self._raw_known = X, Y, True
        try:
            model.set_data(self.gp_data(X, Y), noise_scales=noise_scales)
        except BaseException:
            self._X, self._Y, self._raw_known = old
            raise

    def replace_gp_data(self, model, gp_data, noise_scales=None) -> None:
        """Give ``model`` GP data ``(X [N, Fd + U], Y [N, E])`` directly; when the layout is
        the identity they are the raw transitions, otherwise the raw ones become unknown."""
        self._accept_any = True
        try:
            model.set_data(gp_data, noise_scales=noise_scales)
        finally:
            self._accept_any = False
        if not self.layout.is_identity:
            self._raw_known = False

    def attach(self, model) -> None:
        """Check that ``model`` has the layout's input and output sizes and holds these
        transitions' GP data (adopting its data when the layout is the identity), then
        follow its future ``set_data`` calls."""
        inputs = self.layout.gp_state_dim + self._X.shape[1] - self.state_dim
        outputs = self.layout.num_outputs
        if (getattr(model, "num_dims", inputs), getattr(model, "num_outputs", outputs)) != (
                inputs, outputs):
            raise ValueError(
                f"the dynamics model maps {model.num_dims} inputs to {model.num_outputs} "
                f"outputs, but this agent's GP reads {inputs} (state features, then actions) "
                f"and predicts {outputs} state dimensions")
        self.model_data_changed(np.asarray(model.X), np.asarray(model.Y))
        if self._model is not None:
            self._model.remove_data_listener(self.model_data_changed)
        model.add_data_listener(self.model_data_changed)
        self._model = model

    def model_data_changed(self, gp_X: np.ndarray, Y: np.ndarray) -> None:
        """Listener of the dynamics model's ``set_data``: ``gp_X [N, Fd + U]``, ``Y [N, E]``."""
        if self.layout.is_identity:
            self._X, self._Y = np.array(gp_X, dtype=np.float64), np.array(Y, dtype=np.float64)
            return
        if self._accept_any or not self._raw_known:
            return
        X_expected, Y_expected = self.gp_data(self._X, self._Y)
        if not (gp_X.shape == X_expected.shape and Y.shape == Y_expected.shape
                and np.array_equal(gp_X, X_expected) and np.array_equal(Y, Y_expected)):
            raise ValueError(
                f"the dynamics model of an agent with {self.layout.describe()} cannot take GP "
                f"data directly (raw states cannot be recovered from its inputs): give the "
                f"raw transitions to PILCO.set_data((X, Y)) instead (or GP data without raw "
                f"states to PILCO.set_gp_data)"
            )
