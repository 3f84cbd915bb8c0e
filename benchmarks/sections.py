"""The benchmark's sections but `peers`, each a function of the run's `Bench` returning its report.

benchmarks/README.md says what each figure means. Measurements that several sections use (the
matmul ceiling, env-only and update-only rates, the trainer's timed periods) are memoized on the
`Bench`, so each runs once per benchmark run.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp

from arld_jax.compile import compiler_options
from arld_jax.config import Config, hparams_from_config
from arld_jax.envs import make_env
from arld_jax.replay import make_prioritized_replay, replay_nbytes
from arld_jax.train import Trainer, make_train
from arld_jax.types import example_transition
from benchmarks import flops
from benchmarks.harness import (
    REPO_ROOT,
    Bench,
    block,
    log,
    mem_total_bytes,
    print_table,
    summarize,
    time_calls,
)
from benchmarks.programs import (
    FULL,
    HC_ACTION_DIM,
    HC_OBS_DIM,
    PAPER_BATCH,
    PAPER_HIDDEN,
    PAPER_UPDATE,
    PLAIN_SAC,
    QUICK,
    Sizes,
    agent_and_inputs,
    compile_trainer,
    env_config,
    env_rollout,
    matmul_call,
    replay_scan,
    time_periods,
    trainer_config,
    update_call,
)

CHILD_MARKER = "FIRST_STEP_RESULT "


def measure_matmul(sizes: Sizes, ensembles: int, dtype: jnp.dtype, width: int = 256) -> dict:
    """GFLOP/s of the chain (2 * width^3 FLOPs per matmul per ensemble member)."""
    call, flop = matmul_call(sizes.matmul_steps, ensembles, dtype, width)
    times = time_calls(call, sizes.repeats)
    return summarize(times) | {
        "flops_per_call": flop,
        "gflops_median": flop / statistics.median(times) / 1e9,
        "gflops_best": flop / min(times) / 1e9,
    }


def section_matmul(b: Bench) -> dict:
    """f32 and bf16-input (f32 accumulation) matmul throughput, single and 8-ensemble batched."""
    out = {}
    for dtype_name, dtype in (("float32", jnp.float32), ("bfloat16", jnp.bfloat16)):
        for ensembles in (1, 8):
            out[f"{dtype_name}_e{ensembles}"] = measure_matmul(b.sizes, ensembles, dtype)
    out["note"] = (
        f"lax.scan of {b.sizes.matmul_steps} x <- tanh(x @ w), [E,256,256] @ [E,256,256], jitted, "
        "timed after a warm-up call; gflops_best is the physical ceiling used elsewhere"
    )
    rows = [
        [k.replace("_e", " x"), v["gflops_median"], v["gflops_best"], v["median_s"] * 1e3]
        for k, v in out.items()
        if isinstance(v, dict)
    ]
    print_table(
        "matmul throughput, 256-wide (dtype x ensembles)",
        ["shape", "GFLOP/s median", "GFLOP/s best", "ms/call"],
        rows,
    )
    return out


def matmul_gflops(b: Bench, dtype_name: str = "float32") -> float:
    """Best 256-wide GFLOP/s of `dtype_name` (single and 8-ensemble, the larger), measured once."""
    if "matmul" not in b.report["sections"]:
        log("(measuring matmul throughput first: the physical limit needs it)")
        b.run_section("matmul")
    m = b.report["sections"]["matmul"]
    return max(m[f"{dtype_name}_e1"]["gflops_best"], m[f"{dtype_name}_e8"]["gflops_best"])


def measured_limit(
    b: Bench, cfg: Config, obs_dim: int, action_dim: int, gflops: float | None = None
) -> float:
    """`flops.limit_updates_per_s` of `cfg` at `gflops` when given, else at the matmul section's
    best rate for `cfg`'s matmul dtype (`matmul_gflops`)."""
    dtype_name = "bfloat16" if cfg.matmul_dtype == "bfloat16" else "float32"
    return flops.limit_updates_per_s(
        cfg, obs_dim, action_dim, gflops or matmul_gflops(b, dtype_name)
    )


