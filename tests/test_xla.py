"""The policy objective compiled whole by XLA, and what it takes to compile it once per run.

* Padding (:func:`pilco.moments.pad_factorization`): a factorisation padded with centres of
  zero weight predicts the same moments, and the padded objective has the same value and
  gradient as the exact one (to 1e-10; the exact, unpadded path is the one the MATLAB
  reference and gradient tests check).
* The XLA-compatible graph (QR and Cholesky log-determinants instead of ``slogdet``) has
  the graph path's value and gradient, with angles, several tasks, context dimensions and
  the policy's noisy input; ``optimize_policy(jit_compile=True)`` optimises; a new horizon
  gives a new trace.
* The persistent compilation cache: the environment variables that point TensorFlow at it
  for a run and for the runs of a sweep.
"""
from __future__ import annotations

import os

import numpy as np
import pytest
import tensorflow as tf

from pilco import moments, runtime
from pilco.controllers import RbfController, squash_sin
from pilco.models import PILCO
from pilco.moments import compiled
from pilco.rewards import CartPoleReward, ExponentialReward
from pilco.sweep.runs import run_environment


def test_bucket_sizes_round_up_by_at_most_a_quarter_and_are_few():
    sizes = [compiled.bucket_size(n) for n in range(1, 2001)]
    assert all(b >= n for n, b in zip(range(1, 2001), sizes))
    assert all(b <= max(n + 7, 1.25 * n) for n, b in zip(range(1, 2001), sizes))
    assert sizes == sorted(sizes)  # more data never means a smaller bucket
    # data that double (from 161 to 320 transitions) meet four sizes
    assert len({compiled.bucket_size(n) for n in range(161, 321)}) == 4
    assert compiled.bucket_size(40) == 40 and compiled.bucket_size(41) == 48
    with pytest.raises(ValueError, match="at least one point"):
        compiled.bucket_size(0)


def _factorization(rng, n=13, D=3, E=2):
    X = rng.uniform(-1.0, 1.0, (n, D))
    Y = np.stack([np.sin(X @ rng.standard_normal(D)) for _ in range(E)], 1)
    ell = tf.constant(rng.uniform(0.5, 1.5, (E, D)))
    return moments.factorize(tf.constant(X), tf.constant(Y), ell,
                             tf.constant([0.8, 1.3], tf.float64),
                             tf.constant([1e-2, 3e-3], tf.float64))


@pytest.mark.parametrize("deterministic", [False, True])
def test_a_padded_factorization_predicts_the_same_moments(deterministic):
    rng = np.random.default_rng(0)
    fact = _factorization(rng)
    if deterministic:
        fact = fact._replace(iK=None)
    padded = moments.pad_factorization(fact, 24)
    assert padded.centers.shape == (24, 3) and padded.beta.shape == (2, 24)
    assert (padded.iK is None) == deterministic
    np.testing.assert_array_equal(padded.beta.numpy()[:, 13:], 0.0)
    m = tf.constant([[0.3, -0.2, 0.5]], tf.float64)
    A = rng.standard_normal((3, 3))
    s = tf.constant(0.1 * A @ A.T + 0.01 * np.eye(3))
    for constant in (False, True):
        exact = moments.moment_match(m, s, fact, constant=constant)
        with_pad = moments.moment_match(m, s, padded, constant=constant)
        for a, b in zip(exact, with_pad):
            np.testing.assert_allclose(b.numpy(), a.numpy(), rtol=1e-12, atol=1e-14)
    assert moments.pad_factorization(fact, 13) is fact
    with pytest.raises(ValueError, match="cannot pad 13 centres to 12"):
        moments.pad_factorization(fact, 12)


