"""MGPR behaves like a GPflow model (issue #53, part A).

A small data set (2-D input, 2 outputs, 50 points) beside ``gpflow.models.GPR``: GPflow's
optimiser on ``training_loss`` trains it as its own ``optimize`` does; ``predict_f``,
``predict_y`` and ``predict_log_density`` agree with one GPR per output holding the same
hyperparameters; predictions compile with ``tf.function``; bad inputs give one clear
error each; ``print_summary`` lists the hyperparameters once; the example runs.
"""
from __future__ import annotations

import os
import runpy
import subprocess
import sys

import gpflow
import numpy as np
import pytest
import tensorflow as tf
from check_shapes import get_check_shapes

from pilco.controllers import LinearController, RbfController
from pilco.models import MGPR, PILCO
from pilco.rewards import ExponentialReward

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TOL = 1e-10


def _data(n=50, seed=0):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-2.0, 2.0, (n, 2))
    Y = np.c_[np.sin(X[:, 0]) * X[:, 1], np.cos(1.5 * X[:, 1])] + 0.05 * rng.standard_normal((n, 2))
    return X, Y


def _gprs(model: MGPR, X, Y):
    """One gpflow GPR per output with the model's hyperparameters."""
    out = []
    for e, m in enumerate(model.models):
        gpr = gpflow.models.GPR((X, Y[:, e:e + 1]),
                                kernel=gpflow.kernels.SquaredExponential(lengthscales=np.ones(2)))
        gpr.kernel.lengthscales.assign(m.kernel.lengthscales)
        gpr.kernel.variance.assign(m.kernel.variance)
        gpr.likelihood.variance.assign(m.likelihood.variance)
        out.append(gpr)
    return out


@pytest.fixture(scope="module")
def trained():
    X, Y = _data()
    model = MGPR((X, Y))
    model.optimize(maxiter=200)
    return model, X, Y, _gprs(model, X, Y)


@pytest.fixture(scope="module")
def Xs():
    return np.random.default_rng(1).uniform(-2.5, 2.5, (7, 2))


def test_scipy_on_training_loss_equals_optimize():
    X, Y = _data()
    own, theirs = MGPR((X, Y)), MGPR((X, Y))
    losses = own.optimize(maxiter=200)
    result = gpflow.optimizers.Scipy().minimize(theirs.training_loss, theirs.trainable_variables,
                                                options=dict(maxiter=200), method="L-BFGS-B")
    assert result.success
    np.testing.assert_allclose(float(theirs.training_loss()), float(np.sum(losses)),
                               rtol=1e-8)
    for a, b in zip(own.trainable_parameters, theirs.trainable_parameters):
        np.testing.assert_allclose(a.numpy(), b.numpy(), rtol=1e-4)


def test_objective_and_loss_follow_gpflow(trained):
    model, X, Y, gprs = trained
    assert isinstance(model, gpflow.models.BayesianModel)
    assert isinstance(model, gpflow.base.Module)
    loss = float(model.training_loss())
    objective = float(model.maximum_log_likelihood_objective())
    assert loss == pytest.approx(-(objective + float(model.log_prior_density())), rel=1e-12)
    assert float(model.training_loss_closure()()) == pytest.approx(loss, rel=1e-12)
    # the penalised evidence: the GPs' evidence minus the (non-negative) soft bounds
    evidence = sum(float(g.log_marginal_likelihood()) for g in gprs)
    penalties = sum(float(model._penalty(m)) for m in model.models)
    assert penalties >= 0.0
    assert objective == pytest.approx(evidence - penalties, rel=1e-10)
    lml = model.log_marginal_likelihood()
    assert tf.is_tensor(lml) and lml.shape == (2,)
    np.testing.assert_allclose(lml.numpy(), [g.log_marginal_likelihood().numpy() for g in gprs],
                               rtol=1e-12)