def section_flops(b: Bench) -> dict:
    """FLOPs of one SAC update at B=256, 2x256 (obs 17, action 6), and the updates/s it allows."""
    cfg = PAPER_UPDATE
    agent, state, batch, weights, hp = agent_and_inputs(cfg, HC_OBS_DIM, HC_ACTION_DIM)
    indices = jnp.arange(weights.shape[0])
    lowered = jax.jit(agent.update).lower(state, batch, weights, indices, hp, jax.random.key(1))
    from_xla = flops.xla_flops(lowered.compile())
    analytic = flops.analytic_update_flops(HC_OBS_DIM, HC_ACTION_DIM, PAPER_HIDDEN, PAPER_BATCH)
    f32, bf16 = matmul_gflops(b, "float32"), matmul_gflops(b, "bfloat16")
    out = {
        "obs_dim": HC_OBS_DIM,
        "action_dim": HC_ACTION_DIM,
        "hidden_sizes": list(PAPER_HIDDEN),
        "batch_size": PAPER_BATCH,
        "xla_cost_analysis_flops": from_xla,
        "analytic_matmul_flops": analytic,
        "matmul_gflops_f32_best": f32,
        "matmul_gflops_bf16_best": bf16,
        "limit_updates_per_s_f32": flops.limit_updates_per_s(cfg, HC_OBS_DIM, HC_ACTION_DIM, f32),
        "limit_updates_per_s_bf16": flops.limit_updates_per_s(cfg, HC_OBS_DIM, HC_ACTION_DIM, bf16),
        "limit_updates_per_s_f32_xla_flops": f32 * 1e9 / from_xla if from_xla else float("nan"),
        "note": "limit = best 256-wide matmul FLOP/s / analytic matmul FLOPs of one update",
    }
    print_table(
        "one SAC update, B=256, 2x256, obs 17, action 6",
        ["quantity", "value"],
        [
            ["XLA cost analysis, GFLOP/update", from_xla / 1e9],
            ["analytic matmul count, GFLOP/update", analytic["total"] / 1e9],
            ["  of which critic loss + grad", analytic["critic_loss_and_grad"] / 1e9],
            ["  of which actor loss + grad", analytic["actor_loss_and_grad"] / 1e9],
            ["physical limit f32, updates/s", out["limit_updates_per_s_f32"]],
            ["physical limit bf16, updates/s", out["limit_updates_per_s_bf16"]],
        ],
    )
    return out


def env_steps_per_s(b: Bench, env_name: str, num_envs: int, backend: str = "mjx") -> dict:
    """Env-only env steps/s of `env_name` (physics `backend`) with `num_envs` envs (memoized)."""
    memo_key = ("env", env_name, num_envs, backend)
    if memo_key not in b.memo:
        start = time.perf_counter()
        env = make_env(env_config(env_name, num_envs, backend))
        make_env_s = time.perf_counter() - start
        rollout = env_rollout(env, num_envs, b.sizes.env_steps)
        start = time.perf_counter()
        block(rollout(jax.random.key(1)))  # compile + first call
        first_call_s = time.perf_counter() - start
        times = time_calls(lambda: rollout(jax.random.key(2)), b.sizes.repeats)
        steps = num_envs * b.sizes.env_steps
        b.memo[memo_key] = summarize(times) | {
            "env": env_name if env_name == "toy" else f"{env_name} ({backend})",
            "num_envs": num_envs,
            "steps_per_call": steps,
            "make_env_s": make_env_s,
            "compile_and_first_call_s": first_call_s,
            "note": "each call = one reset (in the same program) + the scanned steps",
            "env_steps_per_s": steps / statistics.median(times),
        }
    return b.memo[memo_key]


