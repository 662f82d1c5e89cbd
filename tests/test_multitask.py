"""Multi-task PILCO: context dimensions, the reward of a linear map of the state, and the
policy objective summed over several start distributions (tasks).

The toy system has the state ``[p, θ, c0, c1]``: two predicted dimensions and a context
``(c0, c1)`` (a task, e.g. a target) that stays constant through an episode, one action.
Its dynamics do not depend on the context; a policy that reads the context makes the
action, and so the predicted dimensions, depend on it.

Monte Carlo checks use the helpers of ``test_monte_carlo.py`` (tolerances in Monte Carlo
standard errors, GP predictions from GPflow's own ``predict_f``). One step is exact for
an unsquashed linear policy without angles; with a squashed RBF policy on an angle the
step's last stage (the dynamics GP on PILCO's matched Gaussian of state, features and
action) is checked exactly, as there.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
import tensorflow as tf

from pilco.angles import augment_state
from pilco.controllers import LinearController, RbfController, squash_sin
from pilco.models import PILCO
from pilco.rewards import CombinedRewards, ExponentialReward, LinearMapReward, difference_map
from test_gradients import H_FD, assert_grad_close, check_against_differences
from test_monte_carlo import (assert_mc, assert_rejects, gauss, gp_latent, mc_cov, mc_mean,
                              np_, policy_np)

D, U = 4, 1
CONTEXT = (2, 3)
M0 = np.array([[0.2, 0.6, 0.5, -0.3]])
# the context has its own variance and is correlated with the predicted dimensions
S0 = np.array([[0.08, 0.02, 0.01, 0.00],
               [0.02, 0.12, 0.00, 0.01],
               [0.01, 0.00, 0.03, 0.005],
               [0.00, 0.01, 0.005, 0.02]])


def transitions(seed=0, N=40):
    """Raw transitions ``X [N, 5] = [p, θ, c0, c1, u]``, ``Y [N, 4]`` (0 in the context)."""
    rng = np.random.default_rng(seed)
    S = np.column_stack([rng.uniform(-1.5, 1.5, N), rng.uniform(-np.pi, np.pi, N),
                         rng.uniform(-1.0, 1.0, (N, 2))])
    u = rng.uniform(-1.0, 1.0, (N, 1))
    dS = np.column_stack([0.4 * np.sin(S[:, 1]) + 0.3 * u[:, 0],
                          0.4 * u[:, 0] - 0.2 * S[:, 0] * np.cos(S[:, 1]),
                          np.zeros((N, 2))])
    dS[:, :2] += 0.02 * rng.standard_normal((N, 2))
    return np.hstack([S, u]), dS


def controller(kind, inputs, seed=1):
    rng = np.random.default_rng(seed)
    if kind == "linear":
        ctrl = LinearController(inputs, U, squash=None)
        ctrl.W.assign(rng.uniform(-1.0, 1.0, (U, inputs)))
        ctrl.b.assign([[0.2]])
    else:
        ctrl = RbfController(inputs, U, 5, max_action=1.5, squash=squash_sin, seed=seed)
        ctrl.set_data((rng.uniform(-1.0, 1.0, (5, inputs)), rng.standard_normal((5, U))))
    return ctrl


def agent(kind="linear", angles=(), context=CONTEXT, reward=None, **kwargs):
    """The toy agent with fixed GP hyperparameters (the same for every agent built)."""
    X, Y = transitions()
    F = D + len(angles)
    policy = kwargs.pop("policy_indices", None)
    inputs = F if policy is None else sum(1 + (d in angles) for d in policy)
    reward = ExponentialReward(D, W=np.diag([2.0, 1.0, 0.0, 0.0]), t=[[0.5, 1.0, 0, 0]]) \
        if reward is None else reward
    kwargs.setdefault("horizon", 5)
    kwargs.setdefault("m_init", M0)
    kwargs.setdefault("S_init", S0)
    p = PILCO((X, Y), controller(kind, inputs), reward, angle_indices=angles,
              context_indices=context, policy_indices=policy, **kwargs)
    for mod in p.mgpr.models:
        mod.kernel.lengthscales.assign(np.full(p.mgpr.num_dims, 1.2))
        mod.kernel.variance.assign(0.3)
        mod.likelihood.variance.assign(1e-3)
    return p


def target_reward():
    """A saturating reward of the distance between p and the context c0 (a target)."""
    return LinearMapReward(D, ExponentialReward(1, W=[[4.0]]), difference_map(D, [0], [2]))


# ---------------------------------------------------------------------------
# The dynamics model never sees the context
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("angles", [(), (1,)], ids=["plain", "angle"])
def test_dynamics_gps_read_and_predict_the_non_context_dimensions(angles):
    X, Y = transitions()
    p = agent(angles=angles)
    F_d = 2 + len(angles)  # p, θ (or sin θ, cos θ)
    assert p.mgpr.num_dims == F_d + U and p.mgpr.num_outputs == 2
    assert len(p.mgpr.models) == 2
    assert np.asarray(p.mgpr.X).shape == (40, F_d + U)
    assert np.asarray(p.mgpr.Y).shape == (40, 2)
    assert all(m.kernel.lengthscales.shape == (F_d + U,) for m in p.mgpr.models)
    expected = np.column_stack([X[:, :1], np.sin(X[:, 1]), np.cos(X[:, 1]), X[:, 4]]) \
        if angles else X[:, [0, 1, 4]]
    np.testing.assert_array_equal(np.asarray(p.mgpr.X), expected)
    np.testing.assert_array_equal(np.asarray(p.mgpr.Y), Y[:, :2])
    # the raw transitions, context included, are kept for the agent's files
    np.testing.assert_array_equal(p.data[0], X)
    # new data go through the same map
    X2, Y2 = transitions(seed=5, N=12)
    p.set_data((X2, Y2))
    assert np.asarray(p.mgpr.X).shape == (12, F_d + U)
    np.testing.assert_array_equal(np.asarray(p.mgpr.Y), Y2[:, :2])
    # the policy reads everything: the context changes the action
    assert p.policy_dim == p.controller.state_dim == D + len(angles)
    x = M0.copy()
    u0 = p.compute_action(x)
    x[0, 2] += 1.0
    assert np.abs(p.compute_action(x) - u0).max() > 1e-3
    # predicted differences of the context are 0, with no uncertainty
    mean, var = p.one_step_prediction(X[:3])
    assert mean.shape == var.shape == (3, D)
    assert np.all(mean[:, 2:] == 0.0) and np.all(var[:, 2:] == 0.0)
    assert np.all(var[:, :2] > 0.0)


def test_dynamics_may_read_context_when_asked_and_index_sets_select_features():
    p = agent(dynamics_indices=[0, 1, 3])
    assert p.mgpr.num_dims == 3 + U and p.mgpr.num_outputs == 2
    np.testing.assert_array_equal(np.asarray(p.mgpr.X), transitions()[0][:, [0, 1, 3, 4]])
    # a policy reading only p and the angle θ (as sin, cos)
    q = agent(kind="rbf", angles=(1,), policy_indices=[0, 1])
    assert q.controller.state_dim == q.policy_dim == 3
    x = M0.copy()
    u0 = q.compute_action(x)
    x[0, 2:] += 1.0  # the context is not read by this policy
    np.testing.assert_array_equal(q.compute_action(x), u0)


# ---------------------------------------------------------------------------
# Context through a rollout
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("kind,angles,noise", [("linear", (), False), ("rbf", (1,), True),
                                               ("rbf", (1,), False)],
                         ids=["linear", "rbf-angle-noisy-policy-input", "rbf-angle"])
def test_context_keeps_mean_and_variance_exactly(kind, angles, noise):
    p = agent(kind, angles, policy_input_noise=noise)
    H = 5
    M, S = (np_(v) for v in p.predict_trajectory(horizon=H))
    c = list(CONTEXT)
    for t in range(H + 1):
        np.testing.assert_array_equal(M[t, c], M0[0, c])
        np.testing.assert_array_equal(S[t][np.ix_(c, c)], S0[np.ix_(c, c)])
    # the predicted dimensions moved and their covariance with the context changed: the
    # policy reads the context, so every step's action (and difference) depends on it
    assert np.abs(M[H, :2] - M0[0, :2]).max() > 0.05
    assert np.abs(S[H][:2, 2:] - S0[:2, 2:]).max() > 1e-3
    assert np.all(np.linalg.eigvalsh(S) > 0)
    # one step equals the trajectory's first
    m1, s1 = (np_(v) for v in p.propagate(M0, S0))
    np.testing.assert_allclose(M[1], m1[0], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(S[1], s1, rtol=1e-12, atol=1e-14)


def test_deterministic_context_stays_deterministic():
    S = S0.copy()
    S[2:, :] = S[:, 2:] = 0.0
    p = agent(S_init=S)
    M, St = (np_(v) for v in p.predict_trajectory())
    assert np.all(St[:, 2:, :] == 0.0) and np.all(St[:, :, 2:] == 0.0)
    assert np.all(M[:, 2:] == M0[0, 2:])


def exact_step_mc(p, m, s, rng):
    """One true step with an unsquashed linear policy on the whole state, no angles:
    x' = x + [f(x_p, θ, u), 0] with u = W x + b, the context carried unchanged."""
    x = gauss(rng, m, s)
    u = policy_np(p.controller, x)
    mu, var = gp_latent(p.mgpr.models, np.hstack([x[:, list(p.dynamics_indices)], u]))
    return x, p.layout.to_state(mu), p.layout.to_state(var)


