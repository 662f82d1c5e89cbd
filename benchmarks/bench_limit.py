"""How far is the policy objective + gradient from what this machine can do in float64?

For each problem of ``bench_policy.py`` (its builders, imported) and number of
transitions N, this script counts the float64 operations of one evaluation of the policy
objective and its gradient (the function L-BFGS-B evaluates) from the compiled graph,
times the evaluation, and sets the achieved rate beside the machine's own float64 limits
measured in the same process and thread settings: a large matrix product (TensorFlow and
numpy), a memory-bound elementwise multiply-add, and TensorFlow's cost per executed
operation.

Usage::

    python benchmarks/bench_limit.py                      # all sizes, both thread settings
    python benchmarks/bench_limit.py --quick              # one size per problem
    python benchmarks/bench_limit.py --json out.json --repeats 7

Each thread setting runs in a fresh process of its own (TensorFlow fixes its thread
pools at its first operation): ``1`` is a task's own setting (``TF_NUM_INTRAOP_THREADS=1``,
:func:`pilco.runtime.configure_threads`; the inter-op pool keeps every CPU, so
independent parts of the objective run side by side, with ``PILCO_PAIR_GROUPS=threads``
also its groups of output pairs, and one evaluation can keep more than one core busy;
numpy's BLAS on one thread), ``sweep`` a sweep's run on one CPU (one intra-op and one
inter-op thread, :func:`pilco.runtime.thread_environment`: everything on one core),
``default`` TensorFlow's and numpy's defaults (every CPU). Each row records its number of
pair groups.

How the flops are counted: the objective + gradient is traced as one ``tf.function``
(with the dynamics GP's data and the start distributions in variables of static shape,
so that every tensor's shape is known; the timed function is the library's own,
unchanged). The graph is walked: function calls are followed into their graphs, the
bodies of the horizon's loops (the forward one and its gradient) counted once per step.
Per operation: a matrix product ``[m, k] x [k, n]`` 2mkn per batch entry; an elementwise
operation (arithmetic, ``exp``, ``sin``, ...) one per output element; a reduction one
per input element; ``AddN`` of k inputs k-1 per element; a d x d inverse 2d^3,
log-determinant and LU solve 2d^3/3 (+2d^2 per right-hand side), Cholesky d^3/3; data
movement (reshape, concat, slice, gather, transpose, ...) none. So a transcendental
function counts as one operation, as in TensorFlow's profiler. The counter is checked
against an analytic count of the dominant term (the dynamics GP's n x n pair block,
``pair_block_flops``).

Columns of the table:

- ``task``, ``N``: the problem and its number of transitions (the dynamics GP's n);
- ``threads``: ``1`` (one intra-op thread, a task's setting), ``sweep`` (one thread in
  all, a sweep's run on one CPU) or ``default``;
- ``MFLOP``: float64 operations of one objective + gradient, in millions;
- ``s``: seconds per objective + gradient, the fastest of ``--repeats`` calls after a
  warm-up call (which traces and compiles);
- ``GFLOP/s``: MFLOP / s / 1000, the achieved rate;
- ``%peak1``, ``%peak2``: that rate as a percentage of the machine's float64 matrix-product
  peak on 1 and on 2 threads (the better of TensorFlow's and numpy's 2000 x 2000 product,
  measured in the ``1`` (or ``sweep``) and ``default`` processes);
- ``ops``: nodes TensorFlow executes per evaluation, counted in the graph as it runs
  (after Grappler's optimisation, which inlines the function calls, removes some
  operations and lowers each loop to control-flow nodes, one ``Switch``, ``Merge`` and
  ``NextIteration`` per loop variable and step; constants left out; a loop's nodes once
  per step). The graph before optimisation has another count (``graph_ops`` in the
  JSON, the loop bodies' part of it is ``bench_policy.py``'s ``loop ops``);
- ``%ovh``: estimated share of the time that is per-operation overhead: ops x the
  measured cost of a tiny operation (a chain of small multiplies and subtractions, which
  the graph optimiser cannot merge) / s. A lower estimate: real operations allocate and
  check more than a tiny one;
- ``%fix``: the same evaluation with N = ``--floor-data`` transitions (the same graph,
  almost no n-dependent work) over s: an upper estimate of the time that does not come
  from the n-sized arithmetic (overhead plus the policy's and other small work);
- ``%mem``: bytes that the operations read and write (every input and output once,
  data-movement operations included) at the measured elementwise bandwidth of large
  arrays, over s: the time if every byte came from main memory (most of the objective's
  tensors fit in the caches, so an upper estimate of the memory-bound time);
- ``%n2``: share of the flops in the dynamics GP's n x n pair block (counted by hand,
  ``pair_block_flops``);
- ``%blk``, ``blk GF/s``: that block's forward pass alone (the library's function on
  random inputs of the problem's shapes, ``pair_block_seconds``), horizon times, as a
  share of s, and its rate: what TensorFlow's kernels reach on those shapes.

The JSON also holds the n^2 coefficient of the counted flops (fitted over the sizes)
beside the hand count (``cross_check``), the flops by operation type, the first call's
seconds, the median seconds and the load average before and after. On a shared machine
every figure depends on the load: the fastest of several calls is reported, the sizes
of one problem are timed in alternating rounds, and the references are measured in the
same process just before.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import time
from collections import Counter
from typing import Callable, Dict, Iterable, List, Optional

import numpy as np

from pilco.runtime import thread_environment

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # bench_policy, run by path

#: the sizes measured: number of transitions of each problem
SIZES = {"cartpole": (40, 80, 160, 320), "reacher": (50, 100, 200)}
#: the sizes of ``--quick``
QUICK_SIZES = {"cartpole": (80,), "reacher": (100,)}

# -- counting -------------------------------------------------------------------------------

#: elementwise operations, one flop per output element
ELEMENTWISE = frozenset({
    "Add", "AddV2", "Sub", "Mul", "RealDiv", "Div", "DivNoNan", "MulNoNan", "Neg", "Exp",
    "Log", "Log1p", "Expm1", "Sqrt", "Rsqrt", "Square", "Reciprocal", "Inv", "Sin", "Cos",
    "Tan", "Tanh", "Sigmoid", "Maximum", "Minimum", "Abs", "Sign", "Pow", "Floor", "Ceil",
    "Round", "SquaredDifference", "SqrtGrad", "RsqrtGrad", "ReciprocalGrad", "InvGrad",
    "TanhGrad", "SigmoidGrad", "Less", "LessEqual", "Greater", "GreaterEqual", "Equal",
    "NotEqual", "Select", "SelectV2", "Cast", "Softplus", "SoftplusGrad",
})
#: reductions, one flop per input element
REDUCTIONS = frozenset({"Sum", "Mean", "Prod", "Max", "Min"})
#: operations that move, select or describe data and do no float arithmetic
DATA_MOVEMENT = frozenset({
    "Const", "Placeholder", "Identity", "IdentityN", "NoOp", "ReadVariableOp", "Reshape",
    "ExpandDims", "Squeeze", "ConcatV2", "Pack", "Unpack", "StridedSlice",
    "StridedSliceGrad", "Slice", "Pad", "PadV2", "Tile", "Transpose", "GatherV2",
    "BroadcastTo", "ZerosLike", "OnesLike", "Fill", "Shape", "ShapeN", "Size", "Rank",
    "BroadcastGradientArgs", "MatrixDiagV3", "MatrixDiagPartV3", "MatrixSetDiagV3",
    "MatrixBandPart", "Range", "Split", "SplitV", "ConcatOffset", "StopGradient",
    "PreventGradient", "EmptyTensorList", "TensorListPushBack", "TensorListPopBack",
    "TensorListReserve", "TensorListElementShape", "TensorListLength", "TensorListStack",
    "TensorListFromTensor", "TensorListGetItem", "TensorListSetItem", "TensorListResize",
    "ScatterNd", "TensorScatterUpdate", "InvertPermutation", "Cumsum", "UnsortedSegmentSum",
    "DynamicStitch", "Maximum_int", "Switch", "Merge", "Enter", "Exit", "NextIteration",
    "LoopCond", "Where", "OptionalNone", "OptionalFromValue", "OptionalHasValue",
    "OptionalGetValue", "VarHandleOp", "AssignVariableOp", "Assert", "CheckNumerics",
    "EnsureShape", "Snapshot",
})
#: operations that only describe tensors: no bytes counted for them
METADATA = frozenset({
    "Const", "Placeholder", "Identity", "IdentityN", "NoOp", "ReadVariableOp", "Reshape",
    "ExpandDims", "Squeeze", "Shape", "ShapeN", "Size", "Rank", "BroadcastGradientArgs",
    "StopGradient", "PreventGradient", "EnsureShape", "Snapshot",
})
#: not executed as operations of their own: left out of the count of executed operations
NOT_EXECUTED = frozenset({"Const", "Placeholder"})
CALLS = frozenset({"PartitionedCall", "StatefulPartitionedCall"})
LOOPS = frozenset({"While", "StatelessWhile"})


def _shape(tensor) -> Optional[List[int]]:
    """The static shape of ``tensor`` as a list, None if any dimension is unknown."""
    dims = tensor.shape.as_list() if tensor.shape.rank is not None else None
    if dims is None or any(d is None for d in dims):
        return None
    return dims


def _elements(tensor) -> Optional[int]:
    shape = _shape(tensor)
    return None if shape is None else int(np.prod(shape, dtype=np.int64))


def _matmul_flops(a_shape, b_shape, transpose_a, transpose_b, out_shape) -> int:
    """2 m k n per output matrix of ``[.., m, k] x [.., k, n]`` (batch from the output)."""
    k = a_shape[-2] if transpose_a else a_shape[-1]
    m, n = out_shape[-2], out_shape[-1]
    batch = int(np.prod(out_shape[:-2], dtype=np.int64)) if len(out_shape) > 2 else 1
    return 2 * batch * m * k * n


def op_flops(op) -> Optional[int]:
    """Float operations of one execution of ``op`` (see the module doc), None when the
    shapes it needs are not static; 0 for data movement and unknown types (those are
    listed by :func:`count_graph`)."""
    kind = op.type
    if kind in DATA_MOVEMENT or kind in CALLS or kind in LOOPS:
        return 0
    if op.outputs and not op.outputs[0].dtype.is_floating and kind not in ("Cast",):
        return 0  # integer bookkeeping (loop counters, indices)
    if kind in ("MatMul", "BatchMatMul", "BatchMatMulV2", "BatchMatMulV3"):
        a, b, out = (_shape(t) for t in (op.inputs[0], op.inputs[1], op.outputs[0]))
        if a is None or b is None or out is None:
            return None
        if kind == "MatMul":
            ta, tb = op.get_attr("transpose_a"), op.get_attr("transpose_b")
        else:
            ta, tb = op.get_attr("adj_x"), op.get_attr("adj_y")
        return _matmul_flops(a, b, ta, tb, out)
    if kind in ELEMENTWISE:
        return _elements(op.outputs[0])
    if kind in REDUCTIONS:
        return _elements(op.inputs[0])
    if kind == "AddN":
        n = _elements(op.outputs[0])
        return None if n is None else (len(op.inputs) - 1) * n
    if kind in ("MatrixInverse", "LogMatrixDeterminant", "Cholesky", "MatrixSolve",
                "MatrixTriangularSolve", "MatrixDeterminant"):
        a = _shape(op.inputs[0])
        if a is None:
            return None
        d = a[-1]
        batch = int(np.prod(a[:-2], dtype=np.int64)) if len(a) > 2 else 1
        if kind == "MatrixInverse":
            per = 2 * d ** 3  # LU (2d^3/3) and the inverse from it (4d^3/3)
        elif kind in ("LogMatrixDeterminant", "MatrixDeterminant"):
            per = 2 * d ** 3 // 3  # LU
        elif kind == "Cholesky":
            per = d ** 3 // 3
        else:
            rhs = _shape(op.inputs[1])
            if rhs is None:
                return None
            k = rhs[-1]
            per = (2 * d ** 3 // 3 if kind == "MatrixSolve" else 0) + 2 * d * d * k
        return batch * per
    return 0


def op_bytes(op) -> Optional[int]:
    """Bytes ``op`` reads and writes, every input and output once (0 for operations that
    only describe tensors); None if a shape is not static."""
    if op.type in METADATA or op.type in CALLS or op.type in LOOPS:
        return 0
    total = 0
    for t in list(op.inputs) + list(op.outputs):
        if t.dtype.is_floating:
            n = _elements(t)
            if n is None:
                return None
            total += n * t.dtype.size
    return total


class Count(dict):
    """Totals of one evaluation: ``flops``, ``ops`` (executed operations), ``bytes``,
    ``flops_by_type`` / ``ops_by_type`` {op type: total}, ``unknown_shapes`` (op types
    whose static shapes were incomplete: their flops are missing) and ``uncounted_types``
    (op types counted as no flops that are not known data movement)."""


def _function_graph(graph, name: str):
    """The graph of the function ``name``, looked up in ``graph`` and its outer graphs."""
    g = graph
    while g is not None:
        fn = g._get_function(name)  # TensorFlow has no public lookup of a graph's functions
        if fn is not None:
            return fn.graph
        g = getattr(g, "outer_graph", None)
    raise LookupError(f"function {name} not found")


def count_graph(graph, loop_iterations: int) -> Count:
    """Flops, executed operations and bytes of one run of ``graph`` (a ``FuncGraph``):
    called functions are counted once per call, the bodies of ``While`` loops
    ``loop_iterations`` times (every loop of the objective runs the horizon's steps) and
    their conditions once more than that."""
    total = Count(flops=0, ops=0, bytes=0, flops_by_type=Counter(), ops_by_type=Counter(),
                  unknown_shapes=set(), uncounted_types=set())

    def walk(g, times):
        for op in g.get_operations():
            if op.type in CALLS:
                walk(_function_graph(g, op.get_attr("f").name), times)
            elif op.type in LOOPS:
                body = getattr(op, "_body_graph", None)
                cond = getattr(op, "_cond_graph", None)
                walk(body if body is not None
                     else _function_graph(g, op.get_attr("body").name),
                     times * loop_iterations)
                walk(cond if cond is not None
                     else _function_graph(g, op.get_attr("cond").name),
                     times * (loop_iterations + 1))
            flops, nbytes = op_flops(op), op_bytes(op)
            if flops is None or nbytes is None:
                total["unknown_shapes"].add(op.type)
            flops, nbytes = flops or 0, nbytes or 0
            if (op.type not in ELEMENTWISE | REDUCTIONS | DATA_MOVEMENT | CALLS | LOOPS
                    and flops == 0 and any(t.dtype.is_floating for t in op.outputs)):
                total["uncounted_types"].add(op.type)
            total["flops"] += times * flops
            total["bytes"] += times * nbytes
            total["flops_by_type"][op.type] += times * flops
            if op.type not in NOT_EXECUTED:
                total["ops"] += times
                total["ops_by_type"][op.type] += times

    walk(graph, 1)
    total["unknown_shapes"] = sorted(total["unknown_shapes"])
    total["uncounted_types"] = sorted(total["uncounted_types"])
    return total


def loss_and_gradient(agent):
    """The policy objective and its gradient w.r.t. the policy's parameters in one
    ``tf.function``, as L-BFGS-B evaluates them (``gpflow.optimizers.Scipy``)."""
    import tensorflow as tf

    variables = agent.controller.trainable_variables

    @tf.function(autograph=False)
    def evaluate():
        with tf.GradientTape() as tape:
            loss = agent._rollout.policy_loss()
        return loss, tape.gradient(loss, variables)

    return evaluate


def with_static_shapes(agent):
    """``agent`` (returned) with its dynamics model refreshed into the rollout's copies of
    the dynamics GP's data, and the rollout's variables of open shape (the GP data's n,
    resized as data grow, and the start distributions' number of tasks T, whose rows the
    objective slices out) replaced by variables of the same values and static shapes:
    every operation's shape is then known to the graph. For counting: the timings use
    agents as the library builds them."""
    import tensorflow as tf

    rollout = agent._rollout
    rollout.refresh(agent.mgpr)
    for name, value in list(vars(rollout).items()):
        if isinstance(value, tf.Variable) and not value.shape.is_fully_defined():
            setattr(rollout, name, tf.Variable(value.numpy(), trainable=False))
    rollout.retrace()  # the traces read the variables they were traced with
    return agent


def count_evaluation(agent) -> Count:
    """:func:`count_graph` of one objective + gradient of ``agent``, through
    :func:`with_static_shapes` (which changes the agent: build one for counting)."""
    evaluate = loss_and_gradient(with_static_shapes(agent))
    return count_graph(evaluate.get_concrete_function().graph, agent.horizon)


def pair_block_flops(outputs: int, n: int, inputs: int, horizon: int) -> int:
    """The n^2 terms of one objective + gradient, counted by hand from
    ``pilco.moments.pairs._pair_second_moments`` (the dynamics GP's pair block; its
    hand-made gradient has no n x n work): per step and per output pair p of
    P = E(E+1)/2, the exponent ``leftT^T rightT`` (2(D+2)n^2 for D GP inputs), its
    ``exp`` (n^2), ``Q [bJ, bJ * iiJ]^T`` (2(D+1)n^2) and ``Q^T bI`` (2n^2); per diagonal
    pair (E of them) ``iK * Q`` (n^2) and its product with ``[1, iiJ]^T``
    (2(D+1)n^2)."""
    E, D = outputs, inputs
    P = E * (E + 1) // 2
    per_step = P * (2 * (D + 2) + 1 + 2 * (D + 1) + 2) + E * (1 + 2 * (D + 1))
    return horizon * per_step * n * n


def problem_dimensions(agent) -> Dict[str, int]:
    """E (state dimensions = GP outputs), the GP's inputs (state features + actions), the
    horizon and n of an agent."""
    return {"outputs": agent.state_dim,
            "inputs": agent.feature_dim + agent.control_dim,
            "horizon": agent.horizon,
            "n": int(agent.mgpr.X.shape[0])}


def executed_operations(graph_def, iterations: int) -> Dict[str, int]:
    """Nodes TensorFlow executes in one run of its optimised graph ``graph_def`` (the
    ``post_optimization_graph`` of a function's run metadata), constants left out.

    By then Grappler has inlined the function calls and lowered each ``While`` loop to
    ``Enter``/``Merge``/``Switch``/``NextIteration``/``Exit`` nodes: a node is in a
    loop's frame when it is reached from that loop's ``Enter`` nodes before an ``Exit``;
    such a node runs ``iterations`` times, except ``Enter`` and ``Exit`` (once). Returns
    ``executed``, ``per_iteration`` (all loops' nodes run each step), ``outside`` and
    ``functions_left`` (functions the graph still calls, their bodies not counted)."""
    nodes = {n.name: n for n in graph_def.node}
    consumers: Dict[str, List[str]] = {}
    for n in graph_def.node:
        for name in n.input:
            consumers.setdefault(name.lstrip("^").split(":")[0], []).append(n.name)
    frame: Dict[str, str] = {}
    stack = [n.name for n in graph_def.node if n.op in ("Enter", "RefEnter")]
    for name in stack:
        frame[name] = nodes[name].attr["frame_name"].s.decode()
    while stack:
        name = stack.pop()
        if nodes[name].op in ("Exit", "RefExit"):
            continue  # the frame ends here
        for c in consumers.get(name, ()):
            if c not in frame:
                frame[c] = frame[name]
                stack.append(c)
    per_iteration = outside = 0
    for n in graph_def.node:
        if n.op == "Const":
            continue
        if n.name in frame and n.op not in ("Enter", "RefEnter", "Exit", "RefExit"):
            per_iteration += 1
        else:
            outside += 1
    return {"executed": outside + iterations * per_iteration, "per_iteration": per_iteration,
            "outside": outside, "functions_left": len(graph_def.library.function)}


# -- timing ---------------------------------------------------------------------------------

def _best_seconds(fn: Callable[[], object], repeats: int) -> List[float]:
    """Seconds of ``repeats`` calls of ``fn`` after one warm-up call."""
    fn()
    seconds = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        seconds.append(time.perf_counter() - t0)
    return seconds


def prepare_evaluation(agent, evaluate=None):
    """The objective + gradient of ``agent`` (its dynamics model refreshed here) as a
    Python callable, and what its first call (tracing and compilation) showed:
    ``value``, ``first_seconds`` and :func:`executed_operations` of the optimised graph
    that ran. ``evaluate``: :func:`loss_and_gradient` of the agent if already made."""
    from tensorflow.python.eager import context  # run metadata: no public API in TF 2

    agent._rollout.refresh(agent.mgpr)
    if evaluate is None:
        evaluate = loss_and_gradient(agent)

    def call():
        loss, grads = evaluate()
        return float(loss), [g.numpy() for g in grads]

    ctx = context.context()
    ctx.enable_run_metadata()  # the first call records the graph Grappler optimised
    try:
        t0 = time.perf_counter()
        value, _ = call()
        first = time.perf_counter() - t0
        metadata = ctx.export_run_metadata()
    finally:
        ctx.disable_run_metadata()
    graphs = [g.post_optimization_graph for g in metadata.function_graphs]
    executed = max((executed_operations(g, agent.horizon) for g in graphs),
                   key=lambda c: c["executed"], default={})
    return call, {"value": value, "first_seconds": first, **executed}


def interleaved_seconds(calls: Dict[str, Callable[[], object]],
                        repeats: int) -> Dict[str, List[float]]:
    """Seconds of ``repeats`` rounds in which every callable of ``calls`` runs once (after
    one warm-up round): on a shared machine the load changes over minutes, and
    alternating keeps it from favouring one of the callables."""
    for fn in calls.values():
        fn()
    seconds: Dict[str, List[float]] = {name: [] for name in calls}
    for _ in range(repeats):
        for name, fn in calls.items():
            t0 = time.perf_counter()
            fn()
            seconds[name].append(time.perf_counter() - t0)
    return seconds


def time_evaluation(agent, repeats: int, evaluate=None) -> Dict[str, object]:
    """:func:`prepare_evaluation` and ``repeats`` timed calls of one agent's objective +
    gradient: ``seconds`` (the fastest), ``median_seconds``, ``all_seconds``."""
    call, info = prepare_evaluation(agent, evaluate)
    seconds = _best_seconds(call, repeats)
    return {**info, "seconds": min(seconds), "median_seconds": float(np.median(seconds)),
            "all_seconds": seconds}


def pair_block_seconds(outputs: int, inputs: int, n: int, repeats: int) -> float:
    """Seconds of the n^2 work of one step alone: the forward pass of the dynamics GP's
    pair block (``pilco.moments.pairs._pair_second_moments``, the library's function,
    all E(E+1)/2 pairs in one group) on random inputs of the problem's shapes, the
    fastest of ``repeats`` calls. Its gradient has no n x n work, so ``horizon`` times
    this is the time the pair block's flops (:func:`pair_block_flops`) take at the speed
    TensorFlow's kernels reach on those shapes by themselves."""
    import tensorflow as tf

    from pilco.moments.pairs import _pair_second_moments

    E, D = outputs, inputs
    P = E * (E + 1) // 2
    rng = np.random.default_rng(0)

    def const(*shape, scale=1.0):
        return tf.constant(scale * rng.standard_normal(shape))

    # moderate exponents (u, v ~ -1, a small T), as a rollout has, so that exp neither
    # overflows nor underflows into slow subnormal numbers
    T = tf.constant(np.broadcast_to(0.01 * np.eye(D), (P, D, D)).copy())
    args = (T, const(P, D), const(P, D), const(P, n, scale=0.1) - 1.0,
            const(P, n, scale=0.1) - 1.0, const(P, D, n), const(P, D, n), const(P, n),
            const(P, n), const(E, n, n, scale=0.01))
    block = tf.function(lambda *a: _pair_second_moments(*a), autograph=False)
    return min(_best_seconds(lambda: block(*args).numpy(), repeats))


def matmul_rates(size: int, repeats: int) -> Dict[str, float]:
    """GFLOP/s of a float64 ``[size, size] x [size, size]`` product (2 size^3 flops), the
    fastest of ``repeats`` calls after a warm-up, with TensorFlow (Eigen) and numpy (its
    BLAS), each on the threads this process was given."""
    import tensorflow as tf

    rng = np.random.default_rng(0)
    a, b = rng.standard_normal((size, size)), rng.standard_normal((size, size))
    ta, tb = tf.constant(a), tf.constant(b)
    flops = 2.0 * size ** 3
    tf_s = min(_best_seconds(lambda: tf.linalg.matmul(ta, tb)[0, 0].numpy(), repeats))
    np_s = min(_best_seconds(lambda: a @ b, repeats))
    return {"tensorflow": flops / tf_s / 1e9, "numpy": flops / np_s / 1e9}


def elementwise_rates(elements: int, repeats: int) -> Dict[str, float]:
    """GB/s of ``a * b + c`` over float64 arrays of ``elements`` entries (two operations,
    each reading two arrays and writing one: 48 bytes per element), the fastest of
    ``repeats``, with TensorFlow and numpy (into a preallocated array). Arrays much larger
    than the caches measure the main memory's bandwidth."""
    import tensorflow as tf

    rng = np.random.default_rng(0)
    a, b, c = (rng.standard_normal(elements) for _ in range(3))
    out = np.empty_like(a)
    ta, tb, tc = tf.constant(a), tf.constant(b), tf.constant(c)
    fused = tf.function(lambda x, y, z: x * y + z, autograph=False)

    def with_numpy():
        np.multiply(a, b, out=out)
        np.add(out, c, out=out)

    nbytes = 48.0 * elements
    tf_s = min(_best_seconds(lambda: fused(ta, tb, tc)[0].numpy(), repeats))
    np_s = min(_best_seconds(with_numpy, repeats))
    return {"tensorflow": nbytes / tf_s / 1e9, "numpy": nbytes / np_s / 1e9}


def op_overhead(repeats: int, lengths=(1000, 3000)) -> float:
    """Seconds per executed tiny operation inside a ``tf.function``: the difference
    between chains of ``lengths`` alternating multiplies and subtractions of 4 x 4
    matrices (which Grappler cannot merge, unlike a chain of additions or of one unary
    function), per operation added; the fastest of ``repeats`` calls each. The two chains'
    calls alternate, so that a burst of load elsewhere on the machine meets both alike."""
    import tensorflow as tf

    def chain(k):
        @tf.function(autograph=False)
        def f(x, y):
            for i in range(k):
                x = x * y if i % 2 else x - y
            return x
        return f

    x = tf.ones([4, 4], tf.float64)
    y = tf.fill([4, 4], tf.constant(1.0 + 1e-9, tf.float64))
    calls = [chain(k) for k in lengths]
    best = [math.inf, math.inf]
    for f in calls:  # warm-up: tracing and compilation
        f(x, y).numpy()
    for _ in range(repeats):
        for i, f in enumerate(calls):
            t0 = time.perf_counter()
            f(x, y).numpy()
            best[i] = min(best[i], time.perf_counter() - t0)
    return (best[1] - best[0]) / (lengths[1] - lengths[0])


# -- one thread setting, in this process ----------------------------------------------------

def build_problem(problem: str, n: int):
    """``bench_policy.build``'s agent of ``problem`` with ``n`` transitions."""
    from bench_policy import build

    if problem == "cartpole":
        return build(problem, cartpole_data=n)
    return build(problem, reacher_data=n)


def measure(problems: Dict[str, Iterable[int]], repeats: int, floor_data: int,
            matmul_size: int, elements: int, count: bool = True) -> Dict[str, object]:
    """Everything one thread setting measures, in this process: the machine's references
    (matrix product, elementwise bandwidth, cost of a tiny operation) and, per problem and
    size, the flop count (unless ``count`` is false: it does not depend on the threads)
    and the timing of one objective + gradient."""
    import tensorflow as tf

    from pilco.moments import pair_groups

    out: Dict[str, object] = {
        "environment": {k: os.environ.get(k) for k in (
            "TF_NUM_INTRAOP_THREADS", "TF_NUM_INTEROP_THREADS", "OPENBLAS_NUM_THREADS",
            "OMP_NUM_THREADS")},
        "load_before": [round(x, 2) for x in os.getloadavg()],
        "matmul_size": matmul_size, "elementwise_elements": elements,
        # a product takes seconds: three after the warm-up
        "matmul_gflops": matmul_rates(matmul_size, min(3, repeats)),
        "elementwise_gbs": elementwise_rates(elements, repeats),
        # its calls take a millisecond: more of them, the slope of two minima is noisy
        "op_seconds": op_overhead(max(20, 4 * repeats)),
        "rows": [],
    }
    for problem, sizes in problems.items():
        # count first (the counting agents are dropped), then trace every size and the
        # small problem of %fix and time them in alternating rounds
        counted = {n: count_evaluation(build_problem(problem, n)) if count else None
                   for n in (floor_data,) + tuple(sizes)}
        calls, infos, dims = {}, {}, {}
        for n in (floor_data,) + tuple(sizes):
            agent = build_problem(problem, n)
            dims[n] = problem_dimensions(agent)
            calls[n], infos[n] = prepare_evaluation(agent)
        seconds = interleaved_seconds(calls, repeats)
        for n in sizes:
            d = dims[n]
            row = {
                "problem": problem, "N": n, **d,
                "pair_groups": len(pair_groups(d["outputs"] * (d["outputs"] + 1) // 2,
                                               d["outputs"])),
                "pair_block_flops": pair_block_flops(d["outputs"], n, d["inputs"],
                                                     d["horizon"]),
                **infos[n],
                "seconds": min(seconds[n]), "median_seconds": float(np.median(seconds[n])),
                "all_seconds": seconds[n],
                "floor_data": floor_data, "floor_seconds": min(seconds[floor_data]),
                "pair_block_seconds": d["horizon"] * pair_block_seconds(
                    d["outputs"], d["inputs"], n, repeats),
            }
            if count:
                row.update(counted_fields(counted[n], counted[floor_data]))
            out["rows"].append(row)
    out["load_after"] = [round(x, 2) for x in os.getloadavg()]
    # the threads as tf.config reports them (0: not configured there; the environment
    # variables above are read by the runtime directly)
    out["tensorflow_threads"] = {
        "intra_op": tf.config.threading.get_intra_op_parallelism_threads(),
        "inter_op": tf.config.threading.get_inter_op_parallelism_threads()}
    return out


def counted_fields(counted: Count, floor: Count) -> Dict[str, object]:
    """The fields of a row that come from :func:`count_evaluation` (``floor``: the
    count of the small problem of %fix)."""
    return {"flops": counted["flops"], "graph_operations": counted["ops"],
            "bytes": counted["bytes"], "floor_flops": floor["flops"],
            "flops_by_type": dict(counted["flops_by_type"].most_common(8)),
            "unknown_shapes": counted["unknown_shapes"],
            "uncounted_types": counted["uncounted_types"]}


#: the fields :func:`counted_fields` makes
COUNTED = ("flops", "graph_operations", "bytes", "floor_flops", "flops_by_type",
           "unknown_shapes", "uncounted_types")


def share_counts(settings: Dict[str, Dict[str, object]]) -> None:
    """Copy the counted fields of the first setting's rows into the rows of the settings
    not counted (``--_no-count``) of the same problem and size: their graph is the same,
    since they keep TensorFlow's default inter-op threads and so the same pair groups
    (the ``sweep`` setting, with one group, is counted in its own process)."""
    first, *others = settings.values()
    by_key = {(r["problem"], r["N"]): r for r in first["rows"]}
    for res in others:
        for r in res["rows"]:
            if "flops" in r:
                continue
            source = by_key[(r["problem"], r["N"])]
            if source["pair_groups"] != r["pair_groups"]:
                raise RuntimeError(f"{r['problem']} N={r['N']}: the settings' graphs differ "
                                   f"({source['pair_groups']} and {r['pair_groups']} pair "
                                   "groups): count each")
            r.update({k: source[k] for k in COUNTED})


# -- both settings, in fresh processes ------------------------------------------------------

#: environment of each thread setting's process (None: removed, TensorFlow's default)
SETTINGS = {
    "1": {"TF_NUM_INTRAOP_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
          "TF_NUM_INTEROP_THREADS": None},
    # exactly what a sweep gives a run on one CPU
    "sweep": thread_environment(1, base={}),
    "default": {"TF_NUM_INTRAOP_THREADS": None, "OPENBLAS_NUM_THREADS": None,
                "OMP_NUM_THREADS": None, "TF_NUM_INTEROP_THREADS": None},
}


def run_setting(setting: str, args, count: bool = True) -> Dict[str, object]:
    """:func:`measure` in a fresh process with ``SETTINGS[setting]``'s environment."""
    env = dict(os.environ)
    for key, value in SETTINGS[setting].items():
        if value is None:
            env.pop(key, None)
        else:
            env[key] = value
    env.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    command = [sys.executable, os.path.abspath(__file__), "--_worker",
               "--repeats", str(args.repeats), "--floor-data", str(args.floor_data),
               "--matmul-size", str(args.matmul_size), "--elements", str(args.elements)]
    command += ["--quick"] if args.quick else []
    command += [] if count else ["--_no-count"]
    command += ["--problem", args.problem]
    done = subprocess.run(command, capture_output=True, text=True, env=env)
    if done.returncode != 0:
        raise RuntimeError(f"the {setting!r} process failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def quadratic_check(rows: List[Dict[str, object]]) -> Optional[Dict[str, float]]:
    """Cross-check of the counter with :func:`pair_block_flops`: the counted flops of one
    problem at three or more sizes, fitted by ``a n^2 + b n + c`` (every count is a
    polynomial of degree 2 in n), against the n^2 coefficient counted by hand. With four
    or more sizes the fit's residual also checks the degree."""
    if len(rows) < 3:
        return None
    n = np.array([r["N"] for r in rows], dtype=float)
    y = np.array([r["flops"] for r in rows], dtype=float)
    coef, *_ = np.linalg.lstsq(np.stack([n ** 2, n, np.ones_like(n)], 1), y, rcond=None)
    r0 = rows[0]
    by_hand = pair_block_flops(r0["outputs"], 1, r0["inputs"], r0["horizon"])
    return {"n2_coefficient_graph": float(coef[0]), "n2_coefficient_by_hand": by_hand,
            "n_coefficient_graph": float(coef[1]), "constant_graph": float(coef[2]),
            "max_relative_residual": float(np.max(np.abs(
                np.stack([n ** 2, n, np.ones_like(n)], 1) @ coef - y) / y))}


def table(results: Dict[str, object]) -> List[Dict[str, object]]:
    """The table's rows (see the module doc) from both settings' measurements."""
    settings = results["settings"]
    peak = {s: max(settings[s]["matmul_gflops"].values()) for s in settings}
    one_core = peak.get("1", peak.get("sweep"))
    rows = []
    for s, res in settings.items():
        bandwidth = max(res["elementwise_gbs"].values()) * 1e9
        for r in res["rows"]:
            rate = r["flops"] / r["seconds"] / 1e9
            rows.append({
                "task": r["problem"], "N": r["N"], "threads": s,
                "mflop": r["flops"] / 1e6, "seconds": r["seconds"], "gflops": rate,
                "peak1_percent": 100 * rate / one_core if one_core else None,
                "peak2_percent": 100 * rate / peak["default"] if "default" in peak else None,
                "ops": r["executed"], "graph_ops": r["graph_operations"],
                "overhead_percent": 100 * r["executed"] * res["op_seconds"] / r["seconds"],
                "fixed_percent": 100 * r["floor_seconds"] / r["seconds"],
                "memory_percent": 100 * r["bytes"] / bandwidth / r["seconds"],
                "pair_block_percent": 100 * r["pair_block_flops"] / r["flops"],
                "block_time_percent": 100 * r["pair_block_seconds"] / r["seconds"],
                "block_gflops": r["pair_block_flops"] / r["pair_block_seconds"] / 1e9,
            })
    return rows


def _fmt(x, spec):
    return "-" if x is None else format(x, spec)


def print_report(results: Dict[str, object]) -> None:
    settings = results["settings"]
    print(f"load average before {results['load_before']}, after {results['load_after']}")
    for s, res in settings.items():
        mm, ew = res["matmul_gflops"], res["elementwise_gbs"]
        print(f"threads {s} (load average {res['load_before']} -> {res['load_after']}): "
              f"{res['matmul_size']}^2 matmul TensorFlow {mm['tensorflow']:.2f}, "
              f"numpy {mm['numpy']:.2f} GFLOP/s; a*b+c on {res['elementwise_elements']} "
              f"doubles TensorFlow {ew['tensorflow']:.1f}, numpy {ew['numpy']:.1f} GB/s; "
              f"tiny op {res['op_seconds'] * 1e6:.2f} us")
    header = (f"{'task':<9} {'N':>4} {'threads':>7} {'MFLOP':>8} {'s':>8} {'GFLOP/s':>8} "
              f"{'%peak1':>7} {'%peak2':>7} {'ops':>7} {'%ovh':>5} {'%fix':>5} {'%mem':>5} "
              f"{'%n2':>4} {'%blk':>5} {'blk GF/s':>8}")
    print(header)
    print("-" * len(header))
    for r in results["table"]:
        print(f"{r['task']:<9} {r['N']:>4} {r['threads']:>7} {r['mflop']:>8.1f} "
              f"{r['seconds']:>8.4f} {r['gflops']:>8.3f} {_fmt(r['peak1_percent'], '7.1f')} "
              f"{_fmt(r['peak2_percent'], '7.1f')} {r['ops']:>7} "
              f"{r['overhead_percent']:>5.0f} {r['fixed_percent']:>5.0f} "
              f"{r['memory_percent']:>5.0f} {r['pair_block_percent']:>4.0f} "
              f"{r['block_time_percent']:>5.0f} {r['block_gflops']:>8.2f}")
    for problem, check in results["cross_check"].items():
        if check:
            print(f"{problem}: n^2 flops per evaluation {check['n2_coefficient_graph']:.1f} "
                  f"(graph) vs {check['n2_coefficient_by_hand']} (pair block by hand), fit "
                  f"residual {check['max_relative_residual']:.1e}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--problem", choices=["reacher", "cartpole", "all"], default="all")
    parser.add_argument("--quick", action="store_true", help="one size per problem")
    parser.add_argument("--repeats", type=int, default=5,
                        help="timed calls after the warm-up; the fastest counts")
    parser.add_argument("--floor-data", type=int, default=5,
                        help="transitions of the small problem of the %%fix column")
    parser.add_argument("--matmul-size", type=int, default=2000)
    parser.add_argument("--elements", type=int, default=2 ** 23,
                        help="float64 entries per array of the elementwise reference")
    parser.add_argument("--threads", choices=["1", "sweep", "default", "both", "all"],
                        default="both", help="both: 1 and default; all: the three")
    parser.add_argument("--json", default=None, help="write the results to this file")
    parser.add_argument("--_worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--_no-count", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    sizes = QUICK_SIZES if args.quick else SIZES
    problems = {p: s for p, s in sizes.items() if args.problem in ("all", p)}

    if args._worker:
        print(json.dumps(measure(problems, args.repeats, args.floor_data, args.matmul_size,
                                 args.elements, count=not args._no_count)))
        return 0

    results: Dict[str, object] = {
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                    "processor": platform.processor(), "python": platform.python_version()},
        "load_before": [round(x, 2) for x in os.getloadavg()], "settings": {}}
    chosen = {"both": ["1", "default"], "all": ["1", "sweep", "default"]}.get(
        args.threads, [args.threads])
    for i, setting in enumerate(chosen):
        # the sweep setting's graph has one group of output pairs: counted on its own
        results["settings"][setting] = run_setting(setting, args,
                                                   count=i == 0 or setting == "sweep")
    results["load_after"] = [round(x, 2) for x in os.getloadavg()]
    share_counts(results["settings"])
    first = next(iter(results["settings"].values()))
    results["cross_check"] = {p: quadratic_check([r for r in first["rows"] if r["problem"] == p])
                              for p in problems}
    results["table"] = table(results)
    print_report(results)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