def section_env(b: Bench) -> dict:
    """Env-only throughput (random actions, no agent, no replay)."""
    env_name = "toy" if b.args.skip_mjx else "halfcheetah"
    results = {f"{env_name}_{n}": env_steps_per_s(b, env_name, n) for n in b.sizes.env_counts}
    if env_name == "halfcheetah":  # the same env stepped by MuJoCo's C engine (Config.backend)
        for n in b.sizes.env_counts:
            results[f"halfcheetah-mujoco_{n}"] = env_steps_per_s(b, env_name, n, "mujoco")
    print_table(
        f"env only, random actions, {b.sizes.env_steps} scanned steps per call",
        ["env", "envs", "env steps/s", "ms/call", "compile+1st call s"],
        [
            [
                r["env"],
                r["num_envs"],
                r["env_steps_per_s"],
                r["median_s"] * 1e3,
                r["compile_and_first_call_s"],
            ]
            for r in results.values()
        ],
    )
    return results


def update_memo_key(cfg: Config, obs_dim: int, action_dim: int, num_seeds: int) -> tuple:
    """What makes one update-only program: the shapes, dtype, noise draws and seeds."""
    return (
        obs_dim, action_dim, cfg.hidden_sizes, cfg.batch_size, cfg.matmul_dtype, cfg.noisy_runs,
        num_seeds,
    )  # fmt: skip


def bench_update_call(
    b: Bench, cfg: Config, obs_dim: int, action_dim: int, num_seeds: int = 1
) -> Callable[[], Any]:
    """`update_call` of `b.sizes.updates` updates, compiled once per benchmark run."""
    memo_key = ("update_call", *update_memo_key(cfg, obs_dim, action_dim, num_seeds))
    if memo_key not in b.memo:
        b.memo[memo_key] = update_call(cfg, obs_dim, action_dim, b.sizes.updates, num_seeds)[0]
    return b.memo[memo_key]


def updates_per_s(b: Bench, cfg: Config, obs_dim: int, action_dim: int, num_seeds: int = 1) -> dict:
    """Update-only updates/s (all seeds together) of `cfg`'s agent over `num_seeds` vmapped agents
    (`update_call`). Memoized on the shapes, dtype and seeds."""
    memo_key = ("update", *update_memo_key(cfg, obs_dim, action_dim, num_seeds))
    if memo_key not in b.memo:
        call = bench_update_call(b, cfg, obs_dim, action_dim, num_seeds)
        times = time_calls(call, b.sizes.repeats)
        b.memo[memo_key] = summarize(times) | {
            "matmul_dtype": cfg.matmul_dtype,
            "num_seeds": num_seeds,
            "updates_per_call": b.sizes.updates * num_seeds,
            "updates_per_s": b.sizes.updates * num_seeds / statistics.median(times),
        }
    return b.memo[memo_key]


def section_update(b: Bench) -> dict:
    """Update-only rate at B=256, 2x256, obs 17, action 6: the compute ceiling of the real code."""
    out = {}
    variants = {  # name -> (matmul dtype, Config.noisy_runs)
        "float32": ("float32", False),
        "bfloat16": ("bfloat16", False),
        "float32, noise draws (Noisy SAC program)": ("float32", True),
    }
    for name, (dtype_name, noisy_runs) in variants.items():
        cfg = PAPER_UPDATE.replace(matmul_dtype=dtype_name, noisy_runs=noisy_runs)
        r = updates_per_s(b, cfg, HC_OBS_DIM, HC_ACTION_DIM)
        limit = measured_limit(b, cfg, HC_OBS_DIM, HC_ACTION_DIM)
        out[name] = r | {
            "limit_updates_per_s": limit,
            "fraction_of_limit": r["updates_per_s"] / limit,
        }
    out["float32"] |= interleaved_fraction(b)
    print_table(
        f"update only, B=256, 2x256, {b.sizes.updates} scanned updates on a fixed batch "
        "(interleaved: the median of per-round fractions, matmul chains and update calls alternated)",
        [
            "matmul inputs",
            "updates/s",
            "ms/update",
            "limit updates/s",
            "fraction of limit",
            "interleaved",
        ],
        [
            [
                k,
                v["updates_per_s"],
                1e3 / v["updates_per_s"],
                v["limit_updates_per_s"],
                v["fraction_of_limit"],
                v.get("fraction_of_limit_interleaved", ""),
            ]
            for k, v in out.items()
        ],
    )
    return out


