"""Exact moment matching against Monte Carlo.

Every analytic mean / covariance / input-output covariance of the library is compared
with a Monte Carlo estimate from ``N_MC`` samples drawn with a fixed seed. The
tolerance of each entry is ``Z_TOL`` times that entry's own Monte Carlo standard error
(estimated from the samples: the estimators below are sample means of per-sample
terms, so their standard error is ``std(term) / sqrt(n)``). With ``Z_TOL = 5`` a correct
formula fails with probability ~6e-7 per entry, and the seed is fixed anyway.

A tolerance is only useful if it is tight compared with the errors it must catch, so
every test also asserts that deliberately wrong formulas (ignoring the input
uncertainty, dropping the latent GP variance, dropping cross-covariances, a factor of
2, confusing ``V`` with ``Cov[x, f]``...) land at least ``SEP`` standard errors away
from the Monte Carlo estimate.

GP predictions at the samples come from GPflow's own ``predict_f`` (``GPR`` /
``GPRFITC``), independent of :mod:`pilco.moments`. Latent GP uncertainty is
Rao-Blackwellised: ``E[f] = mean(mu(x))``, ``Var[f_i] = mean(var_i(x)) + Var(mu_i(x))``
and, the outputs being independent given x, ``Cov[f_i, f_j] = Cov(mu_i(x), mu_j(x))``.

Moment matching is exact for one nonlinear map of a Gaussian. Where the library
chains maps (the squashing of an RBF policy's output, the policy and the dynamics GP
on (sin, cos) features, the cart-pole reward on trig features, a PILCO step), it
matches each intermediate distribution by a Gaussian, as PILCO does; those are checked
stage by stage, each stage exactly against Monte Carlo from the matched Gaussian of
the previous one. A whole PILCO step is exact, and checked as such, only when every
intermediate quantity is Gaussian (an unsquashed linear policy without angles).
"""
from __future__ import annotations

import gpflow
import numpy as np
import pytest

from pilco.angles import augment_state, trig_moments
from pilco.controllers import LinearController, RbfController, squash_sat, squash_sin
from pilco.models import MGPR, PILCO, SMGPR
from pilco.rewards import AxisBumpsReward, CartPoleReward, ExponentialReward

N_MC = 200_000
Z_TOL = 5.0  # tolerance, in Monte Carlo standard errors
SEP = 10.0  # a wrong formula must be at least this many standard errors off
ATOL = 1e-9  # floating-point slack for entries whose standard error is ~0


# ---------------------------------------------------------------------------
# Monte Carlo helpers
# ---------------------------------------------------------------------------


def np_(x):
    return np.asarray(x.numpy() if hasattr(x, "numpy") else x, dtype=float)


def gauss(rng, m, s, n=N_MC):
    """n samples of N(m, s); s may be singular (eigen-decomposition)."""
    m = np.reshape(np.asarray(m, dtype=float), -1)
    vals, vecs = np.linalg.eigh(0.5 * (s + s.T))
    L = vecs * np.sqrt(np.clip(vals, 0.0, None))
    return m + rng.standard_normal((n, len(m))) @ L.T


def mc_mean(F):
    """Sample mean [p] and its standard error [p]."""
    return F.mean(0), F.std(0) / np.sqrt(len(F))


def mc_cov(A, B=None, latent_var=None):
    """Sample Cov[A, B] [p, q] and its standard error.

    ``latent_var`` [n, p] adds a per-sample conditional variance to the diagonal
    (Rao-Blackwellised latent GP uncertainty, only with ``B is None``).
    """
    Ac = A - A.mean(0)
    Bc = Ac if B is None else B - B.mean(0)
    terms = Ac[:, :, None] * Bc[:, None, :]
    if latent_var is not None:
        idx = np.arange(A.shape[1])
        terms[:, idx, idx] += latent_var
    return terms.mean(0), terms.std(0) / np.sqrt(len(A))


def assert_mc(name, analytic, estimate, se, z=Z_TOL, atol=ATOL):
    analytic = np.reshape(np_(analytic), np.shape(estimate))
    err = np.abs(analytic - estimate)
    zs = err / np.maximum(se, 1e-300)
    ok = err <= z * se + atol
    assert ok.all(), (
        f"{name}: analytic differs from Monte Carlo by up to {zs[~ok].max():.1f} standard "
        f"errors\nanalytic:\n{analytic}\nMonte Carlo:\n{estimate}\nstandard error:\n{se}"
    )