def matched_step_mc(p, m, s, rng):
    """The dynamics GP on PILCO's matched Gaussian of (x, features z, action u), built
    here from ``augment_state`` and the controller (both checked by Monte Carlo in
    ``test_monte_carlo.py``), with the layout's selections written out."""
    Mf, Sf, Cf = (np_(v) for v in augment_state(m, s, p.angle_indices))
    F = Mf.shape[1]
    Pp = np.eye(F)[:, list(p.layout.policy_features)]
    Pd = np.eye(F)[:, list(p.layout.dynamics_features)]
    Mu, Su, Cu = (np_(v) for v in p.controller.compute_action(Mf @ Pp, Pp.T @ Sf @ Pp))
    sCf = s @ Cf
    mean = np.hstack([m, Mf, Mu])
    cov = np.block([[s, sCf, sCf @ Pp @ Cu],
                    [sCf.T, Sf, Sf @ Pp @ Cu],
                    [(sCf @ Pp @ Cu).T, (Sf @ Pp @ Cu).T, Su]])
    xzu = gauss(rng, mean, cov)
    x, z, u = xzu[:, :D], xzu[:, D:D + F], xzu[:, D + F:]
    mu, var = gp_latent(p.mgpr.models, np.hstack([z @ Pd, u]))
    return x, p.layout.to_state(mu), p.layout.to_state(var)