def interleaved_fraction(b: Bench) -> dict:
    """The f32 update's fraction of the limit with its limit measured beside it.

    This VM's speed drifts within minutes, so an update rate divided by a matmul rate taken in
    another section mixes two speeds. Here each round times the 1- and 8-ensemble f32 matmul
    chains and then one update call, and divides that round's update rate by that round's limit
    (the better chain's GFLOP/s, as `matmul_gflops`, over the analytic FLOPs); the median over
    rounds is reported, with every round's fraction."""
    chains = [matmul_call(b.sizes.matmul_steps, e, jnp.float32) for e in (1, 8)]
    update = bench_update_call(b, PAPER_UPDATE, HC_OBS_DIM, HC_ACTION_DIM)
    fractions = []
    for _ in range(2 * b.sizes.repeats):
        gflops = max(flop / 1e9 / min(time_calls(call, 1)) for call, flop in chains)
        updates_per_s = b.sizes.updates / time_calls(update, 1)[0]
        limit = measured_limit(b, PAPER_UPDATE, HC_OBS_DIM, HC_ACTION_DIM, gflops)
        fractions.append(updates_per_s / limit)
    return {
        "fraction_of_limit_interleaved": statistics.median(fractions),
        "fractions_interleaved": fractions,
    }


def trainer_and_run(
    b: Bench, num_envs: int, num_seeds: int, update_before_add: bool = False
) -> tuple[Trainer, dict]:
    """The trainer of the section's config and its timed periods (memoized: seeds reuses
    trainer's 1 x 1). One seed times `timed_periods` periods; more seeds (N times the work) time
    one."""
    memo_key = ("trainer", num_envs, num_seeds) + (
        ("update_before_add",) if update_before_add else ()
    )
    if memo_key not in b.memo:
        cfg = trainer_config(b.sizes, b.toy_trainer, num_envs, update_before_add)
        trainer = make_train(cfg)
        max_timed = b.sizes.timed_periods if num_seeds == 1 else 1
        b.memo[memo_key] = (trainer, time_periods(trainer, num_seeds, max_timed))
    return b.memo[memo_key]


def trainer_run(b: Bench, num_envs: int, num_seeds: int, update_before_add: bool = False) -> dict:
    """Timed trainer periods of the section's config (`trainer_and_run`)."""
    return trainer_and_run(b, num_envs, num_seeds, update_before_add)[1]


def replay_seconds_per_iteration(
    b: Bench, cfg: Config, obs_dim: int, action_dim: int, num_seeds: int = 0, iters: int = 200
) -> float:
    """Replay-only seconds of one trainer iteration at `cfg`'s capacity, batch and env count
    (all seeds together; `num_seeds` > 0: that many seed-vmapped buffers, see `replay_scan`)."""
    per = make_prioritized_replay(cfg.replay_capacity, cfg.batch_size, cfg.per_alpha)
    iters = max(1, min(cfg.iters_per_eval, iters))
    run, example = replay_scan(per, cfg, obs_dim, action_dim, iters, num_seeds)
    if num_seeds:
        holder = {"r": jax.vmap(lambda _: per.init(example))(jnp.arange(num_seeds))}
    else:
        holder = {"r": per.init(example)}

    def call() -> Any:
        holder["r"], w = run(holder["r"], jax.random.key(4))
        return w

    return statistics.median(time_calls(call, b.sizes.repeats)) / iters