def assert_rejects(name, wrong, estimate, se, sep=SEP):
    """The Monte Carlo check is sharp enough to reject the wrong value ``wrong``."""
    wrong = np.reshape(np_(wrong), np.shape(estimate))
    zs = np.abs(wrong - estimate) / np.maximum(se, 1e-300)
    assert zs.max() > sep, (
        f"the Monte Carlo test cannot tell the wrong formula '{name}' apart "
        f"(only {zs.max():.1f} standard errors off)"
    )


def gp_latent(models, X):
    """GPflow's own latent predictive mean and variance, stacked: [n, E], [n, E]."""
    mus, vs = zip(*(mod.predict_f(X) for mod in models))
    return np.hstack([np_(v) for v in mus]), np.hstack([np_(v) for v in vs])


def squash_np(v, e, squash):
    if squash is None:
        return v
    if squash is squash_sin:
        return e * np.sin(v)
    if squash is squash_sat:
        return e * (9.0 * np.sin(v) + np.sin(3.0 * v)) / 8.0
    raise ValueError(squash)


def policy_np(ctrl, Z, squash=True):
    """A policy's action at deterministic inputs Z [n, F], without pilco.moments.

    The RBF policy is the posterior mean of GPflow GPRs built on its centers/targets.
    """
    if isinstance(ctrl, RbfController):
        centers, targets = np_(ctrl.centers), np_(ctrl.targets)
        out = []
        for i, g in enumerate(ctrl.models):
            gpr = gpflow.models.GPR(
                (centers, targets[:, i : i + 1]),
                kernel=gpflow.kernels.SquaredExponential(
                    variance=np_(g.kernel.variance), lengthscales=np_(g.kernel.lengthscales)),
                noise_variance=np_(g.likelihood.variance),
            )
            out.append(np_(gpr.predict_f(Z)[0]))
        v = np.hstack(out)
    else:
        v = Z @ np_(ctrl.W).T + np_(ctrl.b)
    return squash_np(v, ctrl.max_action, ctrl.squash if squash else None)


def features_np(X, angle_indices):
    """[x_other, sin θ1, cos θ1, ...] as PILCO feeds the policy and the GP."""
    keep = [d for d in range(X.shape[1]) if d not in angle_indices]
    trig = [np.column_stack([np.sin(X[:, a]), np.cos(X[:, a])]) for a in angle_indices]
    return np.hstack([X[:, keep]] + trig)


# ---------------------------------------------------------------------------
# Dynamics models
# ---------------------------------------------------------------------------


def regression_data(seed=0, N=30):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-2.0, 2.0, (N, 3))
    Y = np.column_stack([
        np.sin(X[:, 0]) + 0.5 * np.cos(X[:, 1]) * X[:, 2],
        0.8 * np.sin(X[:, 0]) + np.cos(X[:, 0] + X[:, 1]) - 0.2 * X[:, 2] ** 2,
    ]) + 0.05 * rng.standard_normal((N, 2))
    return X, Y


def assign_hyperparameters(gp):
    ell = [[1.0, 1.3, 1.6], [0.9, 1.1, 1.8]]
    for i, mod in enumerate(gp.models):
        mod.kernel.lengthscales.assign(ell[i])
        mod.kernel.variance.assign([1.0, 0.7][i])
        mod.likelihood.variance.assign([0.01, 0.02][i])


M_IN = np.array([[0.3, -0.4, 0.8]])
S_IN = np.array([[0.5, 0.2, -0.1], [0.2, 0.4, 0.15], [-0.1, 0.15, 0.6]])


