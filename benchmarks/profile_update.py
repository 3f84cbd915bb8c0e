"""Where the time of one SAC update, or of the trainer's loop, goes: a profiler trace summed per op.

    python -m benchmarks.profile_update                      # the update alone, B 256, 2x256
    python -m benchmarks.profile_update --seeds 8            # the update vmapped over 8 agents
    python -m benchmarks.profile_update --trainer 1          # the trainer, 1 env, C physics
    python -m benchmarks.profile_update --trainer 16 --backend mjx --top 40

The update alone is the benchmark's program (`programs.update_call`, on a fixed batch, HalfCheetah's
shapes); the trainer is `programs.trainer_config` at the paper's sizes (1 update per env step,
periods of 2,000 env steps, one evaluation episode), compiled as the driver does
(`programs.compile_trainer`). The script times untraced calls, then traces one call with
`jax.profiler` and XLA:CPU's per-op events (`--xla_cpu_enable_xprof_traceme`), names each op through
the compiled HLO's `op_name` metadata (its jax scope) and sums the ops' durations per category. Ops
run side by side on the CPU's threads, so each category is printed as a share of the threads'
capacity over the traced span (span x threads that ran at least 5% of the ops' time), and what no op
used is "idle": a thread waiting on a dependency or on the runtime's dispatch between ops (or
running work that has no trace event). Perfetto's export keeps the first 1,000,000 events (about 650
trainer iterations at 1 env); the span is that of the events kept, so the shares hold for the part
traced (the trainer's evaluation, at the end of a period, is then not in it; the benchmark's
`trainer` section times it alone).

Categories: the update's matmuls (YNNPACK fusions and dots), its networks' and losses' element-wise
work (bias + ReLU, ReLU masks, the policy's squashing and log-probabilities, loss reductions), its
optimizer and targets (Adam and Polyak, element-wise over every parameter); in the trainer also the
env step (`env_step`: with C physics a host callback), the replay (`replay_*`: add, sample,
priorities), evaluation, and acting and bookkeeping (the rest of the loop).

A timing, so run it on a quiet machine and read the shares, not the microseconds (benchmarks/README.md).
"""

from __future__ import annotations

import argparse
import bisect
import collections
import dataclasses
import gzip
import json
import os
import re
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

os.environ["XLA_FLAGS"] = (
    os.environ.get("XLA_FLAGS", "") + " --xla_cpu_enable_xprof_traceme=true"
).strip()

import jax  # noqa: E402  (after XLA_FLAGS: jax reads them when its backend starts)
import jax.numpy as jnp  # noqa: E402

from arld_jax.train import make_train  # noqa: E402
from benchmarks.programs import (  # noqa: E402
    FULL,
    HC_ACTION_DIM,
    HC_OBS_DIM,
    PAPER_UPDATE,
    compile_trainer,
    trainer_config,
    update_call,
)

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
    """The category of trace op `op` whose HLO scope is `scope` (module docstring)."""
    if "/evaluate/" in scope:
        return "evaluation"
    if "env_step" in scope:
        return "env step"
    if "/replay_" in scope:
        return "replay"
    if "gradient_steps" in scope or scope.startswith("jit(run)/"):  # the update (alone: jit(run))
        if op.startswith(("ynn", "dot")):
            return "update: matmul"
        inner = scope.split("closed_call/")[-1]
        if any(s in inner for s in NETWORK_SCOPES):
            return "update: networks and losses"
        if "jvp" not in inner and inner.split("/")[-1] in OPTIMIZER_OPS:  # outside the gradients
            return "update: optimizer and targets"
        return "update: other"
    return "acting and bookkeeping"


def trace_ops(call: Callable[[], object], trace_dir: str) -> list[dict]:
    """Complete ('X') events of one traced `call()`."""
    with jax.profiler.trace(trace_dir, create_perfetto_trace=True):
        jax.block_until_ready(call())
    path = next(Path(trace_dir).rglob("perfetto_trace.json.gz"))
    events = json.load(gzip.open(path))
    events = events["traceEvents"] if isinstance(events, dict) else events
    return [e for e in events if e.get("ph") == "X" and "dur" in e]


def alone_or_beside(ops: list[dict]) -> list[str]:
    """For each op: 'alone' when other threads' ops cover < 20% of its time, 'beside' when they
    cover > 80%, else ''. A library may run an op's work on other threads without trace events,
    so an op that gets the second core when alone runs faster alone than beside another op."""
    order = sorted(range(len(ops)), key=lambda i: ops[i]["ts"])
    starts = [ops[i]["ts"] for i in order]
    longest = max(e["dur"] for e in ops)
    labels = [""] * len(ops)
    for i in order:
        e = ops[i]
        lo, hi = e["ts"], e["ts"] + e["dur"]
        covered = 0.0
        for j in order[bisect.bisect_left(starts, lo - longest) : bisect.bisect_right(starts, hi)]:
            o = ops[j]
            if o["tid"] != e["tid"]:
                covered += max(0.0, min(hi, o["ts"] + o["dur"]) - max(lo, o["ts"]))
        share = covered / max(e["dur"], 1e-9)
        labels[i] = "alone" if share < 0.2 else "beside" if share > 0.8 else ""
    return labels


def ops_running(ops: list[dict]) -> list[float]:
    """Share of the ops' span during which exactly 0, 1, 2, ... ops run at once (any threads)."""
    edges = sorted((t, step) for e in ops for t, step in ((e["ts"], 1), (e["ts"] + e["dur"], -1)))
    time_at: collections.Counter[int] = collections.Counter()
    running, last = 0, edges[0][0]
    for t, step in edges:
        time_at[running] += t - last
        running, last = running + step, t
    total = sum(time_at.values())
    return [time_at[n] / total for n in range(max(time_at) + 1)]


