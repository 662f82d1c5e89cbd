"""The policy objective + gradient compiled by TensorFlow's graph and by XLA, per data size.

For each problem of ``bench_policy.py`` (cart-pole, reacher) and each number of
transitions, three fresh processes time the function L-BFGS-B evaluates:

- ``graph``: the TensorFlow graph (the default path);
- ``xla cold``: ``jit_compile=True`` with an empty persistent compilation cache (the
  first run of a sweep, the first time a data-size bucket is met);
- ``xla warm``: the same with the cache the cold process filled (later runs of a sweep).

Each reports the first call's seconds (tracing and compilation, or loading from the
cache) and the median seconds per call over ``--repeats`` calls at nearby points. The
XLA objective runs on the dynamics model padded to its size bucket
(:func:`pilco.moments.bucket_size`), as ``optimize_policy(jit_compile=True)`` runs it.
One intra-op thread per process, as a run of a sweep.

Usage::

    python benchmarks/bench_xla.py                       # both problems, default sizes
    python benchmarks/bench_xla.py --problem cartpole --sizes 40,80,160,280 --json out.json
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_SIZES = {"cartpole": [40, 80, 160, 280], "reacher": [50, 100, 150]}


def _measure(problem: str, size: int, compiler: str, repeats: int) -> dict:
    """In this process: first call and per-call seconds of one compiled objective."""
    from bench_policy import _time_loss_and_gradient, build

    agent = (build(problem, cartpole_data=size) if problem == "cartpole"
             else build(problem, reacher_data=size))
    rollout = agent._rollout
    xla = compiler == "xla"
    rollout.refresh(agent.mgpr, pad=xla)
    loss = rollout.xla_policy_loss if xla else rollout.policy_loss
    args = dict(autograph=False, jit_compile=True) if xla else dict(autograph=False)
    value, first, seconds = _time_loss_and_gradient(
        loss, agent.controller.trainable_variables, repeats, args)
    return {"value": value, "first_call_seconds": first,
            "seconds_per_call": float(np.median(seconds)),
            "centres": int(rollout._centers.numpy().shape[0])}


def _fresh(problem: str, size: int, compiler: str, repeats: int, cache: str) -> dict:
    """:func:`_measure` in a fresh process (one intra-op thread; ``cache`` for XLA)."""
    env = dict(os.environ, TF_NUM_INTRAOP_THREADS="1", TF_CPP_MIN_LOG_LEVEL="2",
               PYTHONPATH=os.pathsep.join([HERE, os.path.dirname(HERE),
                                           os.environ.get("PYTHONPATH", "")]))
    env.pop("XLA_FLAGS", None)  # the tests' fast-compile flag must not leak in here
    if compiler == "xla":
        env["TF_XLA_FLAGS"] = f"--tf_xla_persistent_cache_directory={cache}"
    out = subprocess.run([sys.executable, __file__, "--_one", problem, str(size), compiler,
                          str(repeats)], env=env, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--problem", choices=["cartpole", "reacher", "all"], default="all")
    parser.add_argument("--sizes", default=None,
                        help="comma-separated numbers of transitions (default: cart-pole "
                             "40,80,160,280; reacher 50,100,150)")
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--json", default=None, help="write the results to this file")
    parser.add_argument("--_one", nargs=4, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args._one:
        problem, size, compiler, repeats = args._one
        print(json.dumps(_measure(problem, int(size), compiler, int(repeats))))
        return 0
    problems = ["cartpole", "reacher"] if args.problem == "all" else [args.problem]
    results = {"machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                           "load_before": os.getloadavg()[0]}, "rows": []}
    header = (f"{'problem':<9} {'n':>4} {'bucket':>6} {'graph s/call':>12} {'xla s/call':>10} "
              f"{'speed-up':>8} {'graph 1st s':>11} {'xla cold 1st':>12} {'xla warm 1st':>12}")
    print(header)
    print("-" * len(header))
    for problem in problems:
        sizes = ([int(s) for s in args.sizes.split(",")] if args.sizes
                 else DEFAULT_SIZES[problem])
        for size in sizes:
            with tempfile.TemporaryDirectory() as cache:
                graph = _fresh(problem, size, "graph", args.repeats, cache)
                cold = _fresh(problem, size, "xla", args.repeats, cache)
                warm = _fresh(problem, size, "xla", args.repeats, cache)
            per_call = min(cold["seconds_per_call"], warm["seconds_per_call"])
            row = {"problem": problem, "transitions": size, "bucket": cold["centres"],
                   "graph": graph, "xla_cold": cold, "xla_warm": warm,
                   "relative_difference": abs(cold["value"] - graph["value"])
                   / abs(graph["value"])}
            results["rows"].append(row)
            print(f"{problem:<9} {size:>4} {cold['centres']:>6} "
                  f"{graph['seconds_per_call']:>12.4f} {per_call:>10.4f} "
                  f"{graph['seconds_per_call'] / per_call:>8.2f} "
                  f"{graph['first_call_seconds']:>11.1f} {cold['first_call_seconds']:>12.1f} "
                  f"{warm['first_call_seconds']:>12.1f}", flush=True)
    results["machine"]["load_after"] = os.getloadavg()[0]
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