def check_gp_against_mc(gp, rng):
    M, S, V = (np_(v) for v in gp.predict_on_noisy_inputs(M_IN, S_IN))
    x = gauss(rng, M_IN, S_IN)
    mu, var = gp_latent(gp.models, x)
    m_mc, m_se = mc_mean(mu)
    S_mc, S_se = mc_cov(mu, latent_var=var)
    C_mc, C_se = mc_cov(x, mu)
    assert M.shape == (1, 2) and S.shape == (2, 2) and V.shape == (3, 2)
    assert_mc("M", M, m_mc, m_se)
    assert_mc("S", S, S_mc, S_se)
    assert_mc("Cov[x, f] = s V", S_IN @ V, C_mc, C_se)

    # each term matters at this tolerance
    mu0, _ = gp_latent(gp.models, M_IN)
    assert_rejects("mean at the input mean (no input uncertainty)", mu0, m_mc, m_se)
    lat = np.diag(var.mean(0))
    assert_rejects("S without the latent variance", S - lat, S_mc, S_se)
    assert_rejects("S with twice the latent variance", S + lat, S_mc, S_se)
    assert_rejects("S without output cross-covariance", np.diag(np.diag(S)), S_mc, S_se)
    assert_rejects("V taken as Cov[x, f]", V, C_mc, C_se)
    return M, S, V, (m_mc, m_se, S_mc, S_se)


def test_mgpr_moments_match_monte_carlo():
    gp = MGPR(regression_data())
    assign_hyperparameters(gp)
    check_gp_against_mc(gp, np.random.default_rng(1))


def test_smgpr_moments_match_monte_carlo_of_its_fitc_predictive():
    rng = np.random.default_rng(2)
    data = regression_data()
    gp = SMGPR(data, num_induced_points=8, seed=0)
    assign_hyperparameters(gp)
    gp.models[0].inducing_variable.Z.assign(rng.uniform(-2.0, 2.0, (8, 3)))
    assert all(isinstance(mod, gpflow.models.GPRFITC) for mod in gp.models)
    _, _, _, (m_mc, m_se, S_mc, S_se) = check_gp_against_mc(gp, rng)

    # the sparse predictor really differs from the exact GP on the same data
    full = MGPR(data)
    assign_hyperparameters(full)
    _, Sf, _ = full.predict_on_noisy_inputs(M_IN, S_IN)
    assert_rejects("exact GP moments instead of FITC", Sf, S_mc, S_se)


# ---------------------------------------------------------------------------
# Policies and squashing
# ---------------------------------------------------------------------------


def make_rbf(squash, seed=3):
    rng = np.random.default_rng(seed)
    ctrl = RbfController(3, 2, 10, max_action=[2.0, 0.5], squash=squash, seed=seed)
    ctrl.set_data((rng.uniform(-1.5, 1.5, (10, 3)), 1.2 * rng.standard_normal((10, 2))))
    for i, g in enumerate(ctrl.models):
        g.kernel.lengthscales.assign([[0.8, 1.0, 1.3], [1.2, 0.7, 1.0]][i])
    return ctrl


def check_policy(ctrl, m_yz, S_yz, k, rng):
    """Policy moments at a Gaussian input, in its two exact stages.

    ``(y, z) ~ N(m_yz, S_yz)`` where z = the last columns is the policy's input and y
    (the first k columns) any other Gaussian variables correlated with it.

    1. The raw (unsquashed) action v = policy(z) is checked by Monte Carlo exactly:
       mean, covariance and ``Cov[(y, z), v] = Cov[(y, z), z] V``.
    2. The squashed action u = squash(v): PILCO squashes the Gaussian that matches the
       moments of v (v itself is not Gaussian for a nonlinear policy), so u is checked
       against Monte Carlo of ``(y, z, v)`` drawn from that matched Gaussian.

    Returns the Monte Carlo statistics of the last stage: (u samples, m_mc, m_se, S_mc,
    S_se, C_mc, C_se) with C = Cov[(y, z), u].
    """
    Mz, Sz = m_yz[:, k:], S_yz[k:, k:]
    Mr, Sr, Vr = (np_(v) for v in ctrl.compute_action(Mz, Sz, squash=False))
    yz = gauss(rng, m_yz, S_yz)
    v = policy_np(ctrl, yz[:, k:], squash=False)
    m_mc, m_se = mc_mean(v)
    S_mc, S_se = mc_cov(v)
    if isinstance(ctrl, RbfController):  # deterministic GP: documented 1e-6 jitter
        S_mc = S_mc + 1e-6 * np.eye(v.shape[1])
    C_mc, C_se = mc_cov(yz, v)
    assert_mc("raw action mean", Mr, m_mc, m_se)
    assert_mc("raw action covariance", Sr, S_mc, S_se)
    assert_mc("Cov[input, raw action] = s V", S_yz[:, k:] @ Vr, C_mc, C_se)
    stats = (v, m_mc, m_se, S_mc, S_se, C_mc, C_se)
    if ctrl.squash is None:
        return stats
    Ms, Ss, Vs = (np_(v) for v in ctrl.compute_action(Mz, Sz, squash=True))
    cross = S_yz[:, k:] @ Vr
    yzv = gauss(rng, np.hstack([m_yz, Mr]), np.block([[S_yz, cross], [cross.T, Sr]]))
    u = squash_np(yzv[:, S_yz.shape[0]:], ctrl.max_action, ctrl.squash)
    m_mc, m_se = mc_mean(u)
    S_mc, S_se = mc_cov(u)
    C_mc, C_se = mc_cov(yzv[:, : S_yz.shape[0]], u)
    assert_mc("squashed action mean", Ms, m_mc, m_se)
    assert_mc("squashed action covariance", Ss, S_mc, S_se)
    assert_mc("Cov[input, squashed action] = s V", S_yz[:, k:] @ Vs, C_mc, C_se)
    return (u, m_mc, m_se, S_mc, S_se, C_mc, C_se)