def evaluate_seconds(b: Bench, trainer: Trainer, agent_state: Any) -> float:
    """Seconds of one `trainer.evaluate` (jitted alone, not vmapped, after a warm-up call)."""
    evaluate = jax.jit(trainer.evaluate, compiler_options=compiler_options())
    return statistics.median(
        time_calls(lambda: evaluate(agent_state, jax.random.key(5)), b.sizes.repeats)
    )


def period_breakdown(b: Bench, trainer: Trainer, timing: dict) -> dict:
    """Split one timed period into evaluation, env, updates, replay and the rest.

    Each share is measured ALONE (evaluate jitted by itself; env-only, update-only and replay-only
    scans at the same sizes) and scaled to one period; 'other' is the remainder (acting, query
    bookkeeping, state samples, scan overhead) and can come out negative when the parts overlap."""
    cfg = trainer.cfg
    obs_dim, action_dim = trainer.obs_dim, trainer.action_dim
    iters = cfg.iters_per_eval
    parts = {
        "evaluation": evaluate_seconds(b, trainer, timing["_agent_state"]),
        "env": cfg.eval_every / env_steps_per_s(b, cfg.env_name, cfg.num_envs)["env_steps_per_s"],
        "updates": iters
        * cfg.updates_per_iter
        / updates_per_s(b, cfg, obs_dim, action_dim)["updates_per_s"],
        "replay": iters * replay_seconds_per_iteration(b, cfg, obs_dim, action_dim),
    }
    period_s = timing["median_s"]
    parts["other"] = period_s - sum(parts.values())
    return {
        "seconds": parts,
        "share": {k: v / period_s for k, v in parts.items()},
        "method": "each part timed alone at the same sizes and scaled to one period; other = rest",
    }


def section_trainer(b: Bench) -> dict:
    """The full trainer at 1 env (paper) and 16 envs, 1 update per env step, one period timed."""
    out = {}
    for num_envs in (1, 16):
        trainer, timing = trainer_and_run(b, num_envs, 1)
        cfg = trainer.cfg
        breakdown = period_breakdown(b, trainer, timing)
        eval_s = breakdown["seconds"]["evaluation"]
        no_eval_s = timing["median_s"] - eval_s
        limit = measured_limit(b, cfg, trainer.obs_dim, trainer.action_dim)
        out[f"envs_{num_envs}"] = {k: v for k, v in timing.items() if not k.startswith("_")} | {
            "env": cfg.env_name,
            "hidden_sizes": list(cfg.hidden_sizes),
            "batch_size": cfg.batch_size,
            "replay_capacity": cfg.replay_capacity,
            "updates_per_iteration": cfg.updates_per_iter,
            "limit_updates_per_s": limit,
            "fraction_of_limit": timing["updates_per_s"] / limit,
            "without_eval_env_steps_per_s": cfg.eval_every / no_eval_s,
            "without_eval_updates_per_s": timing["updates_per_period"] / no_eval_s,
            "without_eval_fraction_of_limit": timing["updates_per_period"] / no_eval_s / limit,
            "without_eval_method": "period time minus trainer.evaluate timed alone",
            "breakdown": breakdown,
        }
    _print_trainer(out)
    return out


def _print_trainer(out: dict) -> None:
    rows = []
    for r in out.values():
        rows.append(
            [
                f"{r['num_envs']} env(s), {r['updates_per_iteration']} upd/iter",
                r["env_steps_per_s"],
                r["updates_per_s"],
                r["fraction_of_limit"],
                r["without_eval_env_steps_per_s"],
                r["without_eval_fraction_of_limit"],
                r["compile_s"],
            ]
        )
    env = next(iter(out.values()))["env"]
    print_table(
        f"full trainer ({env}), 1 update per env step, one timed period",
        [
            "config",
            "env steps/s",
            "updates/s",
            "of limit",
            "no-eval steps/s",
            "no-eval of limit",
            "compile s",
        ],
        rows,
    )
    shares = [
        [f"{r['num_envs']} env(s)"]
        + [r["breakdown"]["share"][k] for k in ("evaluation", "env", "updates", "replay", "other")]
        for r in out.values()
    ]
    print_table(
        "share of one period's time (each part timed alone, scaled to one period)",
        ["config", "evaluation", "env", "updates", "replay", "other"],
        shares,
    )