def check_step(name, m1, s1, x, delta, var):
    xn = x + delta
    m_mc, m_se = mc_mean(xn)
    S_mc, S_se = mc_cov(xn, latent_var=var)
    assert_mc(f"{name}: mean", m1, m_mc, m_se)
    assert_mc(f"{name}: covariance", s1, S_mc, S_se)
    return S_mc, S_se


@pytest.mark.parametrize("kind,angles", [("linear", ()), ("rbf", (1,))],
                         ids=["linear-exact", "rbf-angle-last-stage"])
def test_context_cross_covariance_matches_monte_carlo_step_by_step(kind, angles):
    """5 steps: from N(M_t, S_t), one Monte Carlo step (the context of each sample held
    fixed through it) must give M_{t+1}, S_{t+1}, cross-covariances with the context
    included."""
    p = agent(kind, angles)
    H = 5
    M, S = (np_(v) for v in p.predict_trajectory(horizon=H))
    rng = np.random.default_rng(21)
    sample = exact_step_mc if kind == "linear" else matched_step_mc
    for t in range(H):
        m_t, s_t = M[t:t + 1], S[t]
        x, delta, var = sample(p, m_t, s_t, rng)
        S_mc, S_se = check_step(f"step {t + 1}", M[t + 1:t + 2], S[t + 1], x, delta, var)
        if t == 0:
            # sharp enough to see the context's cross-covariance with Δ
            wrong = S[t + 1].copy()
            wrong[:2, 2:] = s_t[:2, 2:]
            wrong[2:, :2] = s_t[2:, :2]
            assert_rejects("Cov[Δ, context] dropped", wrong, S_mc, S_se)