@pytest.mark.parametrize("squash", [None, squash_sin, squash_sat], ids=["raw", "sin", "sat"])
def test_rbf_controller_matches_monte_carlo(squash):
    ctrl = make_rbf(squash)
    rng = np.random.default_rng(4)
    M, S, V = (np_(v) for v in ctrl.compute_action(M_IN, S_IN))
    _, m_mc, m_se, S_mc, S_se, C_mc, C_se = check_policy(ctrl, M_IN, S_IN, 0, rng)

    u0 = policy_np(ctrl, M_IN)
    assert_rejects("action at the mean state", u0, m_mc, m_se)
    assert_rejects("no action cross-covariance", np.diag(np.diag(S)), S_mc, S_se)
    assert_rejects("V taken as Cov[x, u]", V, C_mc, C_se)
    if squash is not None:
        Mr, Sr, _ = (np_(v) for v in ctrl.compute_action(M_IN, S_IN, squash=False))
        assert_rejects("squash of the raw mean", squash_np(Mr, ctrl.max_action, squash),
                       m_mc, m_se)
        assert_rejects("S without the 1/2 of the sine product formula", 2 * S, S_mc, S_se)
        assert_rejects("raw action covariance", Sr, S_mc, S_se)


@pytest.mark.parametrize("squash", [squash_sin, squash_sat], ids=["sin", "sat"])
def test_squash_alone_matches_monte_carlo(squash):
    m = np.array([[0.7, -1.1]])
    # variances small enough that the sin(3v) term of squash_sat is not damped away
    s = np.array([[0.15, 0.06], [0.06, 0.25]])
    e = np.array([2.0, 0.5])
    M, S, C = (np_(v) for v in squash(m, s, e))
    v = gauss(np.random.default_rng(5), m, s)
    u = squash_np(v, e, squash)
    m_mc, m_se = mc_mean(u)
    S_mc, S_se = mc_cov(u)
    C_mc, C_se = mc_cov(v, u)
    assert_mc("M", M, m_mc, m_se)
    assert_mc("S", S, S_mc, S_se)
    assert_mc("Cov[v, u] = s C", s @ C, C_mc, C_se)

    assert_rejects("squash of the mean", squash_np(m, e, squash), m_mc, m_se)
    assert_rejects("2 S", 2 * S, S_mc, S_se)
    assert_rejects("no cross-covariance", np.diag(np.diag(S)), S_mc, S_se)
    assert_rejects("C taken as Cov[v, u]", C, C_mc, C_se)
    other = squash_sat if squash is squash_sin else squash_sin
    assert_rejects("the other squashing function", np_(other(m, s, e)[1]), S_mc, S_se)


def test_squash_default_max_action_is_one():
    m, s = np.array([[0.3]]), np.array([[0.2]])
    for squash in (squash_sin, squash_sat):
        for a, b in zip(squash(m, s), squash(m, s, 1.0)):
            np.testing.assert_allclose(np_(a), np_(b), rtol=1e-14)


