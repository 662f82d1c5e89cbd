"""The agent's raw transitions: the one source of the data its dynamics model learns from.

The dynamics model reads GP inputs (angles as sin, cos), from which raw angles cannot be
recovered, so the agent keeps the raw transitions ``(X [N, D + U], Y [N, D])`` for
:attr:`pilco.models.PILCO.data` and its files. :class:`Transitions` keeps both in step
whichever way data arrive:

- ``PILCO.set_data`` (raw data) sets both;
- ``agent.mgpr.set_data`` (GP inputs; also on a sparse model or on a model shared by
  several agents) is seen through the model's data listener: without angle dimensions the
  GP inputs are the raw data and are adopted; with angles data that do not match the raw
  transitions are refused with a :class:`ValueError` naming ``PILCO.set_data``;
- assigning ``agent.mgpr = model`` checks the model's data the same way;
- ``PILCO.set_gp_data`` gives GP inputs that need not come from any raw state (e.g. a
  reference model's inputs): the raw transitions are then unknown, and reading
  ``PILCO.data`` or saving the agent raises a :class:`ValueError` until ``set_data``.
"""
from __future__ import annotations

from typing import Sequence, Tuple

import numpy as np

from ..features import angle_features
from ..validation import check_data

__all__ = ["Transitions"]


class Transitions:
    """Raw transitions ``X [N, D + U]`` (``[x_t, u_t]``), ``Y [N, D]`` (``x_{t+1} - x_t``)
    of an agent with state size D and angle dimensions ``angle_indices``."""

    def __init__(self, X: np.ndarray, Y: np.ndarray, state_dim: int,
                 angle_indices: Sequence[int]):
        self.state_dim = state_dim
        self.angle_indices = tuple(angle_indices)
        self._X, self._Y = X, Y
        self._model = None
        self._raw_known = True
        self._accept_any = False

    @property
    def data(self) -> Tuple[np.ndarray, np.ndarray]:
        """Copies of ``(X [N, D + U], Y [N, D])``."""
        if not self._raw_known:
            raise ValueError("the agent's dynamics model holds GP inputs given by "
                             "PILCO.set_gp_data: its raw transitions are unknown (give them "
                             "to PILCO.set_data to save the agent or read PILCO.data)")
        return self._X.copy(), self._Y.copy()

    def gp_inputs(self, X) -> np.ndarray:
        """Raw ``[x, u]`` rows [N, D + U] -> GP inputs [N, F + U] (angles as sin, cos)."""
        X = np.asarray(X, dtype=np.float64)
        if not self.angle_indices:
            return X
        D = self.state_dim
        return np.concatenate([angle_features(X[:, :D], self.angle_indices), X[:, D:]], axis=1)

    def replace(self, model, data, noise_scales=None) -> None:
        """Set new raw transitions and the matching GP data of ``model`` (an MGPR), with
        ``noise_scales`` [N] (see ``MGPR.set_data``)."""
        X, Y = check_data(data, "data", x_dim=self._X.shape[1], y_dim=self.state_dim)
        old = self._X, self._Y, self._raw_known
        self._X, self._Y, self._raw_known = X, Y, True
        try:
            model.set_data((self.gp_inputs(X), Y), noise_scales=noise_scales)
        except BaseException:
            self._X, self._Y, self._raw_known = old
            raise

    def replace_gp_data(self, model, gp_data, noise_scales=None) -> None:
        """Give ``model`` GP data ``(X [N, F + U], Y [N, D])`` directly; without angle
        dimensions they are the raw transitions, with angles the raw ones become unknown."""
        self._accept_any = True
        try:
            model.set_data(gp_data, noise_scales=noise_scales)
        finally:
            self._accept_any = False
        if self.angle_indices:
            self._raw_known = False

    def attach(self, model) -> None:
        """Check that ``model`` holds these transitions' GP data (adopting its data when
        there are no angles), then follow its future ``set_data`` calls."""
        self.model_data_changed(np.asarray(model.X), np.asarray(model.Y))
        if self._model is not None:
            self._model.remove_data_listener(self.model_data_changed)
        model.add_data_listener(self.model_data_changed)
        self._model = model

    def model_data_changed(self, gp_X: np.ndarray, Y: np.ndarray) -> None:
        """Listener of the dynamics model's ``set_data``: ``gp_X [N, F + U]``, ``Y [N, D]``."""
        if not self.angle_indices:
            self._X, self._Y = np.array(gp_X, dtype=np.float64), np.array(Y, dtype=np.float64)
            return
        if self._accept_any or not self._raw_known:
            return
        if not (gp_X.shape == (len(self._X), gp_X.shape[1]) and Y.shape == self._Y.shape
                and np.array_equal(gp_X, self.gp_inputs(self._X)) and np.array_equal(Y, self._Y)):
            raise ValueError(
                f"the dynamics model of an agent with angle dimensions {list(self.angle_indices)} "
                f"cannot take GP inputs directly (raw angles cannot be recovered from sin and "
                f"cos): give the raw transitions to PILCO.set_data((X, Y)) instead (or GP "
                f"inputs without raw states to PILCO.set_gp_data)"
            )