@pytest.mark.parametrize("full_cov", [False, True])
def test_predict_f_and_y_equal_gpr(trained, Xs, full_cov):
    model, X, Y, gprs = trained
    mean, var = model.predict_f(Xs, full_cov=full_cov)
    ymean, yvar = model.predict_y(Xs, full_cov=full_cov)
    assert tf.is_tensor(mean) and tf.is_tensor(var)
    assert var.shape == ((2, 7, 7) if full_cov else (7, 2))
    for e, gpr in enumerate(gprs):
        m_ref, v_ref = gpr.predict_f(Xs, full_cov=full_cov)
        np.testing.assert_allclose(mean.numpy()[:, e], m_ref.numpy()[:, 0], rtol=0, atol=TOL)
        np.testing.assert_allclose(ymean.numpy()[:, e], m_ref.numpy()[:, 0], rtol=0, atol=TOL)
        noise = float(gpr.likelihood.variance.numpy())
        if full_cov:
            np.testing.assert_allclose(var.numpy()[e], v_ref.numpy()[0], rtol=0, atol=TOL)
            np.testing.assert_allclose(yvar.numpy()[e], v_ref.numpy()[0] + noise * np.eye(7),
                                       rtol=0, atol=TOL)
        else:
            yv_ref = gpr.predict_y(Xs)[1].numpy()[:, 0]
            np.testing.assert_allclose(var.numpy()[:, e], v_ref.numpy()[:, 0], rtol=0, atol=TOL)
            np.testing.assert_allclose(yvar.numpy()[:, e], yv_ref, rtol=0, atol=TOL)


def test_full_output_cov_layouts(trained, Xs):
    model = trained[0]
    _, var = model.predict_f(Xs)
    _, cov = model.predict_f(Xs, full_cov=True)
    _, out = model.predict_f(Xs, full_output_cov=True)
    _, both = model.predict_f(Xs, full_cov=True, full_output_cov=True)
    assert out.shape == (7, 2, 2) and both.shape == (7, 2, 7, 2)
    np.testing.assert_array_equal(out.numpy()[:, [0, 1], [0, 1]], var.numpy())
    assert np.all(out.numpy()[:, 0, 1] == 0.0)
    np.testing.assert_array_equal(both.numpy()[:, 1, :, 1], cov.numpy()[1])
    assert np.all(both.numpy()[:, 0, :, 1] == 0.0)


def test_predict_log_density_equals_gpr(trained, Xs):
    model, X, Y, gprs = trained
    Ys = np.random.default_rng(2).standard_normal((7, 2))
    density = model.predict_log_density((Xs, Ys))
    assert density.shape == (7,)
    ref = sum(g.predict_log_density((Xs, Ys[:, e:e + 1])).numpy() for e, g in enumerate(gprs))
    np.testing.assert_allclose(density.numpy(), ref, rtol=0, atol=TOL)
    np.testing.assert_array_equal(model.predict_log_density([Xs.tolist(), Ys.tolist()]).numpy(),
                                  density.numpy())
    with pytest.raises(ValueError, match="same number of rows, got 7 and 6"):
        model.predict_log_density((Xs, Ys[:6]))
    with pytest.raises(ValueError, match="data Y must have 2 columns"):
        model.predict_log_density((Xs, Ys[:, :1]))
    with pytest.raises(NotImplementedError, match="point-wise"):
        model.predict_log_density((Xs, Ys), full_cov=True)


def test_predictions_compile_and_equal_eager(trained, Xs):
    model = trained[0]
    m, s = np.array([[0.3, -0.4]]), np.array([[0.2, 0.05], [0.05, 0.1]])
    eager_f = model.predict_f(Xs)
    eager_n = model.predict_on_noisy_inputs(m, s)
    compiled_f = tf.function(model.predict_f)(tf.constant(Xs))
    compiled_n = tf.function(model.predict_on_noisy_inputs)(tf.constant(m), tf.constant(s))
    for a, b in zip(eager_f + eager_n, compiled_f + compiled_n):
        np.testing.assert_allclose(b.numpy(), a.numpy(), rtol=1e-12, atol=1e-14)
    # a traced function sees noise factors set after it was traced (no Python branch)
    scaled = MGPR(trained[0].data)
    predict = tf.function(scaled.predict_f)
    before = predict(tf.constant(Xs))[0].numpy()
    scaled.set_noise_scales(np.linspace(1.0, 50.0, 50))
    after = predict(tf.constant(Xs))[0].numpy()
    np.testing.assert_allclose(after, scaled.predict_f(Xs)[0].numpy(), rtol=1e-12)
    assert np.max(np.abs(after - before)) > 1e-6


