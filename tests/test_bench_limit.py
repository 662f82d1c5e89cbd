"""``benchmarks/bench_limit.py``: its flop counter is exact on small graphs of known
count, and the functions of its ``--quick`` path give positive finite numbers on a tiny
problem (fast: small sizes, one repeat)."""
from __future__ import annotations

import importlib.util
import math
import os

import numpy as np
import pytest
import tensorflow as tf

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="module")
def bench():
    """The script as a module (benchmarks/ is not a package; the script puts its own
    directory on sys.path for bench_policy)."""
    path = os.path.join(ROOT, "benchmarks", "bench_limit.py")
    spec = importlib.util.spec_from_file_location("bench_limit", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _graph(fn, *args):
    return tf.function(fn, autograph=False).get_concrete_function(*args).graph


def test_counts_a_matmul_and_elementwise_operations_exactly(bench):
    a = tf.TensorSpec([3, 4], tf.float64)
    b = tf.TensorSpec([4, 5], tf.float64)
    # [3, 4] x [4, 5]: 2*3*4*5 = 120; exp and the addition: 15 each; the sum: 15 inputs
    graph = _graph(lambda x, y: tf.reduce_sum(tf.exp(tf.matmul(x, y)) + 1.0), a, b)
    count = bench.count_graph(graph, loop_iterations=1)
    assert count["flops"] == 120 + 15 + 15 + 15
    assert count["flops_by_type"]["MatMul"] == 120
    # MatMul, Exp, AddV2, Sum and the function's output Identity (constants and
    # arguments left out)
    assert count["ops"] == 5
    assert dict(count["ops_by_type"]) == {"MatMul": 1, "Exp": 1, "AddV2": 1, "Sum": 1,
                                          "Identity": 1}
    assert count["unknown_shapes"] == [] and count["uncounted_types"] == []
    # float bytes: matmul 8*(12 + 20 + 15), exp 8*30, add 8*(15 + 1 + 15), sum 8*(15 + 1)
    assert count["bytes"] == 8 * (47 + 30 + 31 + 16)


def test_slices_are_data_movement_and_need_static_shapes(bench):
    # a row of a [3, 4] matrix (as the objective takes each task's start): no flops, one
    # executed operation, its input and output read and written once
    graph = _graph(lambda x: x[1], tf.TensorSpec([3, 4], tf.float64))
    count = bench.count_graph(graph, 1)
    assert count["flops"] == 0
    assert count["ops_by_type"]["StridedSlice"] == 1
    assert count["bytes"] == 8 * (12 + 4)
    assert count["unknown_shapes"] == [] and count["uncounted_types"] == []
    # the same slice of a matrix with an open number of rows: its bytes are not known
    graph = _graph(lambda x: x[1], tf.TensorSpec([None, 4], tf.float64))
    assert bench.count_graph(graph, 1)["unknown_shapes"] == ["StridedSlice"]


def test_batched_and_transposed_products(bench):
    a = tf.TensorSpec([6, 7, 3], tf.float64)  # transposed: [6, 3, 7]
    b = tf.TensorSpec([6, 7, 2], tf.float64)
    graph = _graph(lambda x, y: tf.matmul(x, y, transpose_a=True), a, b)
    assert bench.count_graph(graph, 1)["flops"] == 2 * 6 * 3 * 7 * 2


def test_follows_loops_and_function_calls(bench):
    inner = tf.function(lambda x, m: tf.matmul(x, m) * 2.0, autograph=False)

    def fn(x, m):
        def body(t, x):
            return t + 1, inner(x, m)
        return tf.while_loop(lambda t, x: t < 3, body, (tf.constant(0), x))[1]

    graph = _graph(fn, tf.TensorSpec([3, 5], tf.float64), tf.TensorSpec([5, 5], tf.float64))
    count = bench.count_graph(graph, loop_iterations=3)
    # per step: [3, 5] x [5, 5] (150) and the multiplication (15); integer counter: none
    assert count["flops"] == 3 * (150 + 15)
    assert count["flops_by_type"]["MatMul"] == 450


def test_pair_block_by_hand(bench):
    # E = 1 (one pair, diagonal), D = 1, n = 1, one step: exponent 2*3, exp 1, 2*2, 2,
    # diagonal 1 + 2*2
    assert bench.pair_block_flops(1, 1, 1, 1) == 6 + 1 + 4 + 2 + 1 + 4
    assert bench.pair_block_flops(4, 10, 6, 40) == 40 * 100 * (10 * 33 + 4 * 15)


def _positive_finite(x):
    return isinstance(x, (int, float)) and math.isfinite(x) and x > 0


def test_quick_path_functions_on_a_tiny_problem(bench):
    # one trace for the count and the timing (the script traces each agent separately and
    # times the library's variables of dynamic shape, but compiling twice is too slow here)
    agent = bench.build_problem("cartpole", 5)
    evaluate = bench.loss_and_gradient(bench.with_static_shapes(agent))
    # the dynamics GP's data and the start distributions: no variable of open shape left
    assert all(v.shape.is_fully_defined() for v in agent._rollout.variables)
    count = bench.count_graph(evaluate.get_concrete_function().graph, agent.horizon)
    assert _positive_finite(count["flops"]) and _positive_finite(count["bytes"])
    assert count["unknown_shapes"] == [] and count["uncounted_types"] == []
    dims = bench.problem_dimensions(agent)
    assert dims == {"outputs": 4, "inputs": 6, "horizon": 40, "n": 5}
    block = bench.pair_block_flops(dims["outputs"], 5, dims["inputs"], dims["horizon"])
    assert 0 < block < count["flops"]
    timing = bench.time_evaluation(agent, repeats=1, evaluate=evaluate)
    assert _positive_finite(timing["seconds"]) and np.isfinite(timing["value"])
    # the optimised graph: loops lowered and functions inlined, more nodes run per step
    # than outside the loops
    assert timing["functions_left"] == 0
    assert timing["per_iteration"] > timing["outside"] > 0
    assert timing["executed"] == timing["outside"] + 40 * timing["per_iteration"]
    assert _positive_finite(bench.pair_block_seconds(2, 3, 4, repeats=1))
    assert all(_positive_finite(v) for v in bench.matmul_rates(64, repeats=1).values())
    assert all(_positive_finite(v) for v in bench.elementwise_rates(4096, repeats=1).values())
    # the slope of two minima over alternating calls, 20 each (as the script's least), so
    # that a loaded machine's delays do not reach every call of one chain; 900 operations
    # apart, so that the difference is well above a timer's jitter
    assert _positive_finite(bench.op_overhead(repeats=20, lengths=(100, 1000)))


def _setting(peak, seconds, pair_groups, counted):
    row = {"problem": "cartpole", "N": 40, "seconds": seconds, "executed": 1000,
           "floor_seconds": 0.01, "pair_block_flops": 6e6, "pair_block_seconds": 0.02,
           "pair_groups": pair_groups}
    if counted:
        row.update(flops=1e7 * pair_groups, graph_operations=900 + pair_groups, bytes=1e6,
                   floor_flops=1e5, flops_by_type={}, unknown_shapes=[],
                   uncounted_types=[])
    return {"matmul_gflops": {"numpy": peak, "tensorflow": peak / 2},
            "elementwise_gbs": {"numpy": 10.0}, "op_seconds": 1e-6, "rows": [row]}


def test_the_sweep_setting_keeps_its_own_count_and_is_rated_against_one_core(bench):
    settings = {"1": _setting(20.0, 0.1, 2, counted=True),
                "sweep": _setting(20.0, 0.2, 1, counted=True),
                "default": _setting(40.0, 0.1, 2, counted=False)}
    bench.share_counts(settings)
    # the uncounted setting takes the first setting's count, the sweep's keeps its own
    assert settings["default"]["rows"][0]["flops"] == 2e7
    assert settings["sweep"]["rows"][0]["flops"] == 1e7
    rows = {r["threads"]: r for r in bench.table({"settings": settings})}
    assert rows["sweep"]["gflops"] == pytest.approx(0.05)
    assert rows["sweep"]["peak1_percent"] == pytest.approx(0.25)  # of one core's 20
    assert rows["sweep"]["peak2_percent"] == pytest.approx(0.125)  # of both cores' 40
    # without the "1" process, one core's peak is the sweep process's
    del settings["1"]
    rows = {r["threads"]: r for r in bench.table({"settings": settings})}
    assert rows["sweep"]["peak1_percent"] == pytest.approx(0.25)
    # an uncounted setting whose graph differs from the counted one's is refused
    settings = {"1": _setting(20.0, 0.1, 2, counted=True),
                "default": _setting(40.0, 0.1, 1, counted=False)}
    with pytest.raises(RuntimeError, match="pair groups"):
        bench.share_counts(settings)