def test_context_held_once_per_trajectory_matches_monte_carlo_rollout():
    """Whole trajectories: the context drawn once per trajectory and never changed, the
    GP's latent uncertainty drawn at every step. Moment matching is exact for one step
    only; with a narrow start and a gentle policy the state stays close to Gaussian and
    the predicted moments after 4 steps agree with Monte Carlo to within a few standard
    errors plus a little slack for PILCO's Gaussian approximation: the context's own
    moments and its covariance with the predicted dimensions, which grew from the start's."""
    p = agent("linear")
    p.controller.W.assign(0.5 * p.controller.W.numpy())
    s0 = 0.25 * S0
    H = 4
    M, S = (np_(v) for v in p.predict_trajectory(M0, s0, horizon=H))
    rng = np.random.default_rng(22)
    x = gauss(rng, M0, s0, n=100_000)
    context = x[:, 2:].copy()
    for _ in range(H):
        u = policy_np(p.controller, x)
        mu, var = gp_latent(p.mgpr.models, np.hstack([x[:, :2], u]))
        x = x + p.layout.to_state(mu + np.sqrt(var) * rng.standard_normal(mu.shape))
    np.testing.assert_array_equal(x[:, 2:], context)
    m_mc, m_se = mc_mean(x)
    S_mc, S_se = mc_cov(x)
    assert_mc("context mean", M[H, 2:], m_mc[2:], m_se[2:])
    assert_mc("context covariance", S[H][2:, 2:], S_mc[2:, 2:], S_se[2:, 2:])
    cross = S_mc[:2, 2:]
    scale = np.abs(cross).max()
    assert scale > 3 * np.abs(s0[:2, 2:]).max()  # the correlation with the context grew
    assert_mc("Cov[predicted, context]", S[H][:2, 2:], cross, S_se[:2, 2:],
              atol=0.03 * scale)
    assert_rejects("Cov[predicted, context] kept at the start's", s0[:2, 2:], cross,
                   S_se[:2, 2:])
    moved = np.abs(M[H, :2] - M0[0, :2]).max()
    assert moved > 0.5
    assert_mc("predicted mean", M[H, :2], m_mc[:2], m_se[:2], atol=0.01 * moved)


# ---------------------------------------------------------------------------
# The reward of a linear map of the state
# ---------------------------------------------------------------------------


def test_linear_map_reward_matches_monte_carlo():
    rng = np.random.default_rng(30)
    # [gripper xyz, something else, target xyz]
    A = difference_map(7, [0, 1, 2], [4, 5, 6])
    np.testing.assert_array_equal(A, np.hstack([np.eye(3), np.zeros((3, 1)), -np.eye(3)]))
    B = rng.standard_normal((3, 3))
    W = 0.5 * B @ B.T + 2.0 * np.eye(3)
    reward = LinearMapReward(7, ExponentialReward(3, W=W), A)
    m = np.array([[1.1, 0.4, 0.5, 0.3, 1.2, 0.38, 0.38]])
    L = 0.2 * rng.standard_normal((7, 7))
    s = L @ L.T + 0.01 * np.eye(7)
    mean, var = (np_(v) for v in reward.compute_reward(m, s))
    assert mean.shape == var.shape == (1, 1)
    x = gauss(rng, m, s)
    z = x @ A.T
    r = np.exp(-0.5 * np.einsum("ni,ij,nj->n", z, W, z))[:, None]
    r_mc, r_se = mc_mean(r)
    v_mc, v_se = mc_cov(r)
    assert_mc("E[r]", mean, r_mc, r_se)
    assert_mc("Var[r]", var, v_mc, v_se)
    assert_rejects("reward of the mean state", np.exp(-0.5 * (m @ A.T) @ W @ (A @ m.T)),
                   r_mc, r_se)
    assert_rejects("the map's covariance without the target's (A_g s A_g^T)",
                   ExponentialReward(3, W=W).compute_reward(m[:, :3] - m[:, 4:],
                                                            s[:3, :3])[0], r_mc, r_se)
    # the same value as the saturating reward with the pulled-back weight A^T W A
    full = ExponentialReward(7, W=A.T @ W @ A)
    for a, b in zip(reward.compute_reward(m, s), full.compute_reward(m, s)):
        np.testing.assert_allclose(np_(a), np_(b), rtol=1e-12)
    # an offset b shifts the map: r(A x + b)
    shifted = LinearMapReward(7, ExponentialReward(3, W=W, t=[[0.1, 0.0, -0.2]]), A)
    offset = LinearMapReward(7, ExponentialReward(3, W=W), A, b=[-0.1, 0.0, 0.2])
    for a, b in zip(shifted.compute_reward(m, s), offset.compute_reward(m, s)):
        np.testing.assert_allclose(np_(a), np_(b), rtol=1e-12)
    # a known state: the reward itself, variance 0
    mean0, var0 = (np_(v) for v in reward.compute_reward(m, np.zeros((7, 7))))
    z0 = (m @ A.T)[0]
    np.testing.assert_allclose(mean0, [[np.exp(-0.5 * z0 @ W @ z0)]], rtol=1e-12)
    np.testing.assert_allclose(var0, 0.0, atol=1e-15)


