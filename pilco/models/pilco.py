"""PILCO: policy search through analytic, moment-matched rollouts of a GP dynamics model.

:class:`PILCO` ties together the dynamics model (:class:`MGPR` or :class:`SMGPR`), a
controller and a reward (any objects following :mod:`pilco.protocols`), the initial state
distribution and the horizon. The compiled rollout is :class:`pilco.models.rollout.Rollout`,
the optimiser loop :func:`pilco.models.policy_search.search_policy`, the file layout
:mod:`pilco.models.storage`, the index sets of the state (angles, context, what the
dynamics model and the policy read) :class:`pilco.models.layout.StateLayout`. The agent's
predictions and actions are its base class :class:`pilco.models.predictions.AgentPredictions`,
its start-distribution properties :class:`pilco.models.agent_starts.AgentStarts`.

Multi-task PILCO (Deisenroth et al., ICRA 2014): declare the dimensions that hold the
task (e.g. the target position) as ``context_indices`` (constant through an episode,
read by the policy, not predicted) and give one start distribution per training task
(``m_init [T, D]``, each row holding its task's context): the policy objective is the
sum of the T tasks' expected returns.

Return types: the agent's user-facing methods (predictions, actions, expected returns)
return NumPy arrays (Python floats for single numbers) and run eagerly; the model, the
policy and the reward inside it (:class:`MGPR`, :mod:`pilco.controllers`,
:mod:`pilco.rewards`) are TensorFlow modules whose methods return tensors and run inside
``tf.function``.
"""
from __future__ import annotations

import logging
import time
from typing import Callable, List, Optional, Sequence

import gpflow
import numpy as np
from check_shapes import check_shapes

from ..runtime import reproducible_arithmetic
from ..seeding import generator
from ..validation import (
    check_bool,
    check_controller,
    check_min_rel_improvement,
    check_option,
    check_positive_int,
    check_reward,
    check_seed,
    check_transitions,
)
from . import storage
from .agent_starts import AgentStarts
from .layout import StateLayout
from .mgpr import MGPR
from .policy_search import GuardedScipy, search_policy
from .predictions import AgentPredictions
from .rollout import Rollout
from .smgpr import SMGPR
from .starts import check_starts
from .transitions import Transitions

__all__ = ["PILCO", "POLICY_METHODS"]


logger = logging.getLogger(__name__)

#: optimisers ``PILCO.optimize_policy`` accepts (scipy method names)
POLICY_METHODS = ("L-BFGS-B", "BFGS")


