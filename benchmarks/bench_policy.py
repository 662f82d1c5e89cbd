"""Benchmark of PILCO's policy objective on the paper's problem sizes.

Problems (built through the public API only):

- ``reacher``: state 10, action 7, horizon 50, 50 RBF basis functions, 100 transitions
  (the paper's Fetch reacher);
- ``cartpole``: state 4 with one angle, action 1, horizon 40, 10 basis functions,
  ``squash_sat``, :class:`CartPoleReward` and 40 transitions (the MATLAB release's
  cart-pole after its random episode; ``--cartpole-data`` changes the count).

For each it reports the time to trace and compile the objective and its gradient (first
call of the function L-BFGS-B evaluates), the median seconds per objective + gradient
over repeats, the seconds of ``optimize_policy(maxiter=10)`` in a fresh process
(compilation included), the peak resident memory of that process, and the operations in
the horizon loop's body forward and backward (constants left out; the same on every
machine, so a change's effect on the per-operation overhead can be told from load).

Usage::

    python benchmarks/bench_policy.py                   # both problems, table + JSON
    python benchmarks/bench_policy.py --problem reacher --repeats 20 --json out.json
    python benchmarks/bench_policy.py --baseline      # also time naive_port.py's port
    python benchmarks/bench_policy.py --problem reacher \
        --port /path/to/PILCO --port-python /path/to/port-venv/bin/python

``--port`` times the reference GPflow port (a checkout of nrontsis/PILCO, run by
``port_policy.py`` in a fresh process of its own environment given by ``--port-python``)
side by side with this library on the reacher problem: ``--port-repeats`` rounds, each
one fresh process of this library's ``optimize_policy(maxiter=10)`` and one of the
port's, on the same transitions, hyperparameters, reward, start and initial policy;
medians and their ratio are reported.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time

import numpy as np

from port_policy import peak_memory_mb  # same directory; standard library only


def build(problem: str, seed: int = 0, cartpole_data: int = 40, reacher_data: int = 100):
    """The agent of one benchmark problem, its GP hyperparameters set from its data;
    ``cartpole_data`` / ``reacher_data`` transitions (``bench_limit.py`` varies them)."""
    from pilco.controllers import RbfController, squash_sat, squash_sin
    from pilco.models import PILCO
    from pilco.rewards import CartPoleReward, ExponentialReward

    rng = np.random.default_rng(seed)
    if problem == "reacher":
        D, U, N, H, nb = 10, 7, reacher_data, 50, 50
        A = rng.standard_normal((D + U, D)) / np.sqrt(D + U)
        X = np.concatenate([rng.uniform(-1, 1, (N, D)), rng.uniform(-0.1, 0.1, (N, U))], 1)
        Y = 0.1 * np.tanh(X @ A) + 1e-3 * rng.standard_normal((N, D))
        ctrl = RbfController(D, U, nb, max_action=0.1, squash=squash_sin, seed=seed)
        W = np.zeros((D, D))
        W[:3, :3] = np.eye(3) / 0.2**2
        reward = ExponentialReward(D, W=W, t=np.r_[1.2, 0.38, 0.38, np.zeros(D - 3)])
        agent = PILCO((X, Y), ctrl, reward, horizon=H, m_init=X[:1, :D],
                      S_init=1e-4 * np.eye(D))
    elif problem == "cartpole":
        D, U, N, H, nb = 4, 1, cartpole_data, 40, 10
        X = np.concatenate([rng.normal(0, [0.5, 1.0, 2.0, 1.5], (N, D)),
                            rng.uniform(-10, 10, (N, U))], 1)
        Y = 0.1 * np.stack([X[:, 1], 0.5 * X[:, 4] - 0.1 * X[:, 1], -9 * np.sin(X[:, 3]),
                            X[:, 2]], 1) + 0.01 * rng.standard_normal((N, D))
        ctrl = RbfController(D + 1, U, nb, max_action=10.0, squash=squash_sat, seed=seed)
        agent = PILCO((X, Y), ctrl, CartPoleReward(), horizon=H, m_init=np.zeros((1, D)),
                      S_init=0.01 * np.eye(D), angle_indices=[3])
    else:
        raise ValueError(f"unknown problem {problem!r}")
    for m in agent.mgpr.models:  # sensible fixed hyperparameters: timing does not need training
        m.kernel.lengthscales.assign(np.std(agent.mgpr.X.numpy(), 0) + 0.5)
        m.kernel.variance.assign(0.1)
        m.likelihood.variance.assign(1e-3)
    return agent


def _time_loss_and_gradient(loss, variables, repeats: int, tf_fun_args: dict):
    """Compile ``loss`` and its gradient as L-BFGS-B evaluates them; returns the value at
    the current parameters, the first call's seconds (tracing and compilation included)
    and the seconds of ``repeats`` calls at nearby points."""
    import gpflow

    opt = gpflow.optimizers.Scipy()
    fn = opt.eval_func(loss, variables, tf_fun_args=tf_fun_args, compile=True)
    x0 = opt.initial_parameters(variables).numpy()
    t0 = time.perf_counter()
    value, _ = fn(x0)
    trace = time.perf_counter() - t0
    seconds = []
    for i in range(repeats):
        x = x0 + 1e-3 * np.random.default_rng(i).standard_normal(x0.shape)
        t0 = time.perf_counter()
        fn(x)
        seconds.append(time.perf_counter() - t0)
    return float(value), trace, seconds


def loop_operations(agent) -> dict:
    """Operations in the horizon loop's body of the objective + gradient, forward (with the
    gradient's accumulators) and backward, constants left out: a count that does not
    depend on the machine's load, unlike the seconds (per-operation overhead is most of a
    small problem's time)."""
    import tensorflow as tf

    variables = agent.controller.trainable_variables

    @tf.function(autograph=False)
    def loss_and_gradient():
        with tf.GradientTape() as tape:
            loss = agent._rollout.policy_loss()
        return loss, tape.gradient(loss, variables)

    graph_def = loss_and_gradient.get_concrete_function().graph.as_graph_def()
    counts = {"loop_forward_operations": 0, "loop_gradient_operations": 0}
    for function in graph_def.library.function:
        name = function.signature.name
        if not name.startswith("while_body"):
            continue
        ops = sum(node.op != "Const" for node in function.node_def)
        if "_grad_" in name:
            counts["loop_gradient_operations"] = max(counts["loop_gradient_operations"], ops)
        elif name.endswith("_rewritten"):  # the forward body that feeds the accumulators
            counts["loop_forward_operations"] = max(counts["loop_forward_operations"], ops)
    return counts