# ---------------------------------------------------------------------------
# Angles
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("scale", [None, [1.5, 0.7]], ids=["unit", "scaled"])
def test_trig_moments_match_monte_carlo(scale):
    m = np.array([[0.4, -1.0, 2.0]])
    s = np.array([[0.5, 0.1, 0.3], [0.1, 0.3, -0.1], [0.3, -0.1, 0.8]])
    idx = [0, 2]
    M, S, C = (np_(v) for v in trig_moments(m, s, idx, scale))
    assert M.shape == (1, 4) and S.shape == (4, 4) and C.shape == (3, 4)
    x = gauss(np.random.default_rng(6), m, s)
    e = np.repeat(np.ones(2) if scale is None else np.asarray(scale), 2)
    f = features_np(x, idx)[:, 1:] * e  # interleaved [sin x0, cos x0, sin x2, cos x2]
    m_mc, m_se = mc_mean(f)
    S_mc, S_se = mc_cov(f)
    C_mc, C_se = mc_cov(x, f)
    assert_mc("M", M, m_mc, m_se)
    assert_mc("S", S, S_mc, S_se)
    assert_mc("Cov[x, trig] = s C", s @ C, C_mc, C_se)

    f0 = features_np(m, idx)[:, 1:] * e
    assert_rejects("trig of the mean (no damping)", f0, m_mc, m_se)
    assert_rejects("2 S", 2 * S, S_mc, S_se)
    block = np.kron(np.eye(2), np.ones((2, 2)))
    assert_rejects("angles independent", S * block, S_mc, S_se)
    assert_rejects("C taken as Cov[x, trig]", C, C_mc, C_se)


@pytest.mark.parametrize("angles", [[1], [0, 2], [0, 1, 2]], ids=["one", "two", "all"])
def test_augment_state_matches_monte_carlo(angles):
    m = np.array([[0.4, -1.0, 2.0]])
    s = np.array([[0.5, 0.1, 0.3], [0.1, 0.3, -0.1], [0.3, -0.1, 0.8]])
    Mf, Sf, Cf = (np_(v) for v in augment_state(m, s, angles))
    assert Mf.shape == (1, 3 + len(angles)) and Cf.shape == (3, 3 + len(angles))
    x = gauss(np.random.default_rng(7), m, s)
    f = features_np(x, angles)
    m_mc, m_se = mc_mean(f)
    S_mc, S_se = mc_cov(f)
    C_mc, C_se = mc_cov(x, f)
    assert_mc("Mf", Mf, m_mc, m_se)
    assert_mc("Sf", Sf, S_mc, S_se)
    assert_mc("Cov[x, features] = s Cf", s @ Cf, C_mc, C_se)


# ---------------------------------------------------------------------------
# Rewards
# ---------------------------------------------------------------------------


def test_exponential_reward_matches_monte_carlo():
    rng = np.random.default_rng(8)
    A = rng.standard_normal((3, 3))
    W = 0.5 * (A @ A.T) + 0.5 * np.eye(3)
    t = np.array([[0.5, -0.2, 1.0]])
    m = np.array([[0.1, 0.3, 0.6]])
    s = np.array([[0.3, 0.05, 0.1], [0.05, 0.2, -0.05], [0.1, -0.05, 0.4]])
    reward = ExponentialReward(3, W, t)
    mean, var = (np_(v) for v in reward.compute_reward(m, s))
    assert mean.shape == (1, 1) and var.shape == (1, 1)
    x = gauss(rng, m, s)
    d = x - t
    r = np.exp(-0.5 * np.einsum("ni,ij,nj->n", d, W, d))[:, None]
    r_mc, r_se = mc_mean(r)
    v_mc, v_se = mc_cov(r)
    assert_mc("E[r]", mean, r_mc, r_se)
    assert_mc("Var[r]", var, v_mc, v_se)

    assert_rejects("reward of the mean state", np.exp(-0.5 * (m - t) @ W @ (m - t).T),
                   r_mc, r_se)
    # E[r^2] is the mean of the reward with 2W; with W instead it is off by a factor 2
    wrong_var = mean - mean ** 2
    assert_rejects("E[r^2] computed with W instead of 2W", wrong_var, v_mc, v_se)
    assert_rejects("variance 0", 0.0 * var, v_mc, v_se)