def test_linear_map_reward_gradient_matches_finite_differences():
    A = difference_map(4, [0, 1], [2, 3])
    reward = LinearMapReward(4, ExponentialReward(2, W=np.diag([3.0, 1.5])), A)
    m = tf.Variable(M0)
    with tf.GradientTape() as tape:
        mean, _ = reward.moments(m, tf.constant(S0))
    g = tape.gradient(mean, m).numpy().ravel()
    fd = np.zeros(4)
    for i in range(4):
        e = np.zeros((1, 4))
        e[0, i] = H_FD
        fd[i] = (np_(reward.compute_reward(M0 + e, S0)[0])[0, 0]
                 - np_(reward.compute_reward(M0 - e, S0)[0])[0, 0]) / (2 * H_FD)
    assert_grad_close(g, fd, "d E[r] / d m")


# ---------------------------------------------------------------------------
# The multi-task objective
# ---------------------------------------------------------------------------

#: three tasks: three targets (context), the same arm start; the context is known
#: exactly in the first two and a little uncertain in the third
TASKS_M = np.array([[0.2, 0.6, 0.5, -0.3], [0.2, 0.6, -0.4, 0.2], [0.1, 0.5, 0.9, 0.4]])
TASKS_S = np.stack([np.diag([0.05, 0.08, 0.0, 0.0]), np.diag([0.05, 0.08, 0.0, 0.0]),
                    np.diag([0.05, 0.08, 1e-3, 1e-3])])


def loss_and_grad(p):
    variables = p.controller.trainable_variables
    with tf.GradientTape() as tape:
        loss = p._rollout.policy_loss()
    grads = tape.gradient(loss, variables)
    return float(loss.numpy()), np.concatenate(
        [np.asarray(tf.convert_to_tensor(g)).ravel() for g in grads])


@pytest.mark.parametrize("kind,angles", [("rbf", (1,)), ("linear", ())],
                         ids=["rbf-angle", "linear"])
def test_multitask_objective_is_the_sum_of_single_task_objectives(kind, angles):
    multi = agent(kind, angles, reward=target_reward(), m_init=TASKS_M, S_init=TASKS_S)
    assert multi.num_tasks == 3 and multi.m_init.shape == (3, D)
    assert multi.S_init.shape == (3, D, D)
    multi.expected_return()  # factorises the dynamics model for policy_loss
    loss, grad = loss_and_grad(multi)
    singles, single_grads = [], []
    # one single-task agent serves the three tasks in turn: its start is replaced by the
    # next task's (one start each time, so its compiled objective is traced once)
    single = agent(kind, angles, reward=target_reward(), m_init=TASKS_M[:1],
                   S_init=TASKS_S[0])
    single.controller = multi.controller  # one policy for every task
    for i in range(3):
        single.set_initial(TASKS_M[i:i + 1], TASKS_S[i])
        assert single.num_tasks == 1
        single.expected_return()
        l_i, g_i = loss_and_grad(single)
        singles.append(l_i)
        single_grads.append(g_i)
    assert len(set(singles)) == 3  # the tasks differ
    np.testing.assert_allclose(loss, sum(singles), rtol=0, atol=1e-10)
    np.testing.assert_allclose(grad, np.sum(single_grads, axis=0), rtol=0, atol=1e-10)
    np.testing.assert_allclose(multi.expected_returns(), -np.array(singles), rtol=0,
                               atol=1e-10)
    assert multi.expected_return() == pytest.approx(-loss, abs=1e-12)
    # each task's prediction from its own start
    _, _, total = multi.predict(task=1)
    np.testing.assert_allclose(np_(total)[0, 0], -singles[1], rtol=0, atol=1e-10)


