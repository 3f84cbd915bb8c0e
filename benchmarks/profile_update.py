"""Where one SAC update's time goes: a profiler trace of the update alone, summed per XLA op.

    python benchmarks/profile_update.py              # B 256, 2x256, HalfCheetah's shapes
    python benchmarks/profile_update.py --seeds 8    # the update vmapped over 8 agents
    python benchmarks/profile_update.py --top 40     # and the 40 costliest ops

It times `bench.update_scan` (the benchmark's update-alone program, on a fixed batch), then traces
one call with `jax.profiler` and XLA:CPU's per-op trace events (`--xla_cpu_enable_xprof_traceme`),
and adds up each op's duration, naming ops through the compiled HLO's `op_name` metadata. Ops run on
the CPU's threads side by side, so the busy time of all threads is printed against the wall time
(`threads busy / wall` near the core count means the cores are never idle). Categories:

* matmul: the dots (YNNPACK fusions and plain dots);
* networks and losses: the element-wise work of the forward and backward passes (bias + ReLU, the
  ReLU masks, the Gaussian policy's squashing and log-probabilities, the loss reductions);
* optimizer and targets: Adam and the Polyak update (element-wise over every parameter);
* other: everything else (random numbers, loop bookkeeping).

A timing, so run it on a quiet machine and read the shares, not the microseconds (benchmarks/README.md).
"""

from __future__ import annotations

import argparse
import collections
import gzip
import json
import os
import re
import sys
import tempfile
import time
from pathlib import Path

os.environ["XLA_FLAGS"] = (
    os.environ.get("XLA_FLAGS", "") + " --xla_cpu_enable_xprof_traceme=true"
).strip()
sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench  # noqa: E402
import jax  # noqa: E402

from arld_jax.config import Config  # noqa: E402

NETWORK_SCOPES = ("Actor", "Critic", "softplus", "_normal", "tanh", "log", "exp", "reduce_sum")
OPTIMIZER_OPS = ("add", "sub", "mul", "div", "sqrt", "pow", "integer_pow", "select_n")


def op_names(hlo_text: str) -> dict[str, str]:
    """Instruction name -> its `op_name` metadata (the jax source scope), from compiled HLO text."""
    names = {}
    for line in hlo_text.splitlines():
        m = re.match(r"\s*(?:ROOT )?%?([\w.\-]+) = .*op_name=\"([^\"]+)\"", line)
        if m:
            names[m.group(1)] = m.group(2)
    return names


def category(op: str, scope: str) -> str:
    """The category of trace op `op` with HLO scope `scope` (module docstring)."""
    if op.startswith(("ynn", "dot")):
        return "matmul"
    inner = scope.split("closed_call/", 1)[-1]
    if any(s in inner for s in NETWORK_SCOPES):
        return "networks and losses"
    if "/" not in inner and inner in OPTIMIZER_OPS:  # top-level arithmetic of adam_step / polyak
        return "optimizer and targets"
    return "other"


def trace_ops(run: object, args: tuple, trace_dir: str) -> list[dict]:
    """Complete ('X') events of one traced call of `run(*args)`."""
    with jax.profiler.trace(trace_dir, create_perfetto_trace=True):
        jax.block_until_ready(run(*args))
    path = next(Path(trace_dir).rglob("perfetto_trace.json.gz"))
    events = json.load(gzip.open(path))
    events = events["traceEvents"] if isinstance(events, dict) else events
    return [e for e in events if e.get("ph") == "X" and "dur" in e]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=1, help="agents vmapped (1: no vmap)")
    parser.add_argument("--updates", type=int, default=200, help="scanned updates per call")
    parser.add_argument("--top", type=int, default=0, help="also list the N costliest ops")
    args = parser.parse_args()
    if args.seeds < 1 or args.updates < 1:
        parser.error(f"--seeds and --updates must be >= 1 (got {args.seeds}, {args.updates})")

    cfg = Config(hidden_sizes=bench.PAPER_HIDDEN, batch_size=bench.PAPER_BATCH, **bench.PLAIN_SAC)
    agent, state, batch, weights, hp = bench.agent_and_inputs(
        cfg, bench.HC_OBS_DIM, bench.HC_ACTION_DIM
    )
    key = jax.random.key(3)
    if args.seeds > 1:
        stack = lambda x: jax.numpy.broadcast_to(x, (args.seeds, *x.shape))
        state, batch, weights, hp = jax.tree.map(stack, (state, batch, weights, hp))
        key = jax.random.split(key, args.seeds)
    call_args = (state, batch, weights, hp, key)
    run = bench.update_scan(agent, args.updates, args.seeds if args.seeds > 1 else 0)
    compiled = run.lower(*call_args).compile()
    jax.block_until_ready(compiled(*call_args))
    walls = []
    for _ in range(3):
        start = time.perf_counter()
        jax.block_until_ready(compiled(*call_args))
        walls.append(time.perf_counter() - start)
    wall_us = min(walls) / args.updates * 1e6

    with tempfile.TemporaryDirectory() as trace_dir:
        events = trace_ops(compiled, call_args, trace_dir)
    scopes = op_names(compiled.as_text())
    skip = ("ThunkExecutor", "$", "Slinky", "PjitFunction")
    per_op: collections.Counter[str] = collections.Counter()
    for e in events:
        if not e["name"].startswith(skip):
            per_op[e["name"]] += e["dur"] / args.updates
    per_cat: collections.Counter[str] = collections.Counter()
    for op, us in per_op.items():
        per_cat[category(op, scopes.get(op, ""))] += us
    busy = sum(per_cat.values())

    print(f"one update, {args.seeds} agent(s) vmapped, B {cfg.batch_size}, {cfg.hidden_sizes}")
    print(f"wall (untraced, best of 3): {wall_us:8.1f} us per update call")
    print(f"threads busy (traced):      {busy:8.1f} us  ({busy / wall_us:.2f} x wall)")
    for name in ("matmul", "networks and losses", "optimizer and targets", "other"):
        us = per_cat[name]
        print(f"  {name:24s} {us:8.1f} us  {us / busy:6.1%} of busy time")
    for op, us in per_op.most_common(args.top):
        scope = scopes.get(op, "")
        print(f"  {us:7.1f} us  {category(op, scope):22s} {op[:34]:34s} {scope[-70:]}")


if __name__ == "__main__":
    main()
