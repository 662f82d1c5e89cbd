"""Per-transition noise factors of the dynamics GPs (``MGPR.set_data(..., noise_scales=w)``):
transition i has ``w[i]`` times its output's noise variance. Checked against the
heteroscedastic GP's formulas written out in NumPy, against the unscaled model (factors of
1 change nothing), by what a large factor does to a prediction, and through validation,
the sparse model and the agent file; per output (``w [E, N]``) against each output's own
heteroscedastic GP."""
from __future__ import annotations

import numpy as np
import pytest

from pilco.models import MGPR, PILCO, SMGPR
from pilco.rewards import ExponentialReward
from pilco.controllers import LinearController


def data(seed=0, N=25):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-2.0, 2.0, (N, 3))
    Y = np.column_stack([np.sin(X[:, 0]) + 0.3 * X[:, 2], X[:, 1] * X[:, 2]])
    return X, Y + 0.05 * rng.standard_normal(Y.shape)


def model(seed=0, N=25, **kwargs):
    gp = MGPR(data(seed, N), **kwargs)
    for i, m in enumerate(gp.models):  # distinct, trained-looking values
        m.kernel.lengthscales.assign([1.1 + 0.2 * i, 0.8, 1.5 - 0.3 * i])
        m.kernel.variance.assign(0.7 + 0.4 * i)
        m.likelihood.variance.assign(0.01 * (i + 1))
    return gp


def heteroscedastic(gp, w, Xs):
    """Each output's K^-1 y, K^-1, log evidence and latent mean / variance at Xs with
    ``K = k(X, X) + diag(sn2 * w)``, in NumPy."""
    X, Y = (np.asarray(t) for t in gp.data)
    out = []
    for e, m in enumerate(gp.models):
        ell, sf2 = m.kernel.lengthscales.numpy(), float(m.kernel.variance.numpy())
        sn2 = float(m.likelihood.variance.numpy())

        def k(A, B):
            d = (A[:, None, :] - B[None, :, :]) / ell
            return sf2 * np.exp(-0.5 * np.sum(d ** 2, axis=-1))

        K = k(X, X) + np.diag(sn2 * w)
        iK = np.linalg.inv(K)
        beta = iK @ Y[:, e]
        L = np.linalg.cholesky(K)
        a = np.linalg.solve(L, Y[:, e])
        log_ev = -0.5 * a @ a - np.sum(np.log(np.diag(L))) - 0.5 * len(X) * np.log(2 * np.pi)
        Ks = k(Xs, X)
        out.append(dict(beta=beta, iK=iK, log_evidence=log_ev, mean=Ks @ beta,
                        var=sf2 - np.sum(Ks @ iK * Ks, axis=1)))
    return out


def test_factors_of_one_change_nothing():
    gp, plain = model(), model()
    Xs = data(seed=3, N=6)[0]
    gp.set_data(gp.data, noise_scales=np.ones(25))
    f, g = gp.factorize(), plain.factorize()
    np.testing.assert_array_equal(f.beta.numpy(), g.beta.numpy())
    np.testing.assert_array_equal(f.iK.numpy(), g.iK.numpy())
    np.testing.assert_array_equal(gp._model_losses(), plain._model_losses())
    for a, b in zip(gp.predict_f(Xs), plain.predict_f(Xs)):  # GPflow's own prediction
        np.testing.assert_array_equal(a.numpy(), b.numpy())