def test_noise_scales_in_predictions_equal_heteroscedastic_formula(Xs):
    X, Y = _data()
    model = MGPR((X, Y))
    w = np.random.default_rng(3).uniform(0.5, 20.0, 50)
    model.set_noise_scales(w)
    mean, var = model.predict_f(Xs)
    for e, m in enumerate(model.models):
        k = m.kernel
        K = k(X).numpy() + np.diag(float(m.likelihood.variance.numpy()) * w)
        Ks = k(Xs, X).numpy()
        np.testing.assert_allclose(mean.numpy()[:, e], Ks @ np.linalg.solve(K, Y[:, e]),
                                   rtol=1e-9, atol=1e-12)
        ref = float(k.variance.numpy()) - np.sum(Ks * np.linalg.solve(K, Ks.T).T, axis=1)
        np.testing.assert_allclose(var.numpy()[:, e], ref, rtol=1e-8, atol=1e-12)


BAD_INPUTS = [
    ("nan", np.array([[0.1, np.nan]]), ValueError, "Xnew contains NaN"),
    ("1-D", np.array([0.1, 0.2]), ValueError, r"Xnew must be 2-D \[points, 2\].*reshape"),
    ("columns", np.zeros((3, 3)), ValueError, "Xnew must have 2 columns"),
    ("strings", [["a", "b"]], TypeError, "Xnew must be an array of \\(real\\) numbers"),
]


@pytest.mark.parametrize("method", ["predict_f", "predict_y"])
@pytest.mark.parametrize("case, value, error, message", BAD_INPUTS, ids=[c[0] for c in BAD_INPUTS])
def test_bad_inputs_one_clear_error(trained, method, case, value, error, message):
    model = trained[0]
    with pytest.raises(error, match=message):
        getattr(model, method)(value)
    model.set_noise_scales(np.full(50, 2.0))  # the path that failed with IndexError before
    try:
        with pytest.raises(error, match=message):
            getattr(model, method)(value)
    finally:
        model.set_noise_scales(None)


def test_float32_and_lists_are_converted(trained, Xs):
    model = trained[0]
    reference = model.predict_f(Xs.astype(np.float32).astype(np.float64))
    for given in (Xs.astype(np.float32), tf.constant(Xs, tf.float32), Xs.tolist()):
        mean, var = model.predict_f(given)
        assert mean.dtype == tf.float64
        if isinstance(given, list):
            np.testing.assert_array_equal(mean.numpy(), model.predict_f(Xs)[0].numpy())
        else:
            np.testing.assert_array_equal(mean.numpy(), reference[0].numpy())
    M, S, V = model.predict_on_noisy_inputs([[0.1, 0.2]], np.eye(2, dtype=np.float32) * 0.1)
    assert M.dtype == S.dtype == V.dtype == tf.float64


def test_traced_inputs_checked():
    X, Y = _data()
    model = MGPR((X, Y))
    with pytest.raises(ValueError, match="Xnew must have 2 columns"):
        tf.function(model.predict_f)(tf.zeros([4, 3], tf.float64))
    with pytest.raises(ValueError, match="rank-1"):
        tf.function(model.predict_f)(tf.zeros([4], tf.float64))
    with pytest.raises(tf.errors.InvalidArgumentError, match="Xnew contains NaN"):
        tf.function(model.predict_f)(tf.constant([[0.0, np.nan]]))
    with pytest.raises(tf.errors.InvalidArgumentError, match="input mean contains NaN"):
        tf.function(model.predict_on_noisy_inputs)(tf.constant([[np.nan, 0.0]]),
                                                   tf.eye(2, dtype=tf.float64))
    out = tf.function(model.predict_f)(tf.zeros([4, 2], tf.float32))  # cast, as eager
    assert out[0].dtype == tf.float64


def test_print_summary_lists_hyperparameters_once(trained, capsys):
    model = trained[0]
    names = list(gpflow.utilities.parameter_dict(model))
    assert names == [f".models[{e}].{p}" for e in range(2) for p in
                     ("kernel.variance", "kernel.lengthscales", "likelihood.variance")]
    gpflow.utilities.print_summary(model)
    table = capsys.readouterr().out
    assert "_X" not in table and "_Y" not in table and "_noise_scales" not in table
    assert "data" not in table
    assert table.count("MGPR.models[0].kernel.variance") == 1
    assert len(gpflow.utilities.leaf_components(model)) == 6