def section_overlap(b: Bench) -> dict:
    """The trainer with `update_before_add` (updates independent of the iteration's env step, so
    XLA:CPU may overlap them) against the default order, at 1 and 16 envs."""
    out = {}
    for num_envs in (1, 16):
        base = trainer_run(b, num_envs, 1)
        alt = trainer_run(b, num_envs, 1, update_before_add=True)
        out[f"envs_{num_envs}"] = {
            "add_then_update_env_steps_per_s": base["env_steps_per_s"],
            "update_before_add_env_steps_per_s": alt["env_steps_per_s"],
            "speedup": alt["env_steps_per_s"] / base["env_steps_per_s"],
            "update_before_add_updates_per_s": alt["updates_per_s"],
        }
    print_table(
        "update order: add-then-update (default) vs update_before_add, 1 update per env step",
        ["envs", "default env steps/s", "update_before_add env steps/s", "speedup"],
        [
            [
                k,
                v["add_then_update_env_steps_per_s"],
                v["update_before_add_env_steps_per_s"],
                v["speedup"],
            ]
            for k, v in out.items()
        ],
    )
    return out


def section_replay(b: Bench) -> dict:
    """The trainer's replay work per iteration (1 env, 1 update: add 1, sample 256, write 256
    priorities) for 1 buffer and for N seed-vmapped buffers, at capacities 100k and 1M."""
    capacities = (10_000,) if b.args.quick else (100_000, 1_000_000)
    seed_counts = (1, 2) if b.args.quick else (1, 8)
    iters = 20 if b.args.quick else 200
    rows, out = [], {}
    for capacity in capacities:
        cfg = Config(replay_capacity=capacity, batch_size=PAPER_BATCH)
        for n in seed_counts:
            seconds = replay_seconds_per_iteration(
                b, cfg, HC_OBS_DIM, HC_ACTION_DIM, num_seeds=n if n > 1 else 0, iters=iters
            )
            ms = seconds * 1e3
            out[f"cap_{capacity}_seeds_{n}"] = {
                "capacity": capacity,
                "seeds": n,
                "ms_per_iteration_all_seeds": ms,
                "ms_per_iteration_per_seed": ms / n,
            }
            rows.append([f"{capacity:,}", n, ms, ms / n])
    for capacity in capacities:
        one = out[f"cap_{capacity}_seeds_1"]["ms_per_iteration_all_seeds"]
        n = seed_counts[-1]
        many = out[f"cap_{capacity}_seeds_{n}"]["ms_per_iteration_all_seeds"]
        out[f"cap_{capacity}_vmapped_vs_separate"] = n * one / many
    print_table(
        f"replay alone per iteration (add 1, sample {PAPER_BATCH}, write priorities), {iters} scanned",
        ["capacity", "seeds", "ms/iter (all seeds)", "ms/iter per seed"],
        rows,
    )
    return out


