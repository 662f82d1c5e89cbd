"""Saving and loading PILCO agents, and exporting a trained policy for deployment.

Two file formats, both a single ``.npz`` (a zip of ``.npy`` arrays, read with
``allow_pickle=False``: no code objects are ever stored) holding a JSON metadata string
under the key ``__meta__`` (the layout is :mod:`pilco.models.storage`):

- **agent files** (:func:`save_agent` / :func:`load_agent`, ``format: "pilco-agent"``) keep
  everything needed to continue learning: the raw transitions, every hyperparameter of
  the dynamics GPs (and the inducing inputs of a sparse model), the controller's type,
  constructor settings and parameters, the reward (recursively for combined rewards),
  horizon, initial state distribution, angle indices and the other ``PILCO`` settings.
  A reloaded agent computes bit-identical predictions and actions.
- **policy files** (:func:`export_policy`, ``format: "pilco-policy"``) hold only what
  :func:`pilco.deploy.load_policy` needs to evaluate the deterministic action at a measured
  state with NumPy alone (no TensorFlow on the robot).

All writes are atomic (:mod:`pilco.files`): a crash never leaves a truncated file behind.
These functions are the same as the agent's ``save``, ``PILCO.load`` and
``export_policy`` methods.
"""
from __future__ import annotations

from .controllers import LinearController, RbfController
from .models import storage
from .models.pilco import PILCO
from .models.storage import AGENT_FORMAT, POLICY_FORMAT

__all__ = ["save_agent", "load_agent", "export_policy", "AGENT_FORMAT", "POLICY_FORMAT"]


def save_agent(agent: PILCO, path) -> str:
    """Write ``agent`` to the single file ``path`` (e.g. ``run/agent.npz``), atomically.

    Raises :class:`TypeError` for components that cannot be stored (custom controllers,
    rewards, squash functions or dynamics models). Returns the absolute path written.
    """
    if type(agent) is not PILCO:
        raise TypeError(f"save_agent expects a PILCO agent, got {type(agent).__name__}")
    return agent.save(path)


def load_agent(path) -> PILCO:
    """Rebuild an agent written by :func:`save_agent`; it predicts and acts identically."""
    return PILCO.load(path)


def export_policy(agent, path) -> str:
    """Write the policy of ``agent`` (a PILCO agent, or a bare controller) to ``path``.

    The file holds, as arrays: ``state_dim``, ``angle_indices`` [A], ``max_action`` [U],
    ``unsquashed_variance`` (the variance of the unsquashed action at a known state: the
    RBF policy's moment-matching jitter, 0 for the linear policy), and for an RBF policy
    ``centers`` [n, F], ``beta`` [U, n] (``(K + noise I)^-1 targets`` per output),
    ``targets`` [n, U], ``lengthscales`` [U, F], ``variance`` [U], ``noise`` [U]; for a
    linear policy ``W`` [U, F] and ``b`` [1, U]. ``F = D + A``: the policy reads the state
    with each angle replaced by (sin, cos), appended after the other dimensions. The JSON
    metadata names the controller kind (``rbf``/``linear``) and squash (``sin``/``sat``/
    ``none``). Read it with :func:`pilco.deploy.load_policy`. Returns the path written.
    """
    if isinstance(agent, PILCO):
        return agent.export_policy(path)
    if type(agent) not in (RbfController, LinearController):
        raise TypeError(f"export_policy expects a PILCO agent or a controller, got "
                        f"{type(agent).__name__}")
    return storage.export_policy(agent, path, agent.state_dim, [])
