"""TorchRL's PILCO example against this library's ``torchrl`` preset, one after the other.

Runs TorchRL's ``sota-implementations/pilco/pilco.py`` (InvertedPendulum-v5: 200 random
steps, an RBF policy of 10 basis functions, horizon 40, learning epochs of 100 Adam steps,
each evaluated on 100 steps with the mean action) in its own environment, then
``pilco run gym --preset torchrl`` for the same seeds, each in a fresh process under
``/usr/bin/time``, and reports per run the wall seconds, the peak resident memory and how
many steps each evaluation balanced the pole (TorchRL's ``eval/steps`` is its step
counter before the last step: 99 for all 100 steps). TorchRL's code and environment stay
outside this repository; its environment needs ``torchrl==0.14.1 torch==2.14.1 gpytorch==1.15.2
botorch==0.18.1 hydra-core 'gymnasium[mujoco]' 'mujoco>=3.3,<3.12'``.

    python benchmarks/bench_torchrl.py --torchrl-example /path/to/rl/sota-implementations/pilco \\
        --torchrl-python /path/to/torchrl-venv/bin/python [--seeds 0 1 2] [--epochs 1] \\
        [--timeout 1800] [--json out.json]

TorchRL's run logs to CSV (its example stops with a NameError when no logger backend is
set, and its CSV logger refuses the evaluation's reward, a one-element list: the launcher,
:data:`LAUNCH`, logs the element) without video, ``--epochs`` learning epochs (its default
is 3; its first epoch is enough to compare). Its evaluations are read from the CSV
logger's ``eval/steps``. This library's run has ``--epochs`` learned episodes after its
random ones, each one the evaluation.
"""
from __future__ import annotations

import argparse
import csv
import glob
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def timed(cmd, cwd: str, timeout: float, env=None) -> dict:
    """Run ``cmd`` under ``/usr/bin/time -v``: wall seconds, peak resident memory [MB],
    exit status (None after the timeout), the output's tail."""
    t0 = time.perf_counter()
    try:
        out = subprocess.run(["/usr/bin/time", "-v", *cmd], cwd=cwd, capture_output=True,
                             text=True, timeout=timeout, env=env, check=False)
        status, err, stdout = out.returncode, out.stderr, out.stdout
    except subprocess.TimeoutExpired as expired:
        status = None
        err = (expired.stderr or b"").decode(errors="replace") if isinstance(
            expired.stderr, bytes) else (expired.stderr or "")
        stdout = ""
    seconds = time.perf_counter() - t0
    peak = re.search(r"Maximum resident set size \(kbytes\): (\d+)", err)
    return {"seconds": round(seconds, 1), "peak_mb": round(int(peak.group(1)) / 1024, 1)
            if peak else None, "status": status, "tail": (stdout + err)[-1500:]}


#: runs TorchRL's example with one mend where it crashes: it logs the evaluation's reward
#: as a one-element list, which TorchRL's CSV logger refuses (``float(list)``); the
#: launcher logs the list's element instead. Nothing else of the example changes.
LAUNCH = """
import os, runpy, sys
from torchrl.record.loggers import csv as _csv
_log = _csv.CSVLogger.log_scalar
def _scalar(self, name, value, step=None):
    if isinstance(value, (list, tuple)) and len(value) == 1:
        value = value[0]
    return _log(self, name, value, step=step)
_csv.CSVLogger.log_scalar = _scalar
script = sys.argv[1]
sys.argv = sys.argv[1:]
sys.path.insert(0, os.path.dirname(os.path.abspath(script)))
runpy.run_path(script, run_name="__main__")
"""


def torchrl_run(python: str, example: str, seed: int, epochs: int, timeout: float) -> dict:
    """TorchRL's example for one seed (it sets no seed of its own: the seed only names
    the run), through :data:`LAUNCH`."""
    work = tempfile.mkdtemp(prefix=f"torchrl-pilco-{seed}-")
    cmd = [python, "-c", LAUNCH, os.path.join(example, "pilco.py"), f"pilco.epochs={epochs}",
           "logger.backend=csv", "logger.video=False", f"hydra.run.dir={work}"]
    env = dict(os.environ, MUJOCO_GL="egl")
    result = timed(cmd, work, timeout, env)
    steps = []
    for path in sorted(glob.glob(os.path.join(work, "**", "eval", "steps.csv"),
                                 recursive=True)):
        with open(path) as f:
            steps = [int(float(row[-1])) for row in csv.reader(f) if row]
    result.update(library="torchrl", seed=seed, eval_steps=steps)
    return result


def pilco_run(seed: int, epochs: int, timeout: float) -> dict:
    """``pilco run gym --preset torchrl`` for one seed with ``epochs`` learned episodes."""
    work = tempfile.mkdtemp(prefix=f"pilco-torchrl-{seed}-")
    random_episodes = 20  # the preset's
    cmd = [sys.executable, "-m", "pilco", "run", "gym", "--preset", "torchrl", "--seed",
           str(seed), "--episodes", str(random_episodes + epochs), "--output", work,
           "--quiet", "--no-figures"]
    result = timed(cmd, ROOT, timeout)
    steps = []
    summary = os.path.join(work, "summary.json")
    if os.path.exists(summary):
        with open(summary) as f:
            steps = [e["steps"] for e in json.load(f)["episodes"] if not e["random"]]
    result.update(library="pilco", seed=seed, eval_steps=steps)
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--torchrl-example", required=True,
                        help="the directory of TorchRL's sota-implementations/pilco")
    parser.add_argument("--torchrl-python", required=True,
                        help="the Python of an environment with TorchRL installed")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--epochs", type=int, default=1,
                        help="learning epochs (TorchRL) and learned episodes (pilco)")
    parser.add_argument("--timeout", type=float, default=1800.0,
                        help="seconds one run may take before it is stopped")
    parser.add_argument("--json", help="write the runs and medians here")
    args = parser.parse_args(argv)
    if not os.path.exists(os.path.join(args.torchrl_example, "pilco.py")):
        parser.error(f"--torchrl-example {args.torchrl_example}: no pilco.py there")
    runs = []
    for seed in args.seeds:
        for run in (torchrl_run(args.torchrl_python, args.torchrl_example, seed,
                                args.epochs, args.timeout),
                    pilco_run(seed, args.epochs, args.timeout)):
            runs.append(run)
            print(f"{run['library']:>8} seed {seed}: {run['seconds']:8.1f} s, peak "
                  f"{run['peak_mb']} MB, exit {run['status']}, evaluation steps "
                  f"{run['eval_steps']}", flush=True)
            if run["status"] != 0:
                print(run["tail"], flush=True)
    medians = {}
    for library in ("torchrl", "pilco"):
        done = [r for r in runs if r["library"] == library and r["status"] == 0]
        if done:
            medians[library] = {"seconds": statistics.median(r["seconds"] for r in done),
                                "peak_mb": max(r["peak_mb"] for r in done), "runs": len(done)}
    print(json.dumps(medians))
    if args.json:
        with open(args.json, "w") as f:
            kept = [{k: v for k, v in r.items() if k != "tail"} for r in runs]
            json.dump({"epochs": args.epochs, "runs": kept, "medians": medians}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
