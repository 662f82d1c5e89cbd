"""Analytic gradients against central finite differences.

The policy objective (the compiled horizon rollout, ``PILCO._rollout.policy_loss``) is
differentiated by TensorFlow with respect to the policy's trainable (unconstrained)
variables and compared with central differences ``(L(θ + h) - L(θ - h)) / 2h`` in
float64. With ``h = 1e-5`` the truncation error is ~h^2 |L'''| ~ 1e-10 and the
round-off error ~eps |L| / h ~ 1e-11, far below the ``rtol = 1e-5`` asserted, while a
wrong term of the derivative (a missing chain-rule factor, a stopped gradient, a
non-differentiable branch) changes entries by far more.

Derivatives with respect to a covariance ``s`` are taken along symmetric directions
``E_ij + E_ji`` (``s`` is only defined up to symmetry; Cholesky-based code reads one
triangle), where the analytic directional derivative is ``G_ij + G_ji``.
"""
from __future__ import annotations

import numpy as np
import pytest
import tensorflow as tf

from pilco import moments
from pilco.controllers import LinearController, RbfController, squash_sat, squash_sin
from pilco.models import MGPR, PILCO
from pilco.moments import pairs as moment_pairs
from pilco.rewards import ExponentialReward

H_FD = 1e-5
RTOL = 1e-5


def check_against_differences(p, variables, grads):
    """Each of ``grads`` (the policy loss's gradient) against central differences of
    ``p._rollout.policy_loss()`` in every entry of its variable (restored after)."""
    for var, grad in zip(variables, grads):
        grad = np.asarray(tf.convert_to_tensor(grad).numpy())
        v0 = var.numpy().copy()
        fd = np.zeros(v0.size)
        for i in range(v0.size):
            step = np.zeros(v0.size)
            step[i] = H_FD
            var.assign((v0.ravel() + step).reshape(v0.shape))
            up = float(p._rollout.policy_loss().numpy())
            var.assign((v0.ravel() - step).reshape(v0.shape))
            down = float(p._rollout.policy_loss().numpy())
            fd[i] = (up - down) / (2 * H_FD)
        var.assign(v0)
        assert_grad_close(grad.ravel(), fd, f"d loss / d {var.name}")


def assert_grad_close(analytic, numeric, name):
    analytic = np.asarray(analytic, dtype=float)
    numeric = np.asarray(numeric, dtype=float)
    scale = np.abs(numeric).max()
    assert scale > 1e-4, f"{name}: the gradient is ~0, the comparison would be vacuous"
    # entries far below the largest one are compared absolutely (relative error of a
    # ~0 entry is meaningless); every other entry at rtol
    np.testing.assert_allclose(analytic, numeric, rtol=RTOL, atol=RTOL * 1e-2 * scale,
                               err_msg=name)


# ---------------------------------------------------------------------------
# Policy objective
# ---------------------------------------------------------------------------


def toy_pilco(controller, angle_indices, seed=0):
    """2-D state [p, θ], 1-D action; transitions of a smooth toy system."""
    rng = np.random.default_rng(seed)
    N = 30
    S = np.column_stack([rng.uniform(-1.5, 1.5, N), rng.uniform(-np.pi, np.pi, N)])
    U = rng.uniform(-1.0, 1.0, (N, 1))
    dS = np.column_stack([0.4 * np.sin(S[:, 1]) + 0.3 * U[:, 0],
                          0.4 * U[:, 0] - 0.2 * S[:, 0] * np.cos(S[:, 1])])
    dS += 0.02 * rng.standard_normal(dS.shape)
    reward = ExponentialReward(2, W=np.diag([2.0, 1.0]), t=[[0.5, 1.0]])
    return PILCO((np.hstack([S, U]), dS), controller, reward, horizon=5,
                 m_init=[[0.1, 0.5]], S_init=[[0.05, 0.01], [0.01, 0.08]],
                 angle_indices=angle_indices)


def make_controller(kind, squash, F, seed=1):
    rng = np.random.default_rng(seed)
    if kind == "rbf":
        ctrl = RbfController(F, 1, 5, max_action=1.5, squash=squash, seed=seed)
        ctrl.set_data((rng.uniform(-1.0, 1.0, (5, F)), rng.standard_normal((5, 1))))
        ctrl.models[0].kernel.lengthscales.assign(rng.uniform(0.7, 1.5, F))
    else:
        ctrl = LinearController(F, 1, max_action=1.5, squash=squash, seed=seed)
        ctrl.W.assign(rng.uniform(-1.0, 1.0, (1, F)))
        ctrl.b.assign([[0.3]])
    return ctrl


CASES = [
    ("rbf", squash_sin, ()),
    ("rbf", squash_sat, ()),
    ("rbf", squash_sin, (1,)),
    ("rbf", squash_sat, (1,)),
    ("linear", squash_sin, (1,)),
]


