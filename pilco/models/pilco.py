"""PILCO: policy search through analytic, moment-matched rollouts of a GP dynamics model.

One step of the rollout (MATLAB PILCO's ``propagate``) maps the state distribution
``x_t ~ N(m, s)`` to ``x_{t+1}``:

1. angles are replaced by (sin, cos) features, giving the GP/policy input ``z``;
2. the policy returns ``u ~ N(Mu, Su)`` for the state distribution (optionally it sees a
   noisy measurement ``s + diag(noise) / 2``, ``noise`` being the dynamics GPs'
   likelihood variances, as some MATLAB PILCO versions do);
3. the dynamics GPs predict the state difference ``Δ`` at ``[z, u]``;
4. ``x_{t+1} = x_t + Δ`` with every cross-covariance kept.

The whole horizon is one ``tf.while_loop`` inside a compiled function, traced once; the
dynamics GP factorisations (Cholesky, ``beta``, ``K^-1`` and the pair weights of the
output covariance) do not depend on the policy and are computed once per policy
optimisation, then read from non-trainable variables.
"""
from __future__ import annotations

import logging
import time
from typing import Callable, Optional, Sequence

import gpflow
import numpy as np
import tensorflow as tf
from gpflow.config import default_float

from .. import moments
from ..angles import augment_state
from ..snapshots import Stalled, TrackingScipy, restore, snapshot
from ..validation import (
    _to_numpy,
    as_2d_float,
    check_bool,
    check_covariance,
    check_data,
    check_gaussian,
    check_indices,
    check_min_rel_improvement,
    check_positive_int,
    check_seed,
)
from .mgpr import MGPR
from .smgpr import SMGPR

__all__ = ["PILCO", "POLICY_METHODS"]

logger = logging.getLogger(__name__)

#: optimisers ``PILCO.optimize_policy`` accepts (scipy method names)
POLICY_METHODS = ("L-BFGS-B", "BFGS")


class _GuardedScipy(TrackingScipy):
    """GPflow's Scipy optimiser that survives numerical failures and remembers its best point.

    A trial point far out (a collapsed lengthscale, say) can make the rollout's linear
    algebra fail or its value NaN. Reporting a very large loss there, instead of raising
    or returning NaN, makes the line search step back and the run go on; each such point
    is counted in ``failures``. Every finite evaluation is compared with the best so far,
    so the caller can restore the best parameters ever evaluated without spending extra
    objective evaluations (or a separate forward-only compilation) on bookkeeping.
    """

    PENALTY = 1e10

    def __init__(self):
        super().__init__()
        self.reset()

    def reset(self):
        """Forget the failures and the best point of earlier runs."""
        self.failures = 0
        self.evaluations = 0
        self.first_loss = None
        self.best_loss = np.inf
        self.best_x = None
        self.start_run()

    def eval_func(self, closure, variables, tf_fun_args, compile=True,
                  allow_unused_variables=False):
        inner = super().eval_func(closure, variables, tf_fun_args, compile=compile,
                                  allow_unused_variables=allow_unused_variables)

        def guarded(x):
            self.evaluations += 1
            try:
                loss, grad = inner(x)
            except tf.errors.InvalidArgumentError:
                loss, grad = np.nan, None
            if not np.isfinite(loss) or grad is None or not np.all(np.isfinite(grad)):
                self.failures += 1
                return self.PENALTY, np.zeros_like(x)
            if self.first_loss is None:
                self.first_loss = float(loss)
            if loss < self.best_loss:
                self.best_loss = float(loss)
                self.best_x = np.array(x, dtype=np.float64, copy=True)
            return loss, grad

        return guarded

    def restore_best(self, variables) -> bool:
        """Assign the best point evaluated so far to ``variables``; False if there is none."""
        if self.best_x is None:
            return False
        values = self.unpack_tensors(variables, tf.constant(self.best_x))
        self.assign_tensors(variables, values)
        return True