def test_axis_bumps_match_monte_carlo():
    """One bump per dimension and a diagonal covariance: the bumps are independent, so the
    summed variance (covariances neglected) is exact."""
    rng = np.random.default_rng(9)
    dims, t, w, c = [0, 2, 1], np.array([0.4, -0.3, 1.0]), np.array([0.3, 0.5, 0.2]), \
        np.array([1.0, -0.5, 2.0])
    m = np.array([[0.1, 0.8, -0.1]])
    s = np.diag([0.2, 0.05, 0.3])
    mean, var = (np_(v) for v in AxisBumpsReward(3, dims, t, w, c).compute_reward(m, s))
    assert mean.shape == (1, 1) and var.shape == (1, 1)
    x = gauss(rng, m, s)
    r = (c * np.exp(-0.5 * (x[:, dims] - t) ** 2 / w ** 2)).sum(1, keepdims=True)
    r_mc, r_se = mc_mean(r)
    v_mc, v_se = mc_cov(r)
    assert_mc("E[r]", mean, r_mc, r_se)
    assert_mc("Var[r]", var, v_mc, v_se)
    assert_rejects("bumps at the mean state", r.mean() * 0 + (c * np.exp(
        -0.5 * (m[0, dims] - t) ** 2 / w ** 2)).sum(), r_mc, r_se)


def cartpole_reward_np(x, ell=0.5, w=0.25):
    """exp(-d^2 / (2 w^2)), d the distance of the tip (x + l sin θ, -l cos θ) to (0, l)."""
    tip_x, tip_y = x[:, 0] + ell * np.sin(x[:, 3]), -ell * np.cos(x[:, 3])
    return np.exp(-0.5 * (tip_x ** 2 + (tip_y - ell) ** 2) / w ** 2)[:, None]


def test_cartpole_reward_matches_monte_carlo():
    """Exact for the Gaussian matched to (x, sin θ, cos θ), as MATLAB's loss_cp.

    (sin θ, cos θ) is not Gaussian, so against the true reward the moments are a
    (close) approximation; that is checked with a stated relative tolerance.
    """
    reward = CartPoleReward(pendulum_length=0.5, width=0.25)
    m = np.array([[0.1, 0.2, -0.3, np.pi - 0.3]])
    s = np.diag([0.04, 0.1, 0.2, 0.08])
    s[0, 3] = s[3, 0] = 0.03
    s[2, 3] = s[3, 2] = -0.05
    mean, var = (np_(v) for v in reward.compute_reward(m, s))
    rng = np.random.default_rng(9)

    # exact: the state augmented with (sin θ, cos θ), matched by a Gaussian
    Mt, St, Ct = (np_(v) for v in trig_moments(m, s, [3]))
    cross = s @ Ct
    y = gauss(rng, np.hstack([m, Mt]), np.block([[s, cross], [cross.T, St]]))
    ell, w = 0.5, 0.25
    d2 = (y[:, 0] + ell * y[:, 4]) ** 2 + (ell * y[:, 5] + ell) ** 2
    r = np.exp(-0.5 * d2 / w ** 2)[:, None]
    r_mc, r_se = mc_mean(r)
    v_mc, v_se = mc_cov(r)
    assert_mc("E[r]", mean, r_mc, r_se)
    assert_mc("Var[r]", var, v_mc, v_se)

    assert_rejects("reward of the mean state", cartpole_reward_np(m), r_mc, r_se)
    s_no_angle = s.copy()
    s_no_angle[3, :] = s_no_angle[:, 3] = 0.0
    _, wrong_var = (np_(v) for v in reward.compute_reward(m, s_no_angle))
    assert_rejects("angle uncertainty ignored (variance)", wrong_var, v_mc, v_se)

    # the true reward of the Gaussian state: a close approximation
    r_true = cartpole_reward_np(gauss(rng, m, s))
    np.testing.assert_allclose(mean[0, 0], r_true.mean(), rtol=0.01)
    np.testing.assert_allclose(var[0, 0], r_true.var(), rtol=0.04)