def test_the_qr_and_cholesky_log_determinants_match_slogdet_and_its_gradient():
    rng = np.random.default_rng(1)
    A = rng.standard_normal((4, 4))
    spd = tf.constant(A @ A.T + 4 * np.eye(4))
    general = tf.constant(np.eye(4) + 0.3 * A)  # not symmetric, positive determinant
    for M in (spd, general):
        with tf.GradientTape(persistent=True) as tape:
            tape.watch(M)
            ours = compiled.logdet(M)
            theirs = tf.linalg.slogdet(M)[1]
        np.testing.assert_allclose(ours.numpy(), theirs.numpy(), rtol=1e-13)
        np.testing.assert_allclose(tape.gradient(ours, M).numpy(),
                                   tape.gradient(theirs, M).numpy(), rtol=1e-12)
    np.testing.assert_allclose(compiled.logdet_spd(spd).numpy(),
                               tf.linalg.slogdet(spd)[1].numpy(), rtol=1e-13)
    assert not compiled.in_xla_compatible()
    with compiled.xla_compatible():
        assert compiled.in_xla_compatible()
        with compiled.xla_compatible(False):
            assert not compiled.in_xla_compatible()
        assert compiled.in_xla_compatible()
    assert not compiled.in_xla_compatible()


def _cartpole_like(N=23, horizon=6, **kwargs):
    """A small agent with an angle (cart-pole shaped: 4 states, 1 action, the cart-pole
    reward) and fixed hyperparameters."""
    rng = np.random.default_rng(2)
    X = np.concatenate([rng.normal(0, [0.5, 1.0, 2.0, 1.5], (N, 4)),
                        rng.uniform(-10, 10, (N, 1))], 1)
    Y = 0.1 * np.stack([X[:, 1], 0.5 * X[:, 4] - 0.1 * X[:, 1], -9 * np.sin(X[:, 3]),
                        X[:, 2]], 1) + 0.01 * rng.standard_normal((N, 4))
    ctrl = RbfController(5, 1, 6, max_action=10.0, seed=3)
    agent = PILCO((X, Y), ctrl, CartPoleReward(), horizon=horizon, m_init=np.zeros((1, 4)),
                  S_init=0.01 * np.eye(4), angle_indices=[3], **kwargs)
    for m in agent.mgpr.models:
        m.kernel.lengthscales.assign(np.std(agent.mgpr.X.numpy(), 0) + 0.5)
        m.kernel.variance.assign(0.1)
        m.likelihood.variance.assign(1e-3)
    return agent


def _multi_target(N=19, horizon=5):
    """Two tasks, a context pair the dynamics never see, the policy's noisy input and an
    exponential reward: the other branches of the rollout."""
    rng = np.random.default_rng(4)
    S = np.column_stack([rng.uniform(-1, 1, (N, 2)), rng.uniform(-1, 1, (N, 2))])
    u = rng.uniform(-1, 1, (N, 1))
    dS = np.column_stack([0.3 * u[:, 0] + 0.1 * S[:, 1], 0.2 * S[:, 0], np.zeros((N, 2))])
    ctrl = RbfController(4, 1, 5, max_action=1.0, squash=squash_sin, seed=5)
    reward = ExponentialReward(4, W=np.diag([2.0, 1.0, 0.0, 0.0]), t=[[0.5, 0.2, 0, 0]])
    m0 = np.array([[0.0, 0.0, 0.4, -0.2], [0.1, 0.0, -0.3, 0.3]])
    agent = PILCO((np.hstack([S, u]), dS), ctrl, reward, horizon=horizon, m_init=m0,
                  S_init=0.01 * np.eye(4), context_indices=[2, 3], policy_input_noise=True)
    for m in agent.mgpr.models:
        m.kernel.lengthscales.assign(np.full(agent.mgpr.num_dims, 1.1))
        m.likelihood.variance.assign(1e-3)
    return agent


def _value_and_gradient(agent, loss):
    variables = agent.controller.trainable_variables
    with tf.GradientTape() as tape:
        value = loss()
    return value.numpy(), [g.numpy() for g in tape.gradient(value, variables)]


def _compiled_value_and_gradient(agent, loss, **tf_fun_args):
    variables = agent.controller.trainable_variables

    def both():
        with tf.GradientTape() as tape:
            value = loss()
        return value, tape.gradient(value, variables)

    value, grads = tf.function(both, autograph=False, **tf_fun_args)()
    return value.numpy(), [g.numpy() for g in grads]