def section_seeds(b: Bench) -> dict:
    """Total updates/s of N vmapped seeds (1 env each) against one seed run N times in a row,
    and the same for the update alone (N vmapped agents on a fixed batch, the trainer's network
    and batch): the trainer does the update's work and more, so its N-seed total cannot exceed
    the update alone's, and `update_ceiling_on_speedup` = (update alone, N seeds) / (trainer, 1
    seed) bounds the trainer's speedup in the same run."""
    runs = {n: trainer_run(b, 1, n) for n in b.sizes.seed_counts}
    trainer = trainer_and_run(b, 1, b.sizes.seed_counts[0])[0]
    alone = {
        n: updates_per_s(b, trainer.cfg, trainer.obs_dim, trainer.action_dim, n)
        for n in b.sizes.seed_counts
    }
    single = runs[1]["updates_per_s"] if 1 in runs else float("nan")
    alone_single = alone[1]["updates_per_s"] if 1 in alone else float("nan")
    out = {}
    for n, r in runs.items():
        a = alone[n]["updates_per_s"]
        out[f"seeds_{n}"] = {k: v for k, v in r.items() if not k.startswith("_")} | {
            "total_updates_per_s": r["updates_per_s"],
            "per_seed_updates_per_s": r["updates_per_s"] / n,
            "speedup_vs_separate_runs": r["updates_per_s"] / single,
            "slower_than_separate_runs": bool(r["updates_per_s"] < single),
            "update_alone_total_updates_per_s": a,
            "update_alone_speedup_vs_one_seed": a / alone_single,
            "update_ceiling_on_speedup": a / single,
        }
    print_table(
        "vmapped seeds, 1 env each, 1 update per env step (separate runs = 1 seed's rate); "
        "update alone = the same seeds' updates on a fixed batch, no env or replay",
        [
            "seeds",
            "total updates/s",
            "per seed",
            "vs N separate runs",
            "slower?",
            "compile s",
            "update alone, total",
            "update alone vs 1 seed",
            "ceiling on speedup",
        ],
        [
            [
                n,
                r["total_updates_per_s"],
                r["per_seed_updates_per_s"],
                r["speedup_vs_separate_runs"],
                "yes" if r["slower_than_separate_runs"] else "no",
                r["compile_s"],
                r["update_alone_total_updates_per_s"],
                r["update_alone_speedup_vs_one_seed"],
                r["update_ceiling_on_speedup"],
            ]
            for n, r in zip(runs, out.values(), strict=True)
        ],
    )
    return out


def first_step_child(args: argparse.Namespace) -> None:
    """Child process: enable a persistent cache in `args.cache_dir`, build the 1-env trainer,
    compile one period and run it; print the timings as one JSON line."""
    jax.config.update("jax_compilation_cache_dir", args.cache_dir)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    try:
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    except AttributeError:  # option absent in this jax version
        pass
    sizes = QUICK if args.quick else FULL
    t0 = time.perf_counter()
    trainer = make_train(trainer_config(sizes, args.quick or args.skip_mjx, 1))
    compiled, state, hps, seconds = compile_trainer(trainer, 1)
    to_first_step = time.perf_counter() - t0
    start = time.perf_counter()
    block(compiled(state, hps, jnp.int32(0)))
    result = {
        "build_and_init_s": to_first_step - seconds["lower_s"] - seconds["compile_s"],
        "lower_s": seconds["lower_s"],
        "compile_s": seconds["compile_s"],
        "to_first_step_s": to_first_step,
        "first_chunk_run_s": time.perf_counter() - start,
        "env": trainer.cfg.env_name,
    }
    print(CHILD_MARKER + json.dumps(result), flush=True)


def run_child(b: Bench, cache_dir: str) -> dict:
    """One first-step child process; wall seconds include interpreter start and imports."""
    cmd = [sys.executable, "-m", "benchmarks.bench", "--first-step-child", "--cache-dir"]
    cmd += [cache_dir] + (["--quick"] if b.args.quick else [])
    cmd += ["--skip-mjx"] if b.args.skip_mjx else []
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=3600, cwd=REPO_ROOT)
    wall = time.perf_counter() - start
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith(CHILD_MARKER)]
    if proc.returncode or not lines:
        raise RuntimeError(f"first-step child failed ({proc.returncode}): {proc.stderr[-2000:]}")
    result = json.loads(lines[-1][len(CHILD_MARKER) :])
    files = [p for p in Path(cache_dir).rglob("*") if p.is_file()]
    return result | {
        "wall_s": wall,
        "wall_to_first_step_s": wall - result["first_chunk_run_s"],
        "cache_files_after": len(files),
        "cache_bytes_after": sum(p.stat().st_size for p in files),
    }