# ---------------------------------------------------------------------------
# PILCO rollouts
# ---------------------------------------------------------------------------


def toy_pilco(controller_kind, angle_indices=(), seed=10):
    """A 2-D state [p, θ], 1-D action system with its GP trained on toy transitions."""
    rng = np.random.default_rng(seed)
    N = 40
    S = np.column_stack([rng.uniform(-1.5, 1.5, N), rng.uniform(-np.pi, np.pi, N)])
    U = rng.uniform(-1.0, 1.0, (N, 1))
    dS = np.column_stack([0.4 * np.sin(S[:, 1]) + 0.3 * U[:, 0],
                          0.4 * U[:, 0] - 0.2 * S[:, 0] * np.cos(S[:, 1])])
    dS += 0.02 * rng.standard_normal(dS.shape)
    F = 2 + len(angle_indices)
    if controller_kind == "linear":
        ctrl = LinearController(F, 1, squash=None)
        ctrl.W.assign(rng.uniform(-1.0, 1.0, (1, F)))
        ctrl.b.assign([[0.2]])
    else:
        squash = squash_sin if controller_kind == "rbf_sin" else squash_sat
        ctrl = RbfController(F, 1, 5, max_action=1.5, squash=squash, seed=seed)
        ctrl.set_data((rng.uniform(-1.0, 1.0, (5, F)), rng.standard_normal((5, 1))))
    p = PILCO((np.hstack([S, U]), dS), ctrl, ExponentialReward(2), horizon=5,
              angle_indices=angle_indices)
    for i, mod in enumerate(p.mgpr.models):
        mod.kernel.lengthscales.assign(np.full(F + 1, 1.2))
        mod.kernel.variance.assign(0.3)
        mod.likelihood.variance.assign(1e-3)
    return p


def true_step_mc(p, m, s, rng):
    """x' = x + f(z(x), u(z(x))) with x ~ N(m, s), the GP's latent uncertainty included."""
    x = gauss(rng, m, s)
    z = features_np(x, p.angle_indices)
    u = policy_np(p.controller, z)
    mu, var = gp_latent(p.mgpr.models, np.hstack([z, u]))
    return x, mu, var


def matched_input(p, m, s):
    """PILCO's Gaussian for (x, z, u): features and action moment-matched, x linear in z.

    Built from :func:`augment_state` and ``controller.compute_action`` (both checked
    against Monte Carlo above): mean [1, D+F+U], covariance [D+F+U, D+F+U].
    """
    Mf, Sf, Cf = (np_(v) for v in augment_state(m, s, p.angle_indices))
    Mu, Su, Cu = (np_(v) for v in p.controller.compute_action(Mf, Sf))
    sCf = s @ Cf
    mean = np.hstack([m, Mf, Mu])
    cov = np.block([
        [s, sCf, sCf @ Cu],
        [sCf.T, Sf, Sf @ Cu],
        [(sCf @ Cu).T, (Sf @ Cu).T, Su],
    ])
    return mean, cov


def check_matched_input(p, m, s, rng):
    """Stage 1: (x, z) Gaussian with exact moments; the policy's action at z, by stages."""
    D, F = p.state_dim, p.feature_dim
    mean, cov = matched_input(p, m, s)
    u, m_mc, m_se, S_mc, S_se, C_mc, C_se = check_policy(
        p.controller, mean[:, : D + F], cov[: D + F, : D + F], D, rng)
    # the action blocks of PILCO's matched Gaussian are these moments
    assert_mc("action mean", mean[:, D + F :], m_mc, m_se)
    assert_mc("action covariance", cov[D + F :, D + F :], S_mc, S_se)
    assert_mc("Cov[(x, z), u]", cov[: D + F, D + F :], C_mc, C_se)


def surrogate_step_mc(p, m, s, rng):
    """Stage 2: (x, z, u) from PILCO's matched Gaussian, pushed through the GP."""
    D = p.state_dim
    mean, cov = matched_input(p, m, s)
    xzu = gauss(rng, mean, cov)
    mu, var = gp_latent(p.mgpr.models, xzu[:, D:])
    return xzu[:, :D], mu, var