class PILCO(AgentPredictions, AgentStarts, gpflow.base.Module):
    """The PILCO agent: GP dynamics model, policy, reward and horizon.

    Args:
        data: raw transitions ``(X [N, D + U] = [x_t, u_t], Y [N, D] = x_{t+1} - x_t)``.
        controller: a policy (:class:`pilco.protocols.Controller`) with
            ``state_dim == D + len(angle_indices)`` (it reads the angle-augmented state;
            with ``policy_indices``: the features of those dimensions,
            :attr:`policy_dim`) and ``control_dim == U``.
        reward: a reward (:class:`pilco.protocols.Reward`) on the raw state
            (``state_dim == D``, context dimensions included).
        horizon: number of predicted steps in the policy objective.
        m_init: mean of the initial state [1, D] (default: the first state of ``data``),
            or T means [T, D], one start per task: the objective sums the T tasks'
            expected returns.
        S_init: covariance of the initial state [D, D] (default ``0.01 * I``), shared by
            all tasks, or one per task [T, D, D].
        angle_indices: state dimensions that are angles; the GP and the policy read the
            state with each angle replaced by its (sin, cos) pair, appended in order after
            the non-angle dimensions. The GP still predicts differences of the raw state.
        num_induced_points: if given, the dynamics model is a sparse :class:`SMGPR`.
        policy_input_noise: if True the policy sees ``s + diag(noise_variance) / 2``, a
            noisy measurement of the state; the default (False) feeds it the predicted
            state distribution itself, which is what the MATLAB reference reproduces.
        model_options: keyword arguments of the dynamics model's constructor
            (``noise_floor``, ``max_snr``, ``max_lengthscale_ratio``).
        context_indices: state dimensions that are constant through an episode (the
            task, e.g. a target position; not angles). They are not predicted: a
            predicted step keeps their mean and variance and carries their
            cross-covariances; the dynamics GPs (one per other dimension) do not read
            them unless ``dynamics_indices`` says so; the policy does.
        dynamics_indices: state dimensions whose features the dynamics GPs read (MATLAB
            ``dyni``; default: every non-context dimension).
        policy_indices: state dimensions whose features the policy reads (MATLAB
            ``poli``; default: all).

    See :class:`pilco.models.layout.StateLayout` for the index sets. Bad indices or
    starts raise ValueError naming the problem, before TensorFlow sees them.

    Building an agent turns TensorFlow's Grappler arithmetic optimizer off for the
    process (:func:`pilco.runtime.reproducible_arithmetic`): with it on, the policy
    objective's gradient depends on the executor's scheduling, so the same agent gave
    other bits in another process.
    """

    def __init__(self, data, controller, reward, horizon: int = 30, m_init=None, S_init=None,
                 angle_indices: Sequence[int] = (), num_induced_points: Optional[int] = None,
                 policy_input_noise: bool = False, model_options: Optional[dict] = None,
                 name: Optional[str] = None, context_indices: Sequence[int] = (),
                 dynamics_indices: Optional[Sequence[int]] = None,
                 policy_indices: Optional[Sequence[int]] = None):
        super().__init__(name=name)
        reproducible_arithmetic()
        X, Y = check_transitions(data, "data")
        self.state_dim = D = Y.shape[1]
        self.control_dim = U = X.shape[1] - D
        self.layout = StateLayout(D, angle_indices, context_indices, dynamics_indices,
                                  policy_indices)
        self.angle_indices = self.layout.angle_indices
        self.feature_dim = D + len(self.angle_indices)
        self._check_controller(controller)
        check_reward(reward, D)
        self.policy_input_noise = check_bool(policy_input_noise, "policy_input_noise")
        horizon = check_positive_int(horizon, "horizon")
        self.num_induced_points = num_induced_points
        m0 = X[0:1, :D] if m_init is None else m_init
        S0 = 0.01 * np.eye(D) if S_init is None else S_init
        m0, S0, self._shared_S = check_starts(m0, S0, D, "initial state")
        self._transitions = Transitions(X, Y, self.layout)
        gp_data = self._transitions.gp_data(X, Y)
        options = dict(model_options or {})
        if num_induced_points is None:
            self.mgpr = MGPR(gp_data, **options)
        else:
            self.mgpr = SMGPR(gp_data, num_induced_points, **options)

        self._rollout = Rollout(controller, reward, self.layout, U, self.policy_input_noise,
                                horizon, m0, S0)
        self._drop_compiled()

    def _drop_compiled(self) -> None:
        """Forget the policy optimisers' compiled objectives (TensorFlow graph and XLA):
        they are traces of the controller, reward and starts they saw."""
        self._policy_optimizer = GuardedScipy()
        self._xla_optimizer = GuardedScipy()
        self._mixture_optimizer = GuardedScipy()  # the start mixture's objective
        self._xla_mixture_optimizer = GuardedScipy()
        self._points_optimizer = GuardedScipy()  # the objective with start points
        self._xla_points_optimizer = GuardedScipy()

    def _check_controller(self, controller):
        """``controller`` follows the protocol, reads the policy's features and returns U
        actions (:func:`pilco.validation.check_controller`, whose size message is about
        angles: a subset of dimensions from ``policy_indices`` is reported here)."""
        layout = self.layout
        size = getattr(controller, "state_dim", None)
        if (layout.policy_pick is not None and isinstance(size, (int, np.integer))
                and size != layout.policy_dim):
            raise ValueError(
                f"controller.state_dim is {size} but the policy input has dimension "
                f"{layout.policy_dim} (the features of policy_indices "
                f"{list(layout.policy_indices)}: one per dimension, two per angle)")
        return check_controller(controller, layout.policy_dim, self.control_dim,
                                self.state_dim)

    # -- properties ---------------------------------------------------------------------
    @property
    def controller(self):
        """The policy (:class:`pilco.protocols.Controller`)."""
        return self._rollout.controller

    @controller.setter
    def controller(self, value):
        self._rollout.controller = self._check_controller(value)
        self._drop_compiled()  # its compiled objective saw the old one

    def retrace(self) -> None:
        """Drop the compiled policy objective, trajectory and action functions, so that the
        next call traces them again. Needed after changing a plain attribute that a trace
        holds as a constant, e.g. ``controller.max_action``: assigning the same controller
        (or reward) object again does nothing, as for any TensorFlow module attribute."""
        self._rollout.retrace()
        self._drop_compiled()  # its compiled objective is a trace too

    @property
    def reward(self):
        """The reward (:class:`pilco.protocols.Reward`)."""
        return self._rollout.reward

    @reward.setter
    def reward(self, value):
        self._rollout.reward = check_reward(value, self.state_dim)
        self._drop_compiled()  # its compiled objective saw the old one

    @property
    def horizon(self) -> int:
        return int(self._rollout.horizon.numpy())

    @horizon.setter
    def horizon(self, value: int):
        if self._rollout.set_horizon(check_positive_int(value, "horizon")):
            # their traces have the horizon as a constant
            self._xla_optimizer = GuardedScipy()
            self._xla_mixture_optimizer = GuardedScipy()
            self._xla_points_optimizer = GuardedScipy()

    @property
    def context_indices(self):
        """The context dimensions (constant through an episode, not predicted)."""
        return self.layout.context_indices

    @property
    def dynamics_indices(self):
        """The state dimensions whose features the dynamics GPs read."""
        return self.layout.dynamics_indices

    @property
    def policy_indices(self):
        """The state dimensions whose features the policy reads."""
        return self.layout.policy_indices

    @property
    def policy_dim(self) -> int:
        """The policy's input size (its ``state_dim``): the features of
        :attr:`policy_indices` (``feature_dim`` when the policy reads every dimension)."""
        return self.layout.policy_dim

    @property
    def mgpr(self) -> MGPR:
        """The dynamics model: GP inputs [N, Fd + U] (the features of
        :attr:`dynamics_indices`, then the actions) -> differences of the predicted
        (non-context) dimensions [N, E]; without context and index sets Fd = F and
        E = D."""
        return self._mgpr

    @mgpr.setter
    def mgpr(self, model: MGPR):
        self._transitions.attach(model)  # checks (or, without angles, adopts) its data
        self._mgpr = model

    @property
    def data(self):
        """Raw transitions ``(X [N, D + U], Y [N, D])`` as NumPy arrays (copies)."""
        return self._transitions.data

    # -- data -------------------------------------------------------------------------------
    def gp_inputs(self, X) -> np.ndarray:
        """Raw ``[x, u]`` rows [N, D + U] -> GP inputs [N, Fd + U] (angles as sin, cos;
        only the dynamics dimensions)."""
        return self._transitions.gp_inputs(X)

    def set_data(self, data, noise_scales=None):
        """Replace the transitions ``(X [N, D + U], Y [N, D])`` the dynamics model learns
        from. ``noise_scales [N]``: a positive factor of each transition's noise variance
        (None: all ones); a large one down-weights a transition, e.g. the data of a robot
        before it was damaged; ``[D, N]``: one factor per state dimension's GP and
        transition (``MGPR.set_data``)."""
        self._transitions.replace(self.mgpr, data, noise_scales)

    def set_gp_data(self, gp_data, noise_scales=None):
        """Give the dynamics model GP inputs and targets ``(X [N, Fd + U], Y [N, E])``
        directly (angles as sin, cos columns that need not come from any angle). With angle
        or context dimensions (or ``dynamics_indices``) the raw transitions are then
        unknown: :attr:`data` and :meth:`save` raise a ValueError until :meth:`set_data`
        gives raw ones. ``noise_scales``: as in :meth:`set_data`."""
        self._transitions.replace_gp_data(self.mgpr, gp_data, noise_scales)

    # -- learning ---------------------------------------------------------------------------
    def optimize_models(self, maxiter: int = 1000, restarts: int = 1, seed: Optional[int] = None,
                        callback: Optional[Callable[[int], None]] = None,
                        min_rel_improvement: Optional[float] = None, patience: int = 10):
        """Train the dynamics GPs by evidence maximisation; returns per-output losses [E].

        ``callback(iteration)`` is called after every L-BFGS iteration; ``min_rel_improvement``
        and ``patience`` stop a stalled run early (see :meth:`MGPR.optimize`).
        """
        t0 = time.perf_counter()
        losses = self.mgpr.optimize(maxiter=maxiter, restarts=restarts, seed=seed,
                                    callback=callback, min_rel_improvement=min_rel_improvement,
                                    patience=patience)
        logger.info("dynamics model trained in %.2f s", time.perf_counter() - t0)
        return losses

    def expected_return(self) -> float:
        """Total expected reward of the current policy from the initial state distribution
        (summed over the tasks when there are several): minus the policy objective."""
        self._rollout.refresh(self.mgpr)
        return float(-self._rollout.policy_loss().numpy())

    @check_shapes("return: [T]")
    def expected_returns(self) -> np.ndarray:
        """Total expected reward of the current policy from each task's start
        distribution: [T] (their sum is :meth:`expected_return`)."""
        self._rollout.refresh(self.mgpr)
        return np.array([float(t.numpy()[0, 0]) for t in self._rollout.task_totals()])

    def optimize_policy(self, maxiter: int = 50, restarts: int = 1, seed: Optional[int] = None,
                        callback: Optional[Callable[[int], None]] = None,
                        method: str = "L-BFGS-B", min_rel_improvement: Optional[float] = None,
                        patience: int = 10, jit_compile: bool = False):
        """Maximise the predicted total reward (summed over the tasks) over the policy
        parameters; returns the best total reward. The best policy evaluated by any run is
        kept (see :func:`pilco.models.policy_search.search_policy` for restarts, failures
        and interruptions).

        ``method`` is ``"L-BFGS-B"`` or ``"BFGS"`` (a dense inverse-Hessian update, what
        the MATLAB release's ``minimize`` uses for up to 1000 parameters).
        ``callback(iteration)`` is called after every iteration (an exception it raises
        stops the optimisation). With ``min_rel_improvement`` set, a run stops once its best
        expected return has grown by less than ``min_rel_improvement * max(1, |return|)``
        over the last ``patience`` iterations.

        With ``jit_compile`` the objective and its gradient are compiled whole by XLA
        (:meth:`pilco.models.rollout.Rollout.xla_policy_loss`; the dynamics model padded to
        a few fixed sizes, so a run compiles once per size bucket, and a persistent
        compilation cache, see :func:`pilco.runtime.use_xla_cache`, makes later
        runs start warm). It removes TensorFlow's per-operation overhead, which dominates
        small problems (the cart-pole); the values agree with the graph's up to rounding,
        so runs take other paths.
        """
        maxiter = check_positive_int(maxiter, "maxiter")
        restarts = check_positive_int(restarts, "restarts")
        patience = check_positive_int(patience, "patience")
        method = check_option(method, POLICY_METHODS, "method", ignore_case=True)
        min_rel_improvement = check_min_rel_improvement(min_rel_improvement)
        rng = generator(check_seed(seed))
        if restarts > 1 and not callable(getattr(self.controller, "randomize", None)):
            raise ValueError(f"restarts > 1 needs a controller with a randomize(seed=...) "
                             f"method; {type(self.controller).__name__} has none")
        jit_compile = check_bool(jit_compile, "jit_compile")
        self._rollout.refresh(self.mgpr, pad=jit_compile)
        ro = self._rollout
        objective = ("mixture" if self.start_spread is not None
                     else "points" if (self.start_points is not None
                                       or self.start_scale is not None) else "plain")
        if jit_compile:
            loss, optimizer = {
                "mixture": (ro.xla_mixture_policy_loss, self._xla_mixture_optimizer),
                "points": (ro.xla_points_policy_loss, self._xla_points_optimizer),
                "plain": (ro.xla_policy_loss, self._xla_optimizer)}[objective]
        else:
            loss, optimizer = {
                "mixture": (ro.mixture_policy_loss, self._mixture_optimizer),
                "points": (ro.points_policy_loss, self._points_optimizer),
                "plain": (ro.plain_policy_loss, self._policy_optimizer)}[objective]
        self._last_search = optimizer
        return search_policy(loss, self.controller, optimizer, maxiter, restarts, rng, method,
                             callback, min_rel_improvement, patience, jit_compile=jit_compile)

    @property
    def policy_evaluations(self) -> int:
        """Objective + gradient evaluations of the last :meth:`optimize_policy` (all its
        restarts; 0 before the first)."""
        last = getattr(self, "_last_search", None)
        return 0 if last is None else int(last.evaluations)

    @property
    def policy_run_returns(self) -> List[float]:
        """The best expected return of each run of the last :meth:`optimize_policy`, in
        order (run 0 started from the policy in place, the others from
        ``controller.randomize``); ``-inf`` for a run without a finite evaluation; empty
        before the first search."""
        last = getattr(self, "_last_search", None)
        return [] if last is None else [-float(loss) for loss, _ in last.runs]

    def use_policy_run(self, run: int) -> float:
        """Put the best policy of run ``run`` (an index into :attr:`policy_run_returns`)
        of the last :meth:`optimize_policy` in place of the policy it left; returns that
        run's expected return. A ``ValueError`` if there is no such run or it evaluated no
        finite point."""
        returns = self.policy_run_returns
        if isinstance(run, bool) or not isinstance(run, (int, np.integer)) \
                or not 0 <= run < len(returns):
            raise ValueError(f"run must be an index into the last policy search's "
                             f"{len(returns)} run(s), got {run!r}")
        if not np.isfinite(returns[run]):
            raise ValueError(f"policy search run {run} evaluated no finite point")
        self._last_search.restore_run_best(self.controller.trainable_variables, int(run))
        return returns[run]

    # -- files ------------------------------------------------------------------------------
    def save(self, path) -> str:
        """Write everything needed to continue learning to ``path`` (atomically); returns
        the absolute path written. Layout: :func:`pilco.models.storage.agent_arrays`."""
        return storage.save_agent(self, path)

    @classmethod
    def load(cls, path) -> "PILCO":
        """Rebuild an agent written by :meth:`save`; it predicts and acts identically."""
        return storage.load_agent(cls, path)

    def export_policy(self, path) -> str:
        """Write the trained policy to a small ``.npz`` for :func:`pilco.deploy.load_policy`;
        returns the absolute path written. A policy reading a subset of the state
        (``policy_indices``) cannot be exported yet: policy files feed it every feature."""
        if self.layout.policy_pick is not None:
            raise ValueError(
                f"cannot export a policy that reads only the state dimensions "
                f"{list(self.policy_indices)} (policy_indices): policy files and "
                f"pilco.deploy feed the policy every feature of the state")
        return storage.export_policy(self.controller, path, self.state_dim, self.angle_indices)