def test_multitask_objective_gradient_matches_finite_differences():
    p = agent("rbf", (1,), reward=target_reward(), m_init=TASKS_M, S_init=TASKS_S)
    p.expected_return()
    variables = p.controller.trainable_variables
    with tf.GradientTape() as tape:
        loss = p._rollout.policy_loss()
    grads = tape.gradient(loss, variables)
    assert all(g is not None for g in grads)
    check_against_differences(p, variables, grads)


def test_multitask_policy_optimisation_improves_the_sum():
    p = agent("rbf", (1,), reward=target_reward(), m_init=TASKS_M, S_init=TASKS_S)
    before = p.expected_return()
    best = p.optimize_policy(maxiter=3)
    assert best >= before - 1e-12
    assert p.expected_return() == pytest.approx(best, rel=1e-9)
    assert p.expected_returns().sum() == pytest.approx(best, rel=1e-9)


def test_starts_shared_covariance_and_changing_the_number_of_tasks():
    p = agent(m_init=TASKS_M, S_init=S0)  # one covariance for every task
    assert p.S_init.shape == (D, D) and p.num_tasks == 3
    np.testing.assert_array_equal(p._rollout.S_init.numpy(), np.stack([S0] * 3))
    three = p.expected_returns()
    p.m_init = TASKS_M[:2]  # a shared covariance serves any number of tasks
    assert p.num_tasks == 2
    np.testing.assert_allclose(p.expected_returns(), three[:2], rtol=0, atol=1e-12)
    assert p.optimize_policy(maxiter=1) == pytest.approx(p.expected_return(), rel=1e-9)
    p.set_initial(TASKS_M, TASKS_S)
    assert p.S_init.shape == (3, D, D)
    with pytest.raises(ValueError, match=r"set_initial\(m_init, S_init\)"):
        p.m_init = TASKS_M[:2]
    p.m_init = TASKS_M[::-1]  # as many tasks: the per-task covariances stay
    np.testing.assert_array_equal(p.S_init, TASKS_S)
    p.S_init = S0
    assert p.S_init.shape == (D, D)
    with pytest.raises(ValueError, match="pass task=i"):
        p.predict_trajectory()
    with pytest.raises(ValueError, match="task 3 does not exist"):
        p.predict_trajectory(task=3)
    M, _ = p.predict_trajectory(task=2, horizon=1)
    np.testing.assert_array_equal(np_(M)[0], TASKS_M[0])  # reversed above


# ---------------------------------------------------------------------------
# Files
# ---------------------------------------------------------------------------


def test_multitask_agent_round_trip(tmp_path):
    p = agent("rbf", (1,), reward=CombinedRewards(D, [target_reward(), ExponentialReward(D)]),
              m_init=TASKS_M, S_init=TASKS_S, dynamics_indices=[0, 1, 2])
    path = p.save(tmp_path / "agent.npz")
    with np.load(path) as z:
        meta = json.loads(str(z["__meta__"]))
    assert meta["version"] == 2 and meta["context_indices"] == [2, 3]
    assert meta["dynamics_indices"] == [0, 1, 2] and "policy_indices" not in meta
    back = PILCO.load(path)
    assert back.context_indices == p.context_indices
    assert back.dynamics_indices == p.dynamics_indices and back.num_tasks == 3
    np.testing.assert_array_equal(back.expected_returns(), p.expected_returns())
    # an agent without any of it is still written as version 1
    plain = PILCO(transitions(), controller("linear", D), ExponentialReward(D))
    with np.load(plain.save(tmp_path / "plain.npz")) as z:
        assert json.loads(str(z["__meta__"]))["version"] == 1