def check_step(name, m1, s1, x, mu, var, sharp=False):
    xn = x + mu
    m_mc, m_se = mc_mean(xn)
    S_mc, S_se = mc_cov(xn, latent_var=var)
    assert_mc(f"{name}: mean", m1, m_mc, m_se)
    assert_mc(f"{name}: covariance", s1, S_mc, S_se)
    if sharp:  # the cross-covariance Cov[x, Δ] and the latent variance both matter
        dS, _ = mc_cov(mu, latent_var=var)
        assert_rejects(f"{name}: Cov[x, Δ] dropped", np.cov(x.T) + dS, S_mc, S_se)
        assert_rejects(f"{name}: latent variance dropped", s1 - np.diag(var.mean(0)),
                       S_mc, S_se)


M0 = np.array([[0.2, 0.6]])
S0 = np.array([[0.08, 0.02], [0.02, 0.12]])


def test_pilco_one_step_exact_for_gaussian_policy():
    """Unsquashed linear policy, no angles: (x, u) is Gaussian and one step is exact."""
    p = toy_pilco("linear")
    m1, s1 = (np_(v) for v in p.propagate(M0, S0))
    x, mu, var = true_step_mc(p, M0, S0, np.random.default_rng(11))
    check_step("one step", m1, s1, x, mu, var, sharp=True)


@pytest.mark.parametrize("kind,angles", [("rbf_sin", (1,)), ("rbf_sat", ())],
                         ids=["rbf-sin-angle", "rbf-sat"])
def test_pilco_one_step_stages_for_nonlinear_policy(kind, angles):
    """Squashed RBF policy (and angles): each stage of PILCO's step, exactly."""
    p = toy_pilco(kind, angles)
    rng = np.random.default_rng(12)
    # stage 0: features of the Gaussian state (exact moments, x ~ N(m, s))
    mean, cov = matched_input(p, M0, S0)
    D, F = p.state_dim, p.feature_dim
    x = gauss(rng, M0, S0)
    xz = np.hstack([x, features_np(x, angles)])
    m_mc, m_se = mc_mean(xz)
    S_mc, S_se = mc_cov(xz)
    assert_mc("state and features: mean", mean[:, : D + F], m_mc, m_se)
    assert_mc("state and features: covariance", cov[: D + F, : D + F], S_mc, S_se)
    # stage 1: the policy's moments under the Gaussian features
    check_matched_input(p, M0, S0, rng)
    # stage 2: the dynamics GP on the matched Gaussian, every cross-covariance kept
    m1, s1 = (np_(v) for v in p.propagate(M0, S0))
    check_step("one step", m1, s1, *surrogate_step_mc(p, M0, S0, rng), sharp=True)


@pytest.mark.parametrize("kind,angles", [("linear", ()), ("rbf_sin", (1,))],
                         ids=["linear-exact", "rbf-sin-angle"])
def test_pilco_trajectory_matches_monte_carlo_with_gaussian_refit(kind, angles):
    """5 steps: from N(M_t, S_t), one step by Monte Carlo must give M_{t+1}, S_{t+1}."""
    p = toy_pilco(kind, angles)
    H = 5
    M, S = (np_(v) for v in p.predict_trajectory(M0, S0, H))
    assert M.shape == (H + 1, 2) and S.shape == (H + 1, 2, 2)
    np.testing.assert_allclose(M[0], M0[0])
    np.testing.assert_allclose(S[0], S0)
    m1, s1 = (np_(v) for v in p.propagate(M0, S0))
    np.testing.assert_allclose(M[1], m1[0], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(S[1], s1, rtol=1e-10, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(S) > 0)
    rng = np.random.default_rng(13)
    exact = kind == "linear" and not angles
    for t in range(H):
        m_t, s_t = M[t : t + 1], S[t]
        if exact:
            sample = true_step_mc(p, m_t, s_t, rng)
        else:
            check_matched_input(p, m_t, s_t, rng)
            sample = surrogate_step_mc(p, m_t, s_t, rng)
        check_step(f"step {t + 1}", M[t + 1 : t + 2], S[t + 1], *sample)
    # the state distribution moved and spread: the check covers non-trivial steps
    assert np.abs(M[H] - M[0]).max() > 0.1