def test_every_computation_uses_the_factors():
    gp = model()
    w = np.linspace(0.5, 40.0, 25)
    gp.set_data(gp.data, noise_scales=w)
    np.testing.assert_array_equal(gp.noise_scales, w)
    Xs = data(seed=3, N=6)[0]
    want = heteroscedastic(gp, w, Xs)
    f = gp.factorize()  # what moment matching and the policy search use
    mean, var = (t.numpy() for t in gp.predict_f(Xs))
    for e, ref in enumerate(want):
        np.testing.assert_allclose(f.beta.numpy()[e], ref["beta"], rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(f.iK.numpy()[e], ref["iK"], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(mean[:, e], ref["mean"], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(var[:, e], ref["var"], rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(gp.log_marginal_likelihood(),
                               [ref["log_evidence"] for ref in want], rtol=1e-10)
    # the training loss is the negative log evidence (plus soft bounds ~0 here)
    np.testing.assert_allclose(gp._model_losses(), [-ref["log_evidence"] for ref in want],
                               rtol=1e-8)
    # moment matching at a (nearly) certain input gives the same mean
    M, _, _ = gp.predict_on_noisy_inputs(Xs[:1], 1e-12 * np.eye(3))
    np.testing.assert_allclose(M.numpy()[0], mean[0], rtol=1e-6, atol=1e-9)


def test_factors_per_output_give_each_output_its_own_heteroscedastic_gp():
    """``w [E, N]``: output e is the GP with factors ``w[e]``, in every computation
    (factorisation, GPflow-free prediction, evidence, training loss, moment matching)."""
    gp = model()
    w = np.stack([np.linspace(0.5, 40.0, 25), np.linspace(30.0, 1.0, 25)])
    gp.set_data(gp.data, noise_scales=w)
    np.testing.assert_array_equal(gp.noise_scales, w)
    Xs = data(seed=3, N=6)[0]
    f = gp.factorize()
    mean, var = (t.numpy() for t in gp.predict_f(Xs))
    M, S, _ = gp.predict_on_noisy_inputs(Xs[:1], 0.05 * np.eye(3))
    for e in range(2):
        ref = heteroscedastic(gp, w[e], Xs)[e]
        np.testing.assert_allclose(f.beta.numpy()[e], ref["beta"], rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(f.iK.numpy()[e], ref["iK"], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(mean[:, e], ref["mean"], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(var[:, e], ref["var"], rtol=1e-8, atol=1e-12)
        np.testing.assert_allclose(gp.log_marginal_likelihood()[e], ref["log_evidence"],
                                   rtol=1e-10)
        np.testing.assert_allclose(gp._model_losses()[e], -ref["log_evidence"], rtol=1e-8)
        # output e's moments equal those of a model with w[e] for every output
        alike = model()
        alike.set_data(alike.data, noise_scales=w[e])
        M1, S1, _ = alike.predict_on_noisy_inputs(Xs[:1], 0.05 * np.eye(3))
        np.testing.assert_allclose(M.numpy()[0, e], M1.numpy()[0, e], rtol=1e-10)
        np.testing.assert_allclose(S.numpy()[e, e], S1.numpy()[e, e], rtol=1e-10)
    # identical rows are the same as one row: reported as [N]
    gp.set_noise_scales(np.stack([w[0], w[0]]))
    np.testing.assert_array_equal(gp.noise_scales, w[0])
    np.testing.assert_array_equal(gp.factorize().beta.numpy(),
                                  heteroscedastic_beta(gp, w[0]))


def heteroscedastic_beta(gp, w):
    g = model()
    g.set_data(gp.data, noise_scales=w)
    return g.factorize().beta.numpy()


def test_a_large_factor_lets_better_trusted_data_win_where_they_disagree():
    """Old transitions say y = x; new ones, on part of the same inputs, say y = 0. With
    equal factors the prediction there is a compromise; with the old ones' noise 1e4 times
    larger (noise std 0.01 -> 0.32) it follows the new ones, and where only old data exist
    it still follows them."""
    x_old = np.linspace(-3.0, 3.0, 31)[:, None]
    x_new = np.linspace(-3.0, 0.0, 8)[:, None] + 0.05
    X = np.vstack([x_old, x_new])
    Y = np.vstack([x_old, np.zeros_like(x_new)])
    gp = MGPR((X, Y))
    gp.models[0].kernel.lengthscales.assign([1.0])
    gp.models[0].kernel.variance.assign(4.0)
    gp.models[0].likelihood.variance.assign(1e-4)
    probe = np.array([[-1.5], [2.0]])  # on the disputed inputs; on old data only
    equal = gp.predict_f(probe)[0].numpy()[:, 0]
    w = np.concatenate([np.full(len(x_old), 1e3), np.ones(len(x_new))])
    gp.set_data((X, Y), noise_scales=w)
    scaled = gp.predict_f(probe)[0].numpy()[:, 0]
    assert -1.3 < equal[0] < -0.2  # a compromise between -1.5 and 0
    assert abs(scaled[0]) < 0.1  # the new data's answer
    assert abs(scaled[1] - 2.0) < 0.1  # the old data still answer where they are alone
    gp.set_data((X, Y))  # new data without factors: all ones again
    np.testing.assert_array_equal(gp.noise_scales, np.ones(len(X)))
    np.testing.assert_allclose(gp.predict_f(probe)[0].numpy()[:, 0], equal, rtol=1e-12)


def test_training_with_factors_fits_the_trusted_data():
    """The same disagreement as above, hyperparameters trained: the fit with the old data
    down-weighted predicts the new data's values on the disputed inputs."""
    x_old = np.linspace(-3.0, 3.0, 31)[:, None]
    x_new = np.linspace(-3.0, 0.0, 8)[:, None] + 0.05
    X = np.vstack([x_old, x_new])
    Y = np.vstack([x_old, np.zeros_like(x_new)])
    w = np.concatenate([np.full(len(x_old), 100.0), np.ones(len(x_new))])
    plain, gp = MGPR((X, Y)), MGPR((X, Y))
    gp.set_noise_scales(w)
    for m in (plain, gp):
        m.optimize(maxiter=200)
    np.testing.assert_array_equal(gp.noise_scales, w)  # training keeps them
    mean = gp.predict_f(x_new)[0].numpy()[:, 0]
    assert np.max(np.abs(mean)) < 0.2, mean
    assert np.max(np.abs(plain.predict_f(x_new)[0].numpy())) > 1.0  # equals: a compromise


@pytest.mark.parametrize("bad, error, message", [
    (np.ones(24), ValueError, "must have 25 entries"),
    (np.ones((25, 1)), ValueError, r"per output must have shape \[outputs, transitions\]"),
    (np.ones((2, 24)), ValueError, r"\[2, 25\], got \(2, 24\)"),
    (np.ones((1, 2, 25)), ValueError, "must be 1-D .* or 2-D"),
    (np.c_[np.ones((2, 24)), [1.0, -1.0]], ValueError, r"positive.*at index \(1, 24\)"),
    (np.r_[np.ones(24), 0.0], ValueError, "must be positive"),
    (np.r_[np.ones(24), -2.0], ValueError, "must be positive"),
    (np.r_[np.ones(24), np.nan], ValueError, "NaN"),
    (["a"] * 25, TypeError, "strings"),
])
def test_bad_factors_are_refused_and_change_nothing(bad, error, message):
    gp = model()
    before = gp.factorize().beta.numpy()
    for call in (lambda: gp.set_data(gp.data, noise_scales=bad),
                 lambda: gp.set_noise_scales(bad)):
        with pytest.raises(error, match=message):
            call()
    np.testing.assert_array_equal(gp.noise_scales, np.ones(25))
    np.testing.assert_array_equal(gp.factorize().beta.numpy(), before)


def test_the_sparse_model_refuses_factors():
    X, Y = data()
    sparse = SMGPR((X, Y), num_induced_points=5)
    sparse.set_data((X, Y), noise_scales=np.ones(25))  # ones are fine
    with pytest.raises(ValueError, match="SMGPR"):
        sparse.set_data((X, Y), noise_scales=np.full(25, 2.0))
    with pytest.raises(ValueError, match="SMGPR"):
        sparse.set_noise_scales(np.full(25, 2.0))


def agent(N=12):
    rng = np.random.default_rng(0)
    X, Y = rng.normal(size=(N, 3)), 0.1 * rng.normal(size=(N, 2))
    return PILCO((X, Y), LinearController(2, 1), ExponentialReward(2, t=np.ones(2)),
                 horizon=3)


def test_the_agent_passes_factors_on_and_its_file_keeps_them(tmp_path):
    a = agent()
    w = np.r_[np.full(8, 50.0), np.ones(4)]
    a.set_data(a.data, noise_scales=w)
    np.testing.assert_array_equal(a.mgpr.noise_scales, w)
    loaded = PILCO.load(a.save(tmp_path / "agent.npz"))
    np.testing.assert_array_equal(loaded.mgpr.noise_scales, w)
    assert loaded.expected_return() == pytest.approx(a.expected_return(), rel=1e-12)
    per_output = np.stack([w, np.ones(12)])
    a.set_data(a.data, noise_scales=per_output)
    loaded = PILCO.load(a.save(tmp_path / "per-output.npz"))
    np.testing.assert_array_equal(loaded.mgpr.noise_scales, per_output)
    assert loaded.expected_return() == pytest.approx(a.expected_return(), rel=1e-12)
    a.set_data(a.data)  # data without factors: all ones
    np.testing.assert_array_equal(PILCO.load(a.save(tmp_path / "b.npz")).mgpr.noise_scales,
                                  np.ones(12))