def section_first_step(b: Bench) -> dict:
    """Cold (empty persistent cache) and warm (same cache again) time to the first chunk."""
    cache_dir = tempfile.mkdtemp(prefix="arld_bench_cache_")
    try:
        cold = run_child(b, cache_dir)
        warm = run_child(b, cache_dir)
    finally:
        shutil.rmtree(cache_dir, ignore_errors=True)
    out = {
        "cold": cold,
        "warm": warm,
        "command": "python -m benchmarks.bench --first-step-child (fresh subprocess)",
    }
    print_table(
        f"time to first training step, 1 env ({cold['env']}), fresh subprocess",
        [
            "cache",
            "wall to 1st step s",
            "trace+lower s",
            "XLA compile s",
            "build+init s",
            "1st chunk run s",
            "wall s",
        ],
        [
            [
                name,
                r["wall_to_first_step_s"],
                r["lower_s"],
                r["compile_s"],
                r["build_and_init_s"],
                r["first_chunk_run_s"],
                r["wall_s"],
            ]
            for name, r in (("cold", cold), ("warm", warm))
        ],
    )
    return out


def tree_nbytes(tree: Any) -> int:
    """Bytes of every leaf of `tree`; works on arrays and on `jax.eval_shape` outputs alike."""
    return int(sum(math.prod(x.shape) * x.dtype.itemsize for x in jax.tree.leaves(tree)))


def section_memory(b: Bench) -> dict:
    """Replay and whole-TrainState bytes per seed at capacity 1M, from `jax.eval_shape` (nothing
    of that size is allocated; a 1000-item buffer checks the count against `replay_nbytes`)."""
    capacity = 1_000_000
    per = make_prioritized_replay(capacity, PAPER_BATCH, 0.6)
    example = example_transition(HC_OBS_DIM, HC_ACTION_DIM)
    replay_bytes = tree_nbytes(jax.eval_shape(per.init, example))
    small = make_prioritized_replay(1000, PAPER_BATCH, 0.6)
    small_check = replay_nbytes(small.init(example)) == tree_nbytes(
        jax.eval_shape(small.init, example)
    )
    env_name = "toy" if b.args.skip_mjx else "halfcheetah"
    cfg = Config(env_name=env_name, replay_capacity=capacity, **PLAIN_SAC)
    trainer = make_train(cfg)
    shapes = jax.eval_shape(trainer.init, jax.random.key(0), hparams_from_config(cfg))
    parts = {name: tree_nbytes(getattr(shapes, name)) for name in shapes.__dataclass_fields__}
    total = sum(parts.values())
    mem_total = mem_total_bytes()
    out = {
        "capacity": capacity,
        "replay_bytes_obs17_act6": replay_bytes,
        "replay_nbytes_agrees_on_small_buffer": small_check,
        "train_state_env": env_name,
        "train_state_bytes": total,
        "train_state_parts_bytes": parts,
        "machine_memory_bytes": mem_total,
        "seeds_fitting_in_memory": mem_total // total if mem_total else None,
        "method": "jax.eval_shape (no allocation); bytes = sum of prod(shape) * itemsize",
    }
    mib = 2**20
    rows = [["replay (obs 17, action 6)", replay_bytes / mib]]
    rows += [[f"TrainState ({env_name}) total", total / mib]]
    rows += [[f"  {k}", v / mib] for k, v in parts.items() if v >= mib // 100]
    print_table(f"memory per seed at replay capacity {capacity:,}", ["what", "MiB"], rows)
    return out