def time_objective(problem: str, repeats: int, cartpole_data: int):
    """Trace time and per-call seconds of the objective + gradient L-BFGS-B evaluates."""
    import tensorflow as tf

    agent = build(problem, cartpole_data=cartpole_data)
    agent._rollout.refresh(agent.mgpr)
    _, trace, seconds = _time_loss_and_gradient(
        agent._rollout.policy_loss, agent.controller.trainable_variables, repeats,
        dict(autograph=False))

    @tf.function
    def forward():
        return agent._rollout.policy_loss()

    forward()
    fwd = []
    for _ in range(max(3, repeats // 2)):
        t0 = time.perf_counter()
        forward().numpy()
        fwd.append(time.perf_counter() - t0)
    return {"trace_seconds": trace, "objective_gradient_seconds": float(np.median(seconds)),
            "objective_gradient_min_seconds": float(np.min(seconds)),
            "objective_seconds": float(np.median(fwd)), **loop_operations(agent)}


def time_baseline(problem: str, repeats: int, cartpole_data: int):
    """The same objective + gradient through ``naive_port`` (a straightforward port):
    its agreement with the library, trace time, seconds per call, and the seconds of 10
    L-BFGS-B iterations with it (compilation included)."""
    import gpflow

    from naive_port import make_objective

    agent = build(problem, cartpole_data=cartpole_data)
    agent._rollout.refresh(agent.mgpr)
    ours = float(agent._rollout.policy_loss().numpy())
    naive, trace, seconds = _time_loss_and_gradient(
        make_objective(agent), agent.controller.trainable_variables, repeats, {})
    fresh = build(problem, cartpole_data=cartpole_data)
    fresh._rollout.refresh(fresh.mgpr)
    t0 = time.perf_counter()
    gpflow.optimizers.Scipy().minimize(make_objective(fresh), fresh.controller.trainable_variables,
                                       method="L-BFGS-B", options=dict(maxiter=10))
    return {"baseline_relative_difference": abs(float(naive) - ours) / abs(ours),
            "baseline_trace_seconds": trace,
            "baseline_objective_gradient_seconds": float(np.median(seconds)),
            "baseline_optimize_maxiter10_seconds": time.perf_counter() - t0}



def optimize_fresh(problem: str, cartpole_data: int):
    """optimize_policy(maxiter=10) in this (fresh) process; run via a subprocess."""
    agent = build(problem, cartpole_data=cartpole_data)
    t0 = time.perf_counter()
    agent.optimize_policy(maxiter=10)
    secs = time.perf_counter() - t0
    peak_mb = peak_memory_mb()
    return {"optimize_policy_maxiter10_seconds": secs, "peak_memory_mb": peak_mb}


def write_problem(agent, path: str) -> None:
    """The agent's problem as arrays for ``port_policy.py`` (no pilco needed to read it)."""
    ctrl = agent.controller
    ell, sf2, sn2 = agent.mgpr.hyperparameters()
    np.savez(path, X=agent.mgpr.X.numpy(), Y=agent.mgpr.Y.numpy(),
             lengthscales=ell.numpy(), variance=sf2.numpy(), noise=sn2.numpy(),
             W=agent.reward.W.numpy(), t=agent.reward.t.numpy(), m_init=agent.m_init,
             S_init=agent.S_init, horizon=agent.horizon, centers=ctrl.centers.numpy(),
             targets=ctrl.targets.numpy(),
             policy_lengthscales=np.stack([m.kernel.lengthscales.numpy() for m in ctrl.models]),
             max_action=float(np.max(np.asarray(ctrl.max_action))))  # one bound in the port


def _fresh_ours(problem: str, cartpole_data: int) -> dict:
    out = subprocess.run(
        [sys.executable, __file__, "--_fresh", problem, "--cartpole-data", str(cartpole_data)],
        capture_output=True, text=True, check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def time_port(port: str, python: str, repeats: int) -> dict:
    """Fresh processes of this library's and the port's ``optimize_policy(maxiter=10)`` on
    the reacher problem, interleaved; medians and their ratio."""
    import tempfile

    agent = build("reacher")
    script = os.path.join(os.path.dirname(os.path.abspath(__file__)), "port_policy.py")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}  # the port's pilco only
    ours, theirs = [], []
    with tempfile.TemporaryDirectory() as tmp:
        problem = os.path.join(tmp, "reacher.npz")
        write_problem(agent, problem)
        for _ in range(repeats):
            ours.append(_fresh_ours("reacher", 0)["optimize_policy_maxiter10_seconds"])
            out = subprocess.run([python, script, problem, "--port", port],
                                 capture_output=True, text=True, env=env)
            if out.returncode != 0:
                raise RuntimeError(f"the port's run failed:\n{out.stderr[-3000:]}")
            theirs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    port_seconds = [t["port_optimize_policy_seconds"] for t in theirs]
    return {"port_rounds": repeats,
            "ours_optimize_policy_maxiter10_seconds_all": ours,
            "port_optimize_policy_maxiter10_seconds_all": port_seconds,
            "ours_optimize_policy_maxiter10_seconds": float(np.median(ours)),
            "port_optimize_policy_maxiter10_seconds": float(np.median(port_seconds)),
            "port_ratio": float(np.median(port_seconds) / np.median(ours)),
            "port_peak_memory_mb": float(np.median([t["port_peak_memory_mb"] for t in theirs]))}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--problem", choices=["reacher", "cartpole", "all"], default="all")
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--cartpole-data", type=int, default=40)
    parser.add_argument("--json", default=None, help="write the results to this file")
    parser.add_argument("--baseline", action="store_true",
                        help="also time the straightforward port in naive_port.py (reacher "
                             "only: it has no angles)")
    parser.add_argument("--port", default=None,
                        help="checkout of nrontsis/PILCO: also time its optimize_policy "
                             "(reacher) side by side, in fresh processes of --port-python")
    parser.add_argument("--port-python", default=None,
                        help="python of an environment where the port runs (TF 2, gpflow 2, "
                             "numpy<2, pandas<2.3)")
    parser.add_argument("--port-repeats", type=int, default=3,
                        help="rounds of the side-by-side comparison (medians reported)")
    parser.add_argument("--_fresh", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.port and not args.port_python:
        parser.error("--port needs --port-python (the port's environment)")
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")

    if args._fresh:
        print(json.dumps(optimize_fresh(args._fresh, args.cartpole_data)))
        return 0

    problems = ["reacher", "cartpole"] if args.problem == "all" else [args.problem]
    results = {"machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                           "python": platform.python_version()}, "problems": {}}
    import tensorflow as tf

    results["machine"]["tensorflow"] = tf.__version__
    for problem in problems:
        res = time_objective(problem, args.repeats, args.cartpole_data)
        res.update(_fresh_ours(problem, args.cartpole_data))
        results["problems"][problem] = res
    if args.baseline and "reacher" in results["problems"]:
        results["problems"]["reacher"].update(
            time_baseline("reacher", max(3, args.repeats // 3), args.cartpole_data))

    if args.port:
        if "reacher" not in results["problems"]:
            parser.error("--port compares on the reacher problem")
        results["problems"]["reacher"].update(
            time_port(args.port, args.port_python, args.port_repeats))

    header = (f"{'problem':<10} {'trace s':>8} {'obj+grad s':>11} {'obj s':>7} "
              f"{'opt(10) s':>10} {'peak MB':>8} {'loop ops fwd/grad':>18}")
    print(header)
    print("-" * len(header))
    for problem, r in results["problems"].items():
        ops = f"{r['loop_forward_operations']}/{r['loop_gradient_operations']}"
        print(f"{problem:<10} {r['trace_seconds']:>8.2f} {r['objective_gradient_seconds']:>11.3f} "
              f"{r['objective_seconds']:>7.3f} {r['optimize_policy_maxiter10_seconds']:>10.2f} "
              f"{r['peak_memory_mb']:>8.0f} {ops:>18}")
    for problem, r in results["problems"].items():
        if "baseline_objective_gradient_seconds" in r:
            grad, opt = (r["baseline_objective_gradient_seconds"],
                         r["baseline_optimize_maxiter10_seconds"])
            print(f"\nstraightforward port ({problem}): trace "
                  f"{r['baseline_trace_seconds']:.1f} s, objective + gradient {grad:.2f} s "
                  f"({grad / r['objective_gradient_seconds']:.1f}x ours), 10 L-BFGS-B "
                  f"iterations {opt:.1f} s "
                  f"({opt / r['optimize_policy_maxiter10_seconds']:.1f}x ours); same "
                  f"objective to {r['baseline_relative_difference']:.1e}")
    for problem, r in results["problems"].items():
        if "port_ratio" in r:
            print(f"\nreference port nrontsis/PILCO ({problem}), optimize_policy(maxiter=10) in "
                  f"fresh processes, median of {r['port_rounds']} interleaved rounds: port "
                  f"{r['port_optimize_policy_maxiter10_seconds']:.1f} s, this library "
                  f"{r['ours_optimize_policy_maxiter10_seconds']:.1f} s: "
                  f"{r['port_ratio']:.1f}x")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