def test_policy_reading_a_subset_cannot_be_exported(tmp_path):
    p = agent("rbf", (1,), policy_indices=[0, 1])
    with pytest.raises(ValueError, match="policy_indices"):
        p.export_policy(tmp_path / "policy.npz")
    assert not list(tmp_path.iterdir())


# ---------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------

BAD = [
    ("context-out-of-range", dict(context=(2, 4)), ValueError,
     r"context_indices: index 4 is outside the state \(dimension 4\)"),
    ("context-duplicates", dict(context=(2, 2)), ValueError, "context_indices has duplicates"),
    ("context-float", dict(context=(2.0,)), TypeError, "context_indices must hold integers"),
    ("context-overlaps-angles", dict(context=(1, 2), angles=(1,)), ValueError,
     r"context_indices and angle_indices overlap at \[1\]"),
    ("context-everything", dict(context=(0, 1, 2, 3)), ValueError,
     "at least one must be predicted"),
    ("dynamics-out-of-range", dict(dynamics_indices=[0, 7]), ValueError,
     "dynamics_indices: index 7 is outside the state"),
    ("policy-empty", dict(policy_indices=[]), ValueError, "policy_indices is empty"),
    ("m-init-columns", dict(m_init=np.zeros((3, 5))), ValueError,
     r"initial state mean must have shape \(T, 4\) \(one start per task\), got \(3, 5\)"),
    ("m-init-rank", dict(m_init=np.zeros((3, 4, 1))), ValueError,
     r"initial state mean must have shape \(T, 4\)"),
    ("m-init-nan", dict(m_init=np.where(np.eye(3, 4) > 0, np.nan, 0.0)), ValueError,
     "task 0's initial state mean contains NaN"),
    ("S-init-tasks", dict(m_init=TASKS_M, S_init=TASKS_S[:2]), ValueError,
     r"initial state covariance must have shape \(4, 4\) \(shared by all tasks\) or "
     r"\(3, 4, 4\) \(one per task\), got \(2, 4, 4\)"),
    ("S-init-one-start-many-covariances", dict(S_init=TASKS_S), ValueError,
     "holds 3 covariances"),
    ("S-init-not-psd",
     dict(m_init=TASKS_M, S_init=TASKS_S * np.array([1.0, -1.0, 1.0])[:, None, None]),
     ValueError, "task 1's initial state covariance is not positive semi-definite"),
]


@pytest.mark.parametrize("kwargs,error,match", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_layouts_and_starts_are_refused_before_tensorflow(kwargs, error, match):
    kwargs = dict(kwargs)
    context = kwargs.pop("context", CONTEXT)
    angles = kwargs.pop("angles", ())
    X, Y = transitions()
    with pytest.raises(error, match=match):
        PILCO((X, Y), controller("linear", D + len(angles)), ExponentialReward(D),
              angle_indices=angles, context_indices=context, **kwargs)


def test_bad_controller_and_reward_maps_are_refused():
    X, Y = transitions()
    with pytest.raises(ValueError, match=r"controller.state_dim is 4 but the policy input has "
                                         r"dimension 3 \(the features of policy_indices"):
        PILCO((X, Y), controller("linear", 4), ExponentialReward(D), angle_indices=(1,),
              context_indices=CONTEXT, policy_indices=[0, 1])
    with pytest.raises(ValueError, match=r"A \(the map from the 4-dimensional state to the "
                                         r"base reward's 2 dimensions\) must have shape "
                                         r"\(2, 4\), got \(2, 3\)"):
        LinearMapReward(D, ExponentialReward(2), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="b must have 2 entries"):
        LinearMapReward(D, ExponentialReward(2), np.zeros((2, 4)), b=[0.0])
    with pytest.raises(TypeError, match="base_reward must be a reward"):
        LinearMapReward(D, "exp", np.zeros((2, 4)))
    with pytest.raises(ValueError, match="as many dimensions"):
        difference_map(D, [0, 1], [2])
    with pytest.raises(ValueError, match="with itself"):
        difference_map(D, [0, 1], [2, 1])
    with pytest.raises(ValueError, match="index 4 is outside"):
        difference_map(D, [0], [4])