@pytest.mark.parametrize(
    "kind,squash,angles", CASES,
    ids=[f"{k}-{s.__name__}-{'angle' if a else 'plain'}" for k, s, a in CASES])
def test_policy_objective_gradient_matches_finite_differences(kind, squash, angles):
    F = 2 + len(angles)
    ctrl = make_controller(kind, squash, F)
    p = toy_pilco(ctrl, angles)
    p.expected_return()  # factorises the dynamics model for policy_loss
    variables = p.controller.trainable_variables
    expected = {"rbf": 5 * F + 5 + F, "linear": F + 1}[kind]  # centers, targets, ell / W, b
    assert sum(int(np.prod(v.shape)) for v in variables) == expected

    with tf.GradientTape() as tape:
        loss = p._rollout.policy_loss()
    grads = tape.gradient(loss, variables)
    assert all(g is not None for g in grads)
    loss0 = float(loss.numpy())
    assert np.isfinite(loss0) and -5.0 <= loss0 < 0.0  # five rewards in (0, 1]

    check_against_differences(p, variables, grads)
    # restoring the variables restores the objective
    assert float(p._rollout.policy_loss().numpy()) == pytest.approx(loss0, rel=1e-12)


# ---------------------------------------------------------------------------
# Moment matching of the dynamics model w.r.t. its input distribution
# ---------------------------------------------------------------------------


def toy_mgpr(seed=2):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-2.0, 2.0, (30, 3))
    Y = np.column_stack([np.sin(X[:, 0]) + 0.5 * X[:, 1] * np.cos(X[:, 2]),
                         0.8 * np.sin(X[:, 0]) + np.cos(X[:, 0] + X[:, 1])])
    gp = MGPR((X, Y + 0.05 * rng.standard_normal(Y.shape)))
    for i, mod in enumerate(gp.models):
        mod.kernel.lengthscales.assign([[1.0, 1.3, 1.6], [0.9, 1.1, 1.8]][i])
        mod.kernel.variance.assign([1.0, 0.7][i])
        mod.likelihood.variance.assign([0.01, 0.02][i])
    return gp


M_IN = np.array([[0.3, -0.4, 0.8]])
S_IN = np.array([[0.5, 0.2, -0.1], [0.2, 0.4, 0.15], [-0.1, 0.15, 0.6]])
_W = np.random.default_rng(3)
W_M, W_S, W_V = _W.standard_normal((1, 2)), _W.standard_normal((2, 2)), _W.standard_normal((3, 2))


def scalarize(M, S, V):
    """A random linear functional of every output, so every entry's derivative counts."""
    return (tf.reduce_sum(W_M * M) + tf.reduce_sum(W_S * S) + tf.reduce_sum(W_V * V))


def check_input_gradients(predict):
    """predict(m, s) -> (M, S, V) as tensors; compare d/dm and symmetric d/ds with FD."""
    m = tf.Variable(M_IN)
    s = tf.Variable(S_IN)
    with tf.GradientTape() as tape:
        L = scalarize(*predict(m, s))
    gm, gs = tape.gradient(L, [m, s])
    assert gm is not None and gs is not None, "no gradient flows to the input moments"
    gm, gs = gm.numpy(), gs.numpy()

    def f(mm, ss):
        return float(scalarize(*predict(tf.constant(mm), tf.constant(ss))).numpy())

    fd_m = np.zeros(3)
    for i in range(3):
        e = np.zeros((1, 3))
        e[0, i] = H_FD
        fd_m[i] = (f(M_IN + e, S_IN) - f(M_IN - e, S_IN)) / (2 * H_FD)
    assert_grad_close(gm.ravel(), fd_m, "dL/dm")

    an_s, fd_s = [], []
    for i in range(3):
        for j in range(i, 3):
            E = np.zeros((3, 3))
            E[i, j] = E[j, i] = 1.0
            an_s.append(np.sum(gs * E))
            fd_s.append((f(M_IN, S_IN + H_FD * E) - f(M_IN, S_IN - H_FD * E)) / (2 * H_FD))
    assert_grad_close(np.array(an_s), np.array(fd_s), "dL/ds (symmetric directions)")


def test_moment_matching_gradients_wrt_input_distribution():
    """The differentiable core the rollout uses: moment_match on the MGPR factorisation."""
    gp = toy_mgpr()
    fact = gp.factorize()
    check_input_gradients(lambda m, s: moments.moment_match(m, s, fact))


def test_predict_on_noisy_inputs_gradients_wrt_m_and_s():
    gp = toy_mgpr()
    check_input_gradients(gp.predict_on_noisy_inputs)