def update_program(seeds: int, updates: int) -> tuple[Any, Callable[[], object], int]:
    """The update alone over `seeds` agents (1: not vmapped): compiled program, one call of it
    on fixed inputs, and the updates a call makes."""
    call, compiled = update_call(PAPER_UPDATE, HC_OBS_DIM, HC_ACTION_DIM, updates, seeds)
    return compiled, call, updates * seeds


def trainer_program(num_envs: int, backend: str) -> tuple[Any, Callable[[], object], int]:
    """The 1-seed trainer after its warm-up period: compiled chunk, one call of it (a period; the
    state is donated, so each call continues from the last) and the updates a call makes."""
    sizes = dataclasses.replace(FULL, period_env_steps=2000 if num_envs == 1 else 4000)
    cfg = trainer_config(sizes, False, num_envs).replace(backend=backend)
    compiled, state, hps, _ = compile_trainer(make_train(cfg), 1)
    holder = {"state": compiled(state, hps, jnp.int32(0))[0]}  # the warm-up period

    def call() -> object:
        holder["state"], metrics = compiled(holder["state"], hps, jnp.int32(1))
        return metrics

    return compiled, call, cfg.iters_per_eval * cfg.updates_per_iter


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=1, help="agents vmapped (1: no vmap)")
    parser.add_argument("--updates", type=int, default=200, help="scanned updates per call")
    parser.add_argument(
        "--trainer",
        type=int,
        default=0,
        metavar="ENVS",
        help="profile the trainer at ENVS envs instead of the update alone",
    )
    parser.add_argument(
        "--backend",
        default="mujoco",
        choices=("mujoco", "mjx"),
        help="the trainer's physics (default: MuJoCo's C engine)",
    )
    parser.add_argument("--top", type=int, default=0, help="also list the N costliest ops")
    args = parser.parse_args()
    if args.seeds < 1 or args.updates < 1 or args.trainer < 0:
        parser.error(
            f"--seeds and --updates must be >= 1 and --trainer >= 0 "
            f"(got {args.seeds}, {args.updates}, {args.trainer})"
        )

    if args.trainer:
        what = f"the trainer, {args.trainer} env(s), {args.backend} physics, one period"
        compiled, call, updates = trainer_program(args.trainer, args.backend)
    else:
        what = f"the update alone, {args.seeds} agent(s), {args.updates} scanned updates"
        compiled, call, updates = update_program(args.seeds, args.updates)
    jax.block_until_ready(call())
    walls = []
    for _ in range(1 if args.trainer else 3):
        start = time.perf_counter()
        jax.block_until_ready(call())
        walls.append(time.perf_counter() - start)

    with tempfile.TemporaryDirectory() as trace_dir:
        events = trace_ops(call, trace_dir)
    scopes = op_names(compiled.as_text())
    # Loop ops (`while`) are left out: their events can span their bodies' ops.
    ops = [e for e in events if e["name"] in scopes and not e["name"].startswith("while")]
    span_us = max(e["ts"] + e["dur"] for e in ops) - min(e["ts"] for e in ops)
    per_thread: collections.Counter[int] = collections.Counter()
    for e in ops:
        per_thread[e["tid"]] += e["dur"]
    # The threads doing the work (the runtime's main thread runs a few tiny ops too).
    threads = sum(us > 0.05 * sum(per_thread.values()) for us in per_thread.values())
    per_op: collections.Counter[str] = collections.Counter()
    for e in ops:
        per_op[e["name"]] += e["dur"]
    per_cat: collections.Counter[str] = collections.Counter()
    for op, us in per_op.items():
        per_cat[category(op, scopes[op])] += us
    capacity = span_us * threads

    print(what)
    print(f"untraced: {min(walls):.3f} s per call, {updates / min(walls):,.1f} updates/s")
    print(f"traced span {span_us / 1e6:.3f} s on {threads} threads; share of their capacity:")
    for name, us in per_cat.most_common():
        print(f"  {name:32s} {us / capacity:6.1%}")
    print(f"  {'idle':32s} {1 - sum(per_cat.values()) / capacity:6.1%}")
    running = ops_running(ops)
    print(
        "share of the span with 0, 1, 2, ... ops running at once: "
        + ", ".join(f"{n}: {share:.1%}" for n, share in enumerate(running))
    )
    durations: dict[str, dict[str, list[float]]] = collections.defaultdict(
        lambda: collections.defaultdict(list)
    )
    for e, label in zip(ops, alone_or_beside(ops), strict=True):
        if label and category(e["name"], scopes[e["name"]]) == "update: matmul":
            durations[e["name"]][label].append(e["dur"])
    heavy = [op for op, _ in per_op.most_common() if op in durations][:12]
    rows = [
        f"{op} {statistics.median(durations[op]['alone']):.0f} / "
        f"{statistics.median(durations[op]['beside']):.0f}"
        for op in heavy
        if durations[op]["alone"] and durations[op]["beside"]
    ]
    print("costliest matmuls, median us alone / with another op beside: " + "; ".join(rows))
    for op, us in per_op.most_common(args.top):
        scope = scopes[op]
        print(f"  {us / capacity:6.2%}  {category(op, scope):30s} {op[:28]:28s} {scope[-60:]}")


if __name__ == "__main__":
    main()