def test_module_tools_still_work(trained, Xs, tmp_path):
    model, X, Y, _ = trained
    copy = gpflow.utilities.deepcopy(model)
    frozen = gpflow.utilities.freeze(model)
    np.testing.assert_array_equal(copy.predict_f(Xs)[0].numpy(), model.predict_f(Xs)[0].numpy())
    np.testing.assert_array_equal(frozen.predict_f(Xs)[0].numpy(),
                                  model.predict_f(Xs)[0].numpy())
    fresh = MGPR((X[:10], Y[:10]))
    path = tf.train.Checkpoint(model=model).write(str(tmp_path / "ckpt"))
    tf.train.Checkpoint(model=fresh).read(path).assert_consumed()
    np.testing.assert_array_equal(fresh.X.numpy(), X)  # data and hyperparameters restored
    np.testing.assert_array_equal(fresh.predict_f(Xs)[0].numpy(), model.predict_f(Xs)[0].numpy())


def test_check_shapes_declared():
    for cls, names in [
        (MGPR, ["predict_f", "predict_y", "predict_log_density", "predict_on_noisy_inputs",
                "training_loss", "maximum_log_likelihood_objective",
                "log_marginal_likelihood"]),
        (PILCO, ["predict", "predict_trajectory", "predict_trajectory_with_rewards",
                 "propagate", "compute_action", "one_step_prediction", "expected_returns"]),
        (RbfController, ["compute_action", "moments"]),
        (LinearController, ["compute_action", "moments"]),
        (ExponentialReward, ["compute_reward", "moments"]),
    ]:
        for name in names:
            assert get_check_shapes(getattr(cls, name)) is not None, f"{cls.__name__}.{name}"


def _agent():
    rng = np.random.default_rng(0)
    X, Y = rng.standard_normal((20, 3)), 0.1 * rng.standard_normal((20, 2))
    return PILCO((X, Y), RbfController(2, 1, 4, seed=0), ExponentialReward(2), horizon=3)


def test_agent_returns_numpy_and_acts_on_batches():
    agent = _agent()
    outputs = [*agent.predict(), *agent.predict_trajectory(), *agent.propagate(
        np.zeros((1, 2)), 0.01 * np.eye(2)), *agent.one_step_prediction(np.zeros((2, 3)))]
    assert all(type(x) is np.ndarray for x in outputs)
    states = np.random.default_rng(1).standard_normal((5, 2))
    batch = agent.compute_action(states)
    assert type(batch) is np.ndarray and batch.shape == (5, 1)
    rows = np.vstack([agent.compute_action(x) for x in states])
    np.testing.assert_array_equal(batch, rows)
    assert agent.compute_action(states[0]).shape == (1, 1)
    with pytest.raises(ValueError, match="state contains NaN"):
        agent.compute_action([[0.0, np.nan]])
    with pytest.raises(ValueError, match="2 entries per row"):
        agent.compute_action(np.zeros((3, 4)))
    # the model's and the policy's own methods return tensors
    assert tf.is_tensor(agent.mgpr.predict_f(np.zeros((1, 3)))[0])
    assert tf.is_tensor(agent.controller.compute_action(np.zeros((1, 2)), np.eye(2))[0])


def test_policy_search_prints_no_tensorflow_warnings():
    """With oneDNN's graph rewrite on (the default on AVX-512 CPUs) float64 products
    followed by additions drew 'Not handling type DT_DOUBLE' lines from it."""
    code = ("import numpy as np\n"
            "from pilco.models import PILCO\n"
            "from pilco.controllers import RbfController\n"
            "from pilco.rewards import ExponentialReward\n"
            "r = np.random.default_rng(0)\n"
            "X, Y = r.standard_normal((15, 4)), 0.1 * r.standard_normal((15, 3))\n"
            "p = PILCO((X, Y), RbfController(3, 1, 3, seed=0), ExponentialReward(3), horizon=2)\n"
            "p.optimize_models(maxiter=5)\n"
            "p.optimize_policy(maxiter=2)\n")
    env = dict(os.environ, TF_ENABLE_ONEDNN_OPTS="1", TF_CPP_MIN_LOG_LEVEL="0",
               PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "DT_DOUBLE" not in run.stderr


def test_example_gp_model_runs(capsys):
    runpy.run_path(os.path.join(ROOT, "examples", "gp_model.py"), run_name="__main__")
    out = capsys.readouterr().out
    assert "predict_y" in out and "log density" in out