def _assert_same(a, b, rtol):
    np.testing.assert_allclose(a[0], b[0], rtol=rtol)
    for ga, gb in zip(a[1], b[1]):
        np.testing.assert_allclose(ga, gb, rtol=rtol, atol=rtol * np.max(np.abs(gb)))


def test_the_padded_objective_has_the_exact_objectives_value_and_gradient():
    agent = _cartpole_like()
    rollout = agent._rollout
    rollout.refresh(agent.mgpr)
    exact = _value_and_gradient(agent, rollout.policy_loss)
    rollout.refresh(agent.mgpr, pad=True)
    assert rollout._centers.numpy().shape[0] == compiled.bucket_size(23) == 24
    _assert_same(_value_and_gradient(agent, rollout.policy_loss), exact, 1e-10)


def test_the_xla_objective_equals_the_graph_objective():
    agent = _multi_target()  # several tasks, context dimensions, the policy's noisy input
    rollout = agent._rollout
    rollout.refresh(agent.mgpr)
    graph = _value_and_gradient(agent, rollout.policy_loss)
    rollout.refresh(agent.mgpr, pad=True)
    xla = _compiled_value_and_gradient(agent, rollout.xla_policy_loss, jit_compile=True)
    _assert_same(xla, graph, 1e-9)


def _xla_objective(agent):
    """The optimiser's compiled XLA objective and its gradient (one flat vector, the
    optimiser's packing) at the current policy."""
    opt = agent._xla_optimizer
    (fn,) = opt.compile_cache.values()
    value, grad = fn(opt.initial_parameters(agent.controller.trainable_variables))
    return value.numpy(), [grad.numpy()]


def _flat(agent, value_and_gradient):
    value, grads = value_and_gradient
    return value, [agent._xla_optimizer.pack_tensors([tf.constant(g) for g in grads]).numpy()]


def test_optimize_policy_with_xla_improves_the_policy_and_retraces_for_a_new_horizon():
    agent = _cartpole_like(horizon=3)  # an angle and the cart-pole reward
    before = agent.expected_return()
    best = agent.optimize_policy(maxiter=6, seed=0, jit_compile=True)
    assert np.isfinite(best) and best > before
    assert agent._xla_optimizer.failures == 0
    assert agent._xla_optimizer.first_loss == pytest.approx(-before, rel=1e-9)
    # the policy left in place is the best one, and the compiled objective's value and
    # gradient there are the graph's
    np.testing.assert_allclose(agent.expected_return(), best, rtol=1e-9)
    agent._rollout.refresh(agent.mgpr)
    graph = _flat(agent, _value_and_gradient(agent, agent._rollout.policy_loss))
    # the padded data the optimiser's program was compiled for (no second compilation)
    agent._rollout.refresh(agent.mgpr, pad=True)
    _assert_same(_xla_objective(agent), graph, 1e-9)
    agent.horizon = 5  # the XLA trace had 3 steps as a constant: it must be traced again
    start = agent.expected_return()
    again = agent.optimize_policy(maxiter=1, seed=0, jit_compile=True)
    assert agent._xla_optimizer.first_loss == pytest.approx(-start, rel=1e-9)
    assert again >= start
    with pytest.raises(TypeError, match="jit_compile"):
        agent.optimize_policy(maxiter=1, jit_compile="yes")