class PILCO(gpflow.base.Module):
    """The PILCO agent: GP dynamics model, policy, reward and horizon.

    Args:
        data: raw transitions ``(X [N, D + U] = [x_t, u_t], Y [N, D] = x_{t+1} - x_t)``.
        controller: a policy with ``state_dim == D + len(angle_indices)`` (it reads the
            angle-augmented state) and ``control_dim == U``.
        reward: a reward on the raw state (``state_dim == D``).
        horizon: number of predicted steps in the policy objective.
        m_init: mean of the initial state [1, D] (default: the first state of ``data``).
        S_init: covariance of the initial state [D, D] (default ``0.01 * I``).
        angle_indices: state dimensions that are angles; the GP and the policy read the
            state with each angle replaced by its (sin, cos) pair, appended in order after
            the non-angle dimensions. The GP still predicts differences of the raw state.
        num_induced_points: if given, the dynamics model is a sparse :class:`SMGPR`.
        policy_input_noise: if True the policy sees ``s + diag(noise_variance) / 2``, a
            noisy measurement of the state; the default (False) feeds it the predicted
            state distribution itself, which is what the MATLAB reference reproduces.
    """

    def __init__(self, data, controller, reward, horizon: int = 30, m_init=None, S_init=None,
                 angle_indices: Sequence[int] = (), num_induced_points: Optional[int] = None,
                 policy_input_noise: bool = False, name: Optional[str] = None):
        super().__init__(name=name)
        X, Y = check_data(data, "data")
        self.state_dim = D = Y.shape[1]
        self.control_dim = U = X.shape[1] - D
        if U < 1:
            raise ValueError(
                f"data X must hold [state, action] with {D} state columns (from Y) and at "
                f"least one action column, got {X.shape[1]} columns"
            )
        self.angle_indices = check_indices(angle_indices, D, "angle_indices")
        self.feature_dim = D + len(self.angle_indices)
        for what, obj, want in (("controller", controller, self.feature_dim),
                                ("reward", reward, D)):
            got = getattr(obj, "state_dim", None)
            if got is None:
                raise TypeError(f"{what} must have a state_dim attribute")
            if got != want:
                raise ValueError(
                    f"{what}.state_dim is {got} but the {'policy input' if what == 'controller' else 'state'} "
                    f"has dimension {want}"
                    + (f" (state {D} + one extra per angle in angle_indices)"
                       if what == "controller" else "")
                )
        if getattr(controller, "control_dim", None) != U:
            raise ValueError(
                f"controller.control_dim is {getattr(controller, 'control_dim', None)} but the "
                f"data has {U} action columns"
            )
        self.controller = controller
        self.reward = reward
        self.policy_input_noise = check_bool(policy_input_noise, "policy_input_noise")
        self._horizon = tf.Variable(check_positive_int(horizon, "horizon"), trainable=False,
                                    dtype=tf.int32, name="horizon")

        self.num_induced_points = num_induced_points
        self._raw_X, self._raw_Y = X, Y
        gp_data = (self.gp_inputs(X), Y)
        if num_induced_points is None:
            self.mgpr = MGPR(gp_data)
        else:
            self.mgpr = SMGPR(gp_data, num_induced_points)

        m0 = X[0:1, :D] if m_init is None else m_init
        S0 = 0.01 * np.eye(D) if S_init is None else S_init
        m0, S0 = check_gaussian(m0, S0, D, "initial state")
        self._m_init = tf.Variable(m0, trainable=False, name="m_init")
        self._S_init = tf.Variable(S0, trainable=False, name="S_init")

        # Policy-independent pieces of the dynamics GP, refreshed by _refresh_dynamics().
        Din = self.feature_dim + U
        E = D
        P = E * (E + 1) // 2
        f = default_float()
        self._dyn_centers = tf.Variable(tf.zeros([0, Din], f), shape=[None, Din], trainable=False)
        self._dyn_beta = tf.Variable(tf.zeros([E, 0], f), shape=[E, None], trainable=False)
        self._dyn_W = tf.Variable(tf.zeros([P, 0, 0], f), shape=[P, None, None], trainable=False)
        self._dyn_ell = tf.Variable(tf.ones([E, Din], f), trainable=False)
        self._dyn_sf2 = tf.Variable(tf.ones([E], f), trainable=False)
        self._dyn_noise = tf.Variable(tf.ones([E], f), trainable=False)
        self._policy_optimizer = _GuardedScipy()

    # -- properties ---------------------------------------------------------------------
    @property
    def horizon(self) -> int:
        return int(self._horizon.numpy())

    @horizon.setter
    def horizon(self, value: int):
        self._horizon.assign(check_positive_int(value, "horizon"))

    @property
    def m_init(self) -> np.ndarray:
        return self._m_init.numpy()

    @m_init.setter
    def m_init(self, value):
        m, _ = check_gaussian(value, self._S_init.numpy(), self.state_dim, "initial state")
        self._m_init.assign(m)

    @property
    def S_init(self) -> np.ndarray:
        return self._S_init.numpy()

    @S_init.setter
    def S_init(self, value):
        self._S_init.assign(check_covariance(value, self.state_dim, "initial state covariance"))

    @property
    def data(self):
        """Raw transitions ``(X [N, D + U], Y [N, D])`` as NumPy arrays (copies)."""
        return self._raw_X.copy(), self._raw_Y.copy()

    # -- data -------------------------------------------------------------------------------
    def gp_inputs(self, X) -> np.ndarray:
        """Raw ``[x, u]`` rows [N, D + U] -> GP inputs [N, F + U] (angles as sin, cos)."""
        X = np.asarray(X, dtype=np.float64)
        D = self.state_dim
        if not self.angle_indices:
            return X
        keep = [d for d in range(D) if d not in self.angle_indices]
        ang = X[:, list(self.angle_indices)]
        trig = np.stack([np.sin(ang), np.cos(ang)], axis=-1).reshape(len(X), -1)
        return np.concatenate([X[:, keep], trig, X[:, D:]], axis=1)

    def set_data(self, data):
        """Replace the transitions ``(X [N, D + U], Y [N, D])`` the dynamics model learns from."""
        X, Y = check_data(data, "data", x_dim=self.state_dim + self.control_dim,
                          y_dim=self.state_dim)
        self._raw_X, self._raw_Y = X, Y
        self.mgpr.set_data((self.gp_inputs(X), Y))

    # -- the rollout ------------------------------------------------------------------------
    def _refresh_dynamics(self):
        """Compute the dynamics GP's factorisation once and store it for compiled rollouts."""
        fact = self.mgpr.factorize()
        self._dyn_centers.assign(fact.centers)
        self._dyn_beta.assign(fact.beta)
        self._dyn_W.assign(moments.pair_weights(fact.beta, fact.iK))
        self._dyn_ell.assign(fact.lengthscales)
        self._dyn_sf2.assign(fact.variance)
        self._dyn_noise.assign(self.mgpr.noise_variance)

    def _dynamics(self) -> moments.Predictor:
        """The cached dynamics GP as loop-invariant prediction pieces."""
        fact = moments.Factorization(
            tf.convert_to_tensor(self._dyn_centers), tf.convert_to_tensor(self._dyn_beta),
            None, tf.convert_to_tensor(self._dyn_ell), tf.convert_to_tensor(self._dyn_sf2),
        )
        return moments.prepare(fact, W=tf.convert_to_tensor(self._dyn_W), deterministic=False)

    def _propagate(self, m, s, dyn, ctrl):
        """One moment-matched step: m [1, D], s [D, D] -> m' [1, D], s' [D, D]."""
        ang = self.angle_indices
        Mf, Sf, Cf = augment_state(m, s, ang)
        if self.policy_input_noise:
            noisy = s + tf.linalg.diag(0.5 * tf.convert_to_tensor(self._dyn_noise))
            Mp, Sp, _ = augment_state(m, noisy, ang)
        else:
            Mp, Sp = Mf, Sf
        Mu, Su, Cu = self.controller._action(Mp, Sp, True, ctrl)
        cov_fu = tf.matmul(Sf, Cu)  # Cov[z, u], [F, U]
        m_in = tf.concat([Mf, Mu], axis=1)
        s_in = tf.concat(
            [tf.concat([Sf, cov_fu], 1), tf.concat([tf.transpose(cov_fu), Su], 1)], 0
        )
        Md, Sd, Vd = moments.predict(m_in, s_in, dyn)
        sCf = tf.matmul(s, Cf)  # Cov[x, z], [D, F]
        cov_x_in = tf.concat([sCf, tf.matmul(sCf, Cu)], axis=1)  # Cov[x, (z, u)]
        cov_xd = tf.matmul(cov_x_in, Vd)  # Cov[x, Δ], [D, D]
        m_next = m + Md
        s_next = s + Sd + cov_xd + tf.transpose(cov_xd)
        return m_next, 0.5 * (s_next + tf.transpose(s_next))

    @tf.function(autograph=False)
    def _total_reward(self, m0, s0, horizon):
        """Sum of expected rewards of steps 1..H, and the final state: compiled, in-graph loop."""
        dyn = self._dynamics()
        ctrl = self.controller.context()
        D = self.state_dim

        def body(t, m, s, total):
            m, s = self._propagate(m, s, dyn, ctrl)
            r, _ = self.reward._reward(m, s)
            return t + 1, m, s, total + r

        _, m, s, total = tf.while_loop(
            lambda t, *_: t < horizon, body,
            (tf.constant(0), m0, s0, tf.zeros([1, 1], dtype=m0.dtype)),
            shape_invariants=(tf.TensorShape([]), tf.TensorShape([1, D]),
                              tf.TensorShape([D, D]), tf.TensorShape([1, 1])),
        )
        return m, s, total

    @tf.function(autograph=False)
    def _trajectory(self, m0, s0, horizon):
        """States 0..H and their reward moments: M [H+1, D], S [H+1, D, D], R, Rv [H+1]."""
        dyn = self._dynamics()
        ctrl = self.controller.context()
        D = self.state_dim
        dtype = m0.dtype
        r0, v0 = self.reward._reward(m0, s0)
        arrays = tuple(tf.TensorArray(dtype, size=horizon + 1) for _ in range(4))
        arrays = tuple(a.write(0, x) for a, x in zip(arrays, (m0[0], s0, r0[0, 0], v0[0, 0])))

        def body(t, m, s, Ms, Ss, Rs, Vs):
            m, s = self._propagate(m, s, dyn, ctrl)
            r, v = self.reward._reward(m, s)
            return (t + 1, m, s, Ms.write(t, m[0]), Ss.write(t, s), Rs.write(t, r[0, 0]),
                    Vs.write(t, v[0, 0]))

        out = tf.while_loop(
            lambda t, *_: t <= horizon, body, (tf.constant(1), m0, s0) + arrays,
            shape_invariants=(tf.TensorShape([]), tf.TensorShape([1, D]),
                              tf.TensorShape([D, D])) + tuple(tf.TensorShape(None) for _ in arrays),
        )
        return tuple(a.stack() for a in out[3:])

    def _initial(self, m, s):
        if m is None:
            m = self._m_init.numpy()
        if s is None:
            s = self._S_init.numpy()
        return check_gaussian(m, s, self.state_dim, "initial state")

    def propagate(self, m, s):
        """One predicted step. Shapes: m [1, D], s [D, D] -> m' [1, D], s' [D, D]."""
        m, s = check_gaussian(m, s, self.state_dim, "state")
        self._refresh_dynamics()
        return self._propagate(m, s, self._dynamics(), self.controller.context())

    def predict(self, m=None, s=None, horizon: Optional[int] = None):
        """Predicted final state and total expected reward of steps 1..H.

        Shapes: m [1, D], s [D, D] (default: the initial state) -> m_H [1, D], S_H [D, D],
        total_reward [1, 1].
        """
        m, s = self._initial(m, s)
        H = self.horizon if horizon is None else check_positive_int(horizon, "horizon")
        self._refresh_dynamics()
        return self._total_reward(m, s, tf.constant(H))

    def predict_trajectory(self, m=None, s=None, horizon: Optional[int] = None):
        """Predicted state distributions of steps 0..H.

        Shapes: m [1, D], s [D, D] -> M [H+1, D], S [H+1, D, D] (index 0 is the start).
        """
        M, S, _, _ = self.predict_trajectory_with_rewards(m, s, horizon)
        return M, S

    def predict_trajectory_with_rewards(self, m=None, s=None, horizon: Optional[int] = None):
        """As :meth:`predict_trajectory`, plus the reward mean [H+1] and variance [H+1]."""
        m, s = self._initial(m, s)
        H = self.horizon if horizon is None else check_positive_int(horizon, "horizon")
        self._refresh_dynamics()
        return self._trajectory(m, s, tf.constant(H))

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

    def _policy_loss(self):
        _, _, total = self._total_reward(
            tf.convert_to_tensor(self._m_init), tf.convert_to_tensor(self._S_init),
            tf.convert_to_tensor(self._horizon),
        )
        return -total[0, 0]

    def expected_return(self) -> float:
        """Total expected reward of the current policy from the initial state distribution."""
        self._refresh_dynamics()
        return float(-self._policy_loss().numpy())

    def optimize_policy(self, maxiter: int = 50, restarts: int = 1, seed: Optional[int] = None,
                        callback: Optional[Callable[[int], None]] = None,
                        method: str = "L-BFGS-B", min_rel_improvement: Optional[float] = None,
                        patience: int = 10):
        """Maximise the predicted total reward over the policy parameters (L-BFGS-B or BFGS).

        The first run starts from the current policy, each further restart from a random
        one. The best policy evaluated by any run is kept (never one worse than the
        starting policy, which is the first point evaluated); a run that fails numerically
        is logged and the best policy so far restored. Returns the best total reward.

        The objective and its gradient are one compiled function (the whole horizon
        in-graph), traced on the first call and reused by later calls and restarts.
        ``callback(iteration)`` is called after every L-BFGS iteration (progress bars;
        an exception it raises, e.g. ``KeyboardInterrupt``, stops the optimisation).

        ``method`` is ``"L-BFGS-B"`` or ``"BFGS"`` (a dense inverse-Hessian update, what
        the MATLAB release's ``minimize`` uses for up to 1000 parameters). With
        ``min_rel_improvement`` set, a run stops once its best expected return has grown by
        less than ``min_rel_improvement * max(1, |return|)`` over the last ``patience``
        iterations (a converged run then costs a few iterations instead of ``maxiter``).
        """
        maxiter = check_positive_int(maxiter, "maxiter")
        restarts = check_positive_int(restarts, "restarts")
        patience = check_positive_int(patience, "patience")
        if not isinstance(method, str) or method.upper() not in POLICY_METHODS:
            raise ValueError(f"method must be one of {POLICY_METHODS}, got {method!r}")
        method = method.upper()
        min_rel_improvement = check_min_rel_improvement(min_rel_improvement)
        rng = np.random.default_rng(check_seed(seed))
        self._refresh_dynamics()
        variables = self.controller.trainable_variables
        opt = self._policy_optimizer
        opt.reset()
        start_values = snapshot(self.controller)

        def keep_best() -> bool:
            """Put the best policy evaluated in place (the start if none); False if none."""
            if opt.restore_best(variables):
                return True
            restore(self.controller, start_values)
            return False

        t0 = time.perf_counter()
        stalled = []
        for r in range(restarts):
            if r > 0:
                self.controller.randomize(seed=int(rng.integers(2**31)))
            opt.start_run()
            try:
                opt.minimize(
                    self._policy_loss, variables, method=method,
                    options=dict(maxiter=maxiter), tf_fun_args=dict(autograph=False),
                    step_callback=opt.step_callback(callback, min_rel_improvement, patience,
                                                    what="negative expected return"),
                )
            except Stalled as stop:
                stalled.append(stop.iterations)
            except (tf.errors.InvalidArgumentError, ValueError) as err:
                logger.warning("policy optimisation run %d failed (%s); keeping the best policy "
                               "so far", r, str(err).splitlines()[0][:120])
            except BaseException:
                # interrupted (Ctrl-C, a callback's exception): leave the best policy
                # evaluated so far in place, not the last trial point of a line search
                keep_best()
                logger.warning("policy optimisation interrupted after %d evaluations; the best "
                               "policy so far is kept", opt.evaluations)
                raise
        if not keep_best():
            logger.warning("policy optimisation evaluated no point where the expected return "
                           "is finite; the starting policy is kept")
            try:
                return float(-self._policy_loss().numpy())
            except tf.errors.InvalidArgumentError:
                return -np.inf
        if opt.failures:
            logger.warning("policy optimisation met %d trial points where the rollout failed "
                           "numerically; the line search stepped back from them", opt.failures)
        start = -np.inf if opt.first_loss is None else -opt.first_loss
        logger.info("policy optimised in %.2f s (%d evaluations%s): expected return %.4f -> %.4f",
                    time.perf_counter() - t0, opt.evaluations,
                    f"; {len(stalled)} run(s) stopped early, after {stalled} iterations"
                    if stalled else "", start, -opt.best_loss)
        return -opt.best_loss

    # -- acting -----------------------------------------------------------------------------
    @tf.function(autograph=False)
    def _act(self, x):
        f = default_float()
        Mf, _, _ = augment_state(x, tf.zeros([self.state_dim, self.state_dim], f),
                                 self.angle_indices)
        F = self.feature_dim
        M, _, _ = self.controller._action(Mf, tf.zeros([F, F], f), True)
        return M

    def compute_action(self, x) -> np.ndarray:
        """The policy's action at a measured state: x [1, D] (or [D]) -> u [1, U]."""
        x = _to_numpy(x, "state")
        x = as_2d_float(x.reshape(1, -1) if x.ndim == 1 else x, "state")
        if x.shape != (1, self.state_dim):
            raise ValueError(f"state must have shape (1, {self.state_dim}), got {x.shape}")
        return self._act(tf.convert_to_tensor(x)).numpy()

    # -- persistence ------------------------------------------------------------------------
    def save(self, path) -> None:
        """Write everything needed to continue learning to ``path`` (atomically)."""
        from ..persistence import save_agent

        save_agent(self, path)

    @classmethod
    def load(cls, path) -> "PILCO":
        """Rebuild an agent written by :meth:`save`."""
        from ..persistence import load_agent

        return load_agent(path)

    def export_policy(self, path) -> None:
        """Write the trained policy to a small ``.npz`` for :func:`pilco.deploy.load_policy`."""
        from ..persistence import export_policy

        export_policy(self, path)
