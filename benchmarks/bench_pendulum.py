"""The reference port's pendulum workload against this library, side by side.

Runs ``pendulum_workload.py`` (one script in the paper code's API, the port's pendulum
swing-up example with gymnasium) in fresh processes, alternating this library and a
checkout of nrontsis/PILCO in its own environment, and reports per library the median
seconds of the whole workload and of its phases (GP training, policy search, rollouts),
the ratio, and whether each run swung the pendulum up. The port's environment needs
``tensorflow==2.21.* tf-keras tensorflow-probability==0.25.* gpflow==2.11.2 'numpy<2'
'pandas<2.3' 'gymnasium==1.4.*'``; its code stays outside this repository.

    python benchmarks/bench_pendulum.py --port /path/to/PILCO \\
        --port-python /path/to/port-venv/bin/python [--rounds 1] [--json out.json]

The port runs without GPflow's compile cache unless ``--port-compile-cache`` (with it,
its optimisations after the first use the first iteration's data: see
``pendulum_workload.py``).

Threads: both processes get this process's environment, so
``TF_NUM_INTRAOP_THREADS=1 python benchmarks/bench_pendulum.py ...`` times both with the
setting of this library's tasks.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
PHASES = ("seconds", "model", "policy", "rollout", "setup")


def run_workload(python: str, port: str | None, seed: int, iterations: int,
                 port_compile_cache: bool = False) -> dict:
    """One fresh process of ``pendulum_workload.py``; its JSON line."""
    cmd = [python, os.path.join(HERE, "pendulum_workload.py"), "--seed", str(seed),
           "--iterations", str(iterations)]
    if port:
        cmd += ["--port", port]
        if port_compile_cache:
            cmd += ["--port-compile-cache"]
    env = dict(os.environ, TF_CPP_MIN_LOG_LEVEL="2")
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    lines = [line for line in out.stdout.splitlines() if line.startswith("{")]
    if out.returncode != 0 or not lines:
        raise RuntimeError(f"{' '.join(cmd)} failed ({out.returncode}):\n{out.stderr[-2000:]}")
    return json.loads(lines[-1])


def summarise(runs: list[dict]) -> dict:
    """Medians of each phase over the runs of one library, and the runs' outcomes."""
    summary = {p: round(statistics.median(r[p] for r in runs), 1) for p in PHASES}
    summary["up_last"] = [r["up_last"] for r in runs]
    summary["first_up"] = [r["first_up"] for r in runs]
    summary["peak_mb"] = max(r["peak_mb"] for r in runs)
    return summary


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--port", required=True, help="checkout of nrontsis/PILCO")
    parser.add_argument("--port-python", required=True, help="python of the port's venv")
    parser.add_argument("--rounds", type=int, default=1, help="runs of each library")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--iterations", type=int, default=8)
    parser.add_argument("--port-compile-cache", action="store_true",
                        help="time the port with GPflow's compile cache, under which its "
                             "optimisations after the first use the first data "
                             "(pendulum_workload.py)")
    parser.add_argument("--json", default=None, help="add the results to this file")
    args = parser.parse_args(argv)
    if args.rounds < 1 or args.iterations < 1:
        parser.error("--rounds and --iterations must be at least 1")
    if not os.path.isdir(os.path.join(args.port, "pilco")):
        parser.error(f"--port {args.port!r} has no pilco package (a checkout of the port?)")

    runs: dict[str, list] = {"pilco": [], "port": []}
    for r in range(args.rounds):
        for name, python, port in (("pilco", sys.executable, None),
                                   ("port", args.port_python, args.port)):
            result = run_workload(python, port, args.seed, args.iterations,
                                  args.port_compile_cache)
            runs[name].append(result)
            print(f"round {r + 1} {name:5s}: {result['seconds']:7.1f} s (GP training "
                  f"{result['model']:.1f}, policy search {result['policy']:.1f}, rollouts "
                  f"{result['rollout']:.1f}); up in the last iteration: {result['up_last']}",
                  flush=True)
    ours, port = summarise(runs["pilco"]), summarise(runs["port"])
    print(f"\n{'phase':14s} {'pilco s':>9s} {'port s':>9s} {'ratio':>6s}")
    for p in PHASES:
        ratio = port[p] / ours[p] if ours[p] > 0 else float("nan")
        print(f"{p:14s} {ours[p]:9.1f} {port[p]:9.1f} {ratio:6.1f}")
    print(f"peak memory MB: pilco {ours['peak_mb']}, port {port['peak_mb']}")
    if args.json:
        results = {}
        if os.path.exists(args.json):
            with open(args.json, encoding="utf-8") as f:
                results = json.load(f)
        key = "pendulum_workload" + ("_port_compile_cache" if args.port_compile_cache else "")
        results[key] = {
            "seed": args.seed, "port_compile_cache": args.port_compile_cache,
            "iterations": args.iterations, "rounds": args.rounds,
            "threads": {k: os.environ[k] for k in ("TF_NUM_INTRAOP_THREADS",
                                                   "TF_NUM_INTEROP_THREADS")
                        if k in os.environ},
            "pilco": ours, "port": port, "runs": runs}
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(results, f, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