def test_use_xla_cache_points_tensorflow_at_the_folder_once(tmp_path, monkeypatch):
    monkeypatch.delenv("TF_XLA_FLAGS", raising=False)
    monkeypatch.setenv(runtime.XLA_CACHE_VARIABLE, str(tmp_path / "sweep-cache"))
    assert runtime.xla_cache_directory() == str(tmp_path / "sweep-cache")
    assert runtime.use_xla_cache() == str(tmp_path / "sweep-cache")
    assert os.path.isdir(tmp_path / "sweep-cache")
    flags = os.environ["TF_XLA_FLAGS"]
    assert flags == f"--tf_xla_persistent_cache_directory={tmp_path / 'sweep-cache'}"
    # a cache already named (by the user, or an earlier call) is kept
    assert runtime.use_xla_cache(str(tmp_path / "other")) == str(tmp_path / "sweep-cache")
    assert os.environ["TF_XLA_FLAGS"] == flags
    # without the variable: the user's cache folder
    env = {"XDG_CACHE_HOME": str(tmp_path / "xdg")}
    assert runtime.xla_cache_directory(env) == str(tmp_path / "xdg" / "pilco" / "xla")
    # other XLA flags are kept
    monkeypatch.setenv("TF_XLA_FLAGS", "--tf_xla_auto_jit=0")
    runtime.use_xla_cache(str(tmp_path / "c"))
    assert os.environ["TF_XLA_FLAGS"] == (
        f"--tf_xla_auto_jit=0 --tf_xla_persistent_cache_directory={tmp_path / 'c'}")


def test_a_sweeps_runs_share_a_cache_in_its_output_folder(tmp_path):
    run_dir = tmp_path / "sweep" / "default" / "seed-3"
    env = run_environment(1, str(run_dir), base={"PATH": "/bin"})
    assert env[runtime.XLA_CACHE_VARIABLE] == str(tmp_path / "sweep" / "xla-cache")
    assert env["TF_NUM_INTRAOP_THREADS"] == "1"
    named = run_environment(1, str(run_dir), base={runtime.XLA_CACHE_VARIABLE: "/c"})
    assert named[runtime.XLA_CACHE_VARIABLE] == "/c"


def test_align_graph_names_makes_the_next_name_a_multiple_of_the_alignment():
    from tensorflow.python.framework import ops

    nxt = compiled.align_graph_names(4096)
    assert nxt % 4096 == 0
    assert ops.uid() == nxt
    for bad in (0, -3, 2.0, True):
        with pytest.raises(ValueError, match="alignment"):
            compiled.align_graph_names(bad)


_PROBE = """
import os, sys
import tensorflow as tf
from tensorflow.python.framework import ops
from pilco.models.policy_search import GuardedScipy
for _ in range(int(sys.argv[1])):  # another history of traces before the objective's
    tf.function(lambda x: x + 1.0).get_concrete_function(tf.TensorSpec([], tf.float64))
w = tf.Variable([0.3, -0.2], dtype=tf.float64)
def loss():
    body = lambda i, y: (i + 1, y + tf.reduce_sum((w - 0.1 * tf.cast(i, tf.float64)) ** 2))
    return tf.while_loop(lambda i, y: i < 4, body, (0, tf.constant(0.0, tf.float64)),
                         maximum_iterations=4)[1]
opt = GuardedScipy()
names = []
for _ in range(2):  # traced once: the second minimize neither traces nor aligns again
    opt.minimize(loss, [w], options=dict(maxiter=3), tf_fun_args=dict(jit_compile=True))
    names.append(ops.uid())
print(len(os.listdir(os.environ["CACHE"])), opt.evaluations, opt.failures,
      names[1] - names[0])
"""


def test_runs_with_other_trace_histories_load_each_others_xla_programs(tmp_path):
    """The persistent cache is keyed on the traced program's names: the policy search
    aligns TensorFlow's name counter before its XLA trace, so a second process whose
    history created other graphs finds the first one's program instead of compiling."""
    import subprocess
    import sys

    cache = tmp_path / "cache"
    env = dict(os.environ, CACHE=str(cache), TF_CPP_MIN_LOG_LEVEL="3",
               TF_XLA_FLAGS=f"--tf_xla_persistent_cache_directory={cache}",
               PYTHONPATH=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    counts = []
    for history in (2, 37):
        out = subprocess.run([sys.executable, "-c", _PROBE, str(history)], env=env,
                             capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr[-2000:]
        files, evaluations, failures, names = map(int, out.stdout.split())
        assert evaluations > 2 and failures == 0
        assert names < compiled.NAME_ALIGNMENT  # not aligned again for the second run
        counts.append(files)
    assert counts[0] >= 1
    assert counts[1] == counts[0], "the second process compiled its own program"