def test_fused_pair_block_gradients_wrt_input_distribution():
    """The rollout's path: a constant factorisation, whose block has a hand-made gradient."""
    gp = toy_mgpr()
    fact = gp.factorize()
    check_input_gradients(lambda m, s: moments.moment_match(m, s, fact, constant=True))


def test_fused_pair_block_agrees_with_automatic_differentiation():
    """Values and gradients of the hand-differentiated block equal TensorFlow's own
    derivatives of the plain formulation (weights formed inside, autodiff throughout)."""
    gp = toy_mgpr()
    fact = gp.factorize()
    results = []
    for constant in (True, False):
        m, s = tf.Variable(M_IN), tf.Variable(S_IN)
        with tf.GradientTape() as tape:
            out = moments.moment_match(m, s, fact, constant=constant, deterministic=False)
            L = scalarize(*out)
        gm, gs = (g.numpy() for g in tape.gradient(L, [m, s]))
        # s is defined up to symmetry: only the symmetric part of dL/ds is meaningful
        results.append([o.numpy() for o in out] + [gm, 0.5 * (gs + gs.T)])
    for fused, plain, name in zip(*results, ("M", "S", "V", "dL/dm", "dL/ds")):
        np.testing.assert_allclose(fused, plain, rtol=1e-10, atol=1e-12, err_msg=name)


@pytest.mark.parametrize("E, groups, count", [(1, 4, 1), (2, 2, 2), (3, 4, 3), (4, 3, 3),
                                               (10, 2, 2), (10, 4, 4)])
def test_pair_groups_cover_every_pair_once_the_diagonal_first(E, groups, count):
    P = E * (E + 1) // 2
    ranges = moments.pair_groups(P, E, groups)
    assert ranges[0][0] == 0 and ranges[-1][1] == P and ranges[0][1] >= E
    assert all(a < b for a, b in ranges) and len(ranges) == count
    assert all(b == c for (_, b), (c, _) in zip(ranges[:-1], ranges[1:]))
    sizes = [b - a for a, b in ranges[1:]]
    assert not sizes or max(sizes) - min(sizes) <= 1  # the off-diagonal pairs spread evenly


def test_one_group_of_pairs_whatever_the_threads_unless_asked(monkeypatch):
    """The grouping changes the rounding, so it does not follow the CPUs by itself: one
    block unless PILCO_PAIR_GROUPS asks for a number of groups or one per thread."""
    monkeypatch.setattr(moment_pairs, "_parallel_threads", lambda: 2)
    monkeypatch.delenv("PILCO_PAIR_GROUPS", raising=False)
    assert moments.pair_groups(15, 5) == [(0, 15)]
    monkeypatch.setenv("PILCO_PAIR_GROUPS", "threads")
    assert len(moments.pair_groups(15, 5)) == 2
    monkeypatch.setenv("PILCO_PAIR_GROUPS", "3")
    assert len(moments.pair_groups(15, 5)) == 3
    for bad in ("0", "two"):
        monkeypatch.setenv("PILCO_PAIR_GROUPS", bad)
        with pytest.raises(ValueError, match="PILCO_PAIR_GROUPS"):
            moments.pair_groups(15, 5)


@pytest.mark.parametrize("groups", [2, 3, 4])
def test_grouped_pair_block_equals_one_group(monkeypatch, groups):
    """The output pairs in groups that run side by side (the rollout's path, constant
    factorisation): values and gradients those of the single block, 5 outputs."""
    rng = np.random.default_rng(4)
    X = rng.uniform(-1, 1, (30, 3))
    Y = np.column_stack([np.sin(X @ rng.normal(size=3)) for _ in range(5)])
    gp = MGPR((X, Y + 0.01 * rng.normal(size=Y.shape)))
    for i, m in enumerate(gp.models):
        m.kernel.lengthscales.assign([0.8 + 0.1 * i, 1.2, 0.9])
        m.likelihood.variance.assign(1e-3 * (i + 1))
    fact = gp.factorize()
    w = [rng.standard_normal(shape) for shape in ((1, 5), (5, 5), (3, 5))]
    results = []
    for count in (1, groups):
        monkeypatch.setenv("PILCO_PAIR_GROUPS", str(count))
        assert len(moments.pair_groups(15, 5)) == count
        m, s = tf.Variable(M_IN), tf.Variable(S_IN)
        with tf.GradientTape() as tape:
            out = moments.moment_match(m, s, fact, constant=True)
            L = sum(tf.reduce_sum(wi * o) for wi, o in zip(w, out))
        gm, gs = (g.numpy() for g in tape.gradient(L, [m, s]))
        results.append([o.numpy() for o in out] + [gm, gs])
    for one, grouped, name in zip(*results, ("M", "S", "V", "dL/dm", "dL/ds")):
        np.testing.assert_allclose(grouped, one, rtol=1e-12, atol=1e-14, err_msg=name)
