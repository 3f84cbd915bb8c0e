"""Throughput, scaling and memory benchmark of arld_jax on this machine (CPU).

    python benchmarks/bench.py                    # everything (about an hour on 2 cores)
    python benchmarks/bench.py --quick            # tiny sizes, toy env for the trainer: smoke test
    python benchmarks/bench.py --only matmul,flops,update --skip-mjx

Sections, in the order they run (benchmarks/README.md says what each figure means):

    matmul      f32 and bf16-input matmul GFLOP/s at 256-wide shapes: the machine's ceiling
    flops       FLOPs of one SAC update (XLA cost analysis and an analytic count) -> updates/s limit
    env         env-only env steps/s with random actions (MJX HalfCheetah, 1 and 16 envs)
    update      update-only updates/s at B=256 on a fixed batch (f32 and bf16 matmul inputs)
    trainer     the full trainer (1 env; 16 envs), with a breakdown of where a period's time goes
    overlap     the trainer with update_before_add (updates may overlap the env step) vs default
    seeds       total updates/s of 1, 2, 4, 8 vmapped seeds against one seed run N times
    first_step  cold and warm (persistent compilation cache) time to the first training chunk
    memory      replay and TrainState bytes per seed at replay capacity 1M
    peers       Brax's own SAC trainer (separate venv, jax 0.9.2) vs arld_jax's, same configs

Every section prints a table as soon as it finishes, and the JSON report
(benchmarks/results/<host>-<date>.json) is rewritten after each one, so a killed run keeps what it
measured. Timings are wall-clock around `block_until_ready`, after a warm-up call that compiles.
This process does NOT use the persistent compilation cache, so its compile times are real; only the
`first_step` children do, each with its own fresh cache directory.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import importlib.metadata
import json
import math
import os
import platform
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp

from arld_jax.agents import Agent, make_agent
from arld_jax.config import Config, hparams_from_config
from arld_jax.envs import Env, make_env
from arld_jax.networks import NUM_CRITICS
from arld_jax.replay import PrioritizedReplay, make_prioritized_replay, replay_nbytes
from arld_jax.train import Trainer, compiler_options, jit_chunk, make_train, over_runs
from arld_jax.types import Transition, example_transition

SECTIONS: tuple[str, ...] = (
    "matmul",
    "flops",
    "env",
    "update",
    "trainer",
    "overlap",
    "replay",
    "seeds",
    "first_step",
    "memory",
    "peers",
)
RESULTS_DIR = Path(__file__).resolve().parent / "results"
CHILD_MARKER = "FIRST_STEP_RESULT "
# HalfCheetah's sizes; the update-only and FLOP figures use them even when the env is skipped.
HC_OBS_DIM, HC_ACTION_DIM = 17, 6
PAPER_HIDDEN, PAPER_BATCH = (256, 256), 256
PLAIN_SAC: dict[str, Any] = dict(noisy_runs=False)
"""Every program benchmarked here is plain SAC, built as the driver builds a sweep without a Noisy
SAC run (`Sweep.program_config`: no actor weight-noise draws). The update section also times the
program that draws them (a sweep with a Noisy SAC cell)."""


PAPER_UPDATE = Config(hidden_sizes=PAPER_HIDDEN, batch_size=PAPER_BATCH, **PLAIN_SAC)
"""The update every update-only figure times: B 256, 2x256, f32, plain SAC (HalfCheetah's shapes
come with HC_OBS_DIM, HC_ACTION_DIM)."""


@dataclass(frozen=True)
class Sizes:
    """How much work each section does (full run or --quick)."""

    matmul_steps: int  # matmuls in one scanned chain
    repeats: int  # timed calls per measurement (after one warm-up call)
    env_counts: tuple[int, ...]  # parallel envs of the env-only section
    env_steps: int  # scanned env steps per env-only call
    updates: int  # scanned SAC updates per update-only call
    period_env_steps: int  # env steps in one trainer period (eval_every)
    timed_periods: int  # trainer periods timed after the warm-up period
    seed_counts: tuple[int, ...]  # vmapped seeds of the seeds section
    trainer_hidden: tuple[int, ...]  # network of the trainer sections
    trainer_batch: int
    trainer_capacity: int
    toy_episode_length: int


FULL = Sizes(
    matmul_steps=1000,
    repeats=5,
    env_counts=(1, 16),
    env_steps=200,
    updates=100,
    period_env_steps=2000,
    timed_periods=2,
    seed_counts=(1, 2, 4, 8),
    trainer_hidden=PAPER_HIDDEN,
    trainer_batch=PAPER_BATCH,
    trainer_capacity=100_000,
    toy_episode_length=1000,
)
QUICK = Sizes(
    matmul_steps=50,
    repeats=2,
    env_counts=(1,),  # a single MJX compile
    env_steps=20,
    updates=10,
    period_env_steps=160,
    timed_periods=1,
    seed_counts=(1, 2),
    trainer_hidden=(64, 64),
    trainer_batch=64,
    trainer_capacity=10_000,
    toy_episode_length=100,
)


# ---------------------------------------------------------------- small helpers


def log(msg: str = "") -> None:
    """Print and flush at once, so a long run shows its progress."""
    print(msg, flush=True)


def block(tree: Any) -> Any:
    """Wait for every array of `tree` (JAX dispatch is asynchronous)."""
    return jax.block_until_ready(tree)


def time_calls(fn: Callable[[], Any], repeats: int) -> list[float]:
    """Seconds of `repeats` calls of `fn` (each waited for), after one untimed warm-up call."""
    block(fn())
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        block(fn())
        times.append(time.perf_counter() - start)
    return times


def time_rounds(calls: dict[str, Callable[[], Any]], rounds: int) -> dict[str, list[float]]:
    """Seconds of each of `calls` (already warmed up), alternated: every round calls each once,
    starting one call later than the round before, so the VM's drift touches them alike and no
    call always runs first."""
    names = list(calls)
    times: dict[str, list[float]] = {name: [] for name in names}
    for r in range(rounds):
        for name in names[r % len(names) :] + names[: r % len(names)]:
            start = time.perf_counter()
            block(calls[name]())
            times[name].append(time.perf_counter() - start)
    return times


def summarize(times: Sequence[float]) -> dict[str, Any]:
    """Median and best of a list of timings."""
    return {"median_s": statistics.median(times), "min_s": min(times), "all_s": list(times)}


def tree_nbytes(tree: Any) -> int:
    """Bytes of every leaf of `tree`; works on arrays and on `jax.eval_shape` outputs alike."""
    return int(sum(math.prod(x.shape) * x.dtype.itemsize for x in jax.tree.leaves(tree)))


def broadcast_seeds(tree: Any, n: int) -> Any:
    """Give every leaf a leading seed axis of size `n`."""
    return jax.tree.map(lambda x: jnp.broadcast_to(x, (n, *jnp.shape(x))), tree)


def print_table(title: str, header: Sequence[str], rows: Sequence[Sequence[Any]]) -> None:
    """A plain aligned text table."""
    cells = [[str(h) for h in header]] + [[_fmt(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    line = "  ".join("-" * w for w in widths)
    log(f"\n== {title}")
    for i, r in enumerate(cells):
        log(
            "  ".join(
                c.rjust(w) if j else c.ljust(w)
                for j, (c, w) in enumerate(zip(r, widths, strict=True))
            )
        )
        if i == 0:
            log(line)


def _fmt(x: Any) -> str:
    if isinstance(x, float):
        if math.isnan(x):
            return "n/a"
        return f"{x:,.3g}" if abs(x) < 100 else f"{x:,.0f}"
    if isinstance(x, int):
        return f"{x:,}"
    return str(x)


def random_batch(key: jax.Array, batch: int, obs_dim: int, action_dim: int) -> Transition:
    """A fixed random minibatch for the update-only measurement."""
    k_obs, k_act, k_rew, k_next = jax.random.split(key, 4)
    return Transition(
        obs=jax.random.normal(k_obs, (batch, obs_dim)),
        action=jax.random.uniform(k_act, (batch, action_dim), minval=-1.0, maxval=1.0),
        reward=jax.random.normal(k_rew, (batch,)),
        next_obs=jax.random.normal(k_next, (batch, obs_dim)),
        terminated=jnp.zeros(batch),
        is_demo=jnp.zeros(batch),
    )


# ---------------------------------------------------------------- the report


@dataclass
class Bench:
    """The run's options, its JSON report and measurements shared between sections."""

    args: argparse.Namespace
    sizes: Sizes
    out: Path
    report: dict[str, Any]
    memo: dict[Any, Any] = field(default_factory=dict)

    @property
    def toy_trainer(self) -> bool:
        """The trainer sections use the toy env (--quick or --skip-mjx)."""
        return self.args.quick or self.args.skip_mjx

    def save(self) -> None:
        """Rewrite the JSON report atomically."""
        self.out.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.out.with_suffix(".tmp")
        tmp.write_text(json.dumps(self.report, indent=2, default=_json_default) + "\n")
        os.replace(tmp, self.out)


def _json_default(x: Any) -> Any:
    if hasattr(x, "item"):
        return x.item()
    return str(x)


def machine_info(args: argparse.Namespace) -> dict[str, Any]:
    """Versions, CPU model and flags, core count, date, load and the exact command."""
    versions = {}
    for pkg in ("jax", "jaxlib", "brax", "mujoco", "mujoco-mjx", "flax", "optax", "numpy"):
        try:
            versions[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            versions[pkg] = None
    cpuinfo = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    model = next(
        (ln.split(":", 1)[1].strip() for ln in cpuinfo.splitlines() if "model name" in ln), ""
    )
    flags_line = next(
        (ln.split(":", 1)[1] for ln in cpuinfo.splitlines() if ln.startswith("flags")), ""
    )
    wanted = ("avx2", "fma", "avx512f", "avx512_bf16", "avx512_vnni", "amx_bf16", "amx_tile")
    return {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "hostname": socket.gethostname(),
        "command": " ".join([sys.executable, *sys.argv]),
        "mode": "quick" if args.quick else "full",
        "skip_mjx": args.skip_mjx,
        "versions": versions,
        "python": platform.python_version(),
        "cpu_model": model or platform.processor(),
        "cpu_flags": [f for f in wanted if f in flags_line.split()],
        "cpu_count": os.cpu_count(),
        "cpus_usable": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "devices": [str(d) for d in jax.devices()],
        "load_average_at_start": list(os.getloadavg()),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "compiler_options": compiler_options(),  # given to every timed program's jax.jit
        "persistent_cache_dir_in_parent": jax.config.jax_compilation_cache_dir,
    }


# ---------------------------------------------------------------- 1. matmul throughput


def matmul_chain(steps: int, dtype: jnp.dtype) -> Callable[..., jax.Array]:
    """Jitted lax.scan of `steps` matmuls x <- tanh(x @ w), [E,256,256] @ [E,256,256].

    Inputs in `dtype`, accumulation in f32 (`preferred_element_type`). The tanh keeps values in
    range (no inf, no denormals) for any chain length; it costs a few percent of the matmul and is
    not counted, so the GFLOP/s are slightly conservative."""

    def chain(x: jax.Array, w: jax.Array) -> jax.Array:
        def body(x: jax.Array, _: None) -> tuple[jax.Array, None]:
            y = jnp.einsum("eij,ejk->eik", x, w, preferred_element_type=jnp.float32)
            return jnp.tanh(y).astype(dtype), None

        x, _ = jax.lax.scan(body, x, None, length=steps)
        return x

    return jax.jit(chain)


def matmul_call(
    sizes: Sizes, ensembles: int, dtype: jnp.dtype, width: int = 256
) -> tuple[Callable[[], jax.Array], int]:
    """One call of the chain on fixed inputs, and its FLOPs (2 * width^3 per matmul per member)."""
    k_x, k_w = jax.random.split(jax.random.key(0))
    shape = (ensembles, width, width)
    x = jax.random.normal(k_x, shape).astype(dtype)
    w = (1.5 / math.sqrt(width) * jax.random.normal(k_w, shape)).astype(dtype)
    chain = matmul_chain(sizes.matmul_steps, dtype)
    return (lambda: chain(x, w)), 2 * width**3 * ensembles * sizes.matmul_steps


def measure_matmul(sizes: Sizes, ensembles: int, dtype: jnp.dtype, width: int = 256) -> dict:
    """GFLOP/s of the chain (2 * width^3 FLOPs per matmul per ensemble member)."""
    call, flops = matmul_call(sizes, ensembles, dtype, width)
    times = time_calls(call, sizes.repeats)
    return summarize(times) | {
        "flops_per_call": flops,
        "gflops_median": flops / statistics.median(times) / 1e9,
        "gflops_best": flops / min(times) / 1e9,
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
        run_section(b, "matmul")
    m = b.report["sections"]["matmul"]
    return max(m[f"{dtype_name}_e1"]["gflops_best"], m[f"{dtype_name}_e8"]["gflops_best"])


# ---------------------------------------------------------------- 2. FLOPs of one update


def dense_layers(in_dim: int, hidden: Sequence[int], head_dims: Sequence[int]) -> list:
    """(in, out) of every Dense layer of an MLP trunk followed by parallel heads."""
    dims = [in_dim, *hidden]
    return list(zip(dims[:-1], dims[1:], strict=True)) + [(dims[-1], o) for o in head_dims]


def layer_flops(layers: Sequence[tuple[int, int]], rows: int) -> int:
    """Forward matmul FLOPs of `layers` on `rows` inputs (one multiply-add = 2 FLOPs)."""
    return sum(2 * rows * i * o for i, o in layers)


def analytic_update_flops(
    obs_dim: int, action_dim: int, hidden: Sequence[int], batch: int
) -> dict[str, int]:
    """Matmul FLOPs of ONE `agent.update` (SAC, twin critics, fixed alpha), counted by hand.

    A Dense layer i -> o on B rows costs 2*B*i*o forward; its backward costs 2*B*i*o for the weight
    gradient and another 2*B*i*o for the input gradient, the latter only when something upstream
    needs it (never for the first layer of the differentiated network, whose input is data).

      actor  = obs -> hidden... -> {mean head, log-std head}, each [h_last -> action_dim]
               (the NoisyDense variance matmul x^2 @ sigma_w^2 feeds no loss, so XLA drops it)
      critic = concat(obs, action) -> hidden... -> 1, NUM_CRITICS of them (twin)

      critic loss = actor fwd on next_obs                      (sample a', log pi(a'|s'))
                  + target twin-critic fwd on (next_obs, a')
                  + twin-critic fwd on (obs, action)
                  + twin-critic bwd: weight grads of every layer, input grads of all but the first
      actor loss  = actor fwd on obs
                  + twin-critic fwd on (obs, a) with the new critic params
                  + twin-critic bwd down to the action: input grads of every layer (the first
                    layer's input grad is computed for the whole concat(obs, a), an upper bound),
                    no critic weight grads
                  + actor bwd: weight grads of every layer, input grads of all but the first

    Not counted (elementwise, O(params) or O(B * action_dim)): Adam, Polyak averaging,
    tanh-Gaussian log-probs, losses, noise sampling. XLA's cost analysis counts those too (and may
    count some ops differently), so its figure is somewhat higher.
    """
    actor = dense_layers(obs_dim, hidden, (action_dim, action_dim))
    critic = dense_layers(obs_dim + action_dim, hidden, (1,))
    actor_fwd = layer_flops(actor, batch)
    twin_fwd = NUM_CRITICS * layer_flops(critic, batch)
    twin_input_grads_but_first = NUM_CRITICS * layer_flops(critic[1:], batch)
    actor_input_grads_but_first = layer_flops(actor[1:], batch)
    critic_loss = actor_fwd + twin_fwd + twin_fwd + twin_fwd + twin_input_grads_but_first
    actor_loss = actor_fwd + twin_fwd + twin_fwd + actor_fwd + actor_input_grads_but_first
    return {
        "critic_loss_and_grad": critic_loss,
        "actor_loss_and_grad": actor_loss,
        "total": critic_loss + actor_loss,
        "actor_forward": actor_fwd,
        "twin_critic_forward": twin_fwd,
    }


def xla_flops(compiled: Any) -> float:
    """The 'flops' entry of a compiled program's cost analysis (a dict, or a list of dicts)."""
    cost = compiled.cost_analysis()
    if isinstance(cost, dict):
        cost = [cost]
    return float(sum(c.get("flops", 0.0) for c in cost or [] if c))


def agent_and_inputs(
    cfg: Config, obs_dim: int, action_dim: int
) -> tuple[Agent, Any, Transition, jax.Array, Any]:
    """An agent of `cfg`, its initial state, a fixed random batch, unit IS weights and hparams."""
    hp = hparams_from_config(cfg)
    agent = make_agent(cfg, obs_dim, action_dim)
    k_init, k_batch = jax.random.split(jax.random.key(0))
    state = agent.init(k_init, hp)
    batch = random_batch(k_batch, cfg.batch_size, obs_dim, action_dim)
    return agent, state, batch, jnp.ones(cfg.batch_size), hp


def section_flops(b: Bench) -> dict:
    """FLOPs of one SAC update at B=256, 2x256 (obs 17, action 6), and the updates/s it allows."""
    cfg = PAPER_UPDATE
    agent, state, batch, weights, hp = agent_and_inputs(cfg, HC_OBS_DIM, HC_ACTION_DIM)
    indices = jnp.arange(weights.shape[0])
    lowered = jax.jit(agent.update).lower(state, batch, weights, indices, hp, jax.random.key(1))
    from_xla = xla_flops(lowered.compile())
    analytic = analytic_update_flops(HC_OBS_DIM, HC_ACTION_DIM, PAPER_HIDDEN, PAPER_BATCH)
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
        "limit_updates_per_s_f32": f32 * 1e9 / analytic["total"],
        "limit_updates_per_s_bf16": bf16 * 1e9 / analytic["total"],
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


def limit_updates_per_s(
    b: Bench, cfg: Config, obs_dim: int, action_dim: int, gflops: float | None = None
) -> float:
    """Physical limit of `cfg`'s update (its own sizes) at the measured 256-wide matmul rate
    (`gflops` when given, else the matmul section's, `matmul_gflops`)."""
    dtype_name = "bfloat16" if cfg.matmul_dtype == "bfloat16" else "float32"
    flops = analytic_update_flops(obs_dim, action_dim, cfg.hidden_sizes, cfg.batch_size)["total"]
    return (gflops or matmul_gflops(b, dtype_name)) * 1e9 / flops


# ---------------------------------------------------------------- 3. env-only


def env_rollout(env: Env, num_envs: int, steps: int) -> Callable[[jax.Array], jax.Array]:
    """Jitted reset, then a lax.scan of `steps` env steps with uniform random actions in [-1, 1].

    The reset sits in the same program so MJX compiles once (an MJX compile takes minutes); it
    costs about one step, i.e. <= 1/steps of a call."""

    def rollout(key: jax.Array) -> jax.Array:
        k_reset, k_steps = jax.random.split(key)

        def body(s: Any, k: jax.Array) -> tuple[Any, jax.Array]:
            a = jax.random.uniform(k, (num_envs, env.action_dim), minval=-1.0, maxval=1.0)
            s = env.step(s, a)
            return s, jnp.sum(s.reward)

        state = env.reset(k_reset, num_envs)
        _, rewards = jax.lax.scan(body, state, jax.random.split(k_steps, steps))
        return jnp.sum(rewards)

    return jax.jit(rollout, compiler_options=compiler_options())


def env_config(env_name: str, num_envs: int, backend: str = "mjx") -> Config:
    """A valid Config with `num_envs` envs (eval_every must be a multiple of num_envs, so the
    default Config(num_envs=16) is rejected; only env_name, backend and num_envs matter to
    make_env)."""
    period = 1000 * num_envs
    return Config(
        env_name=env_name,
        backend=backend,
        num_envs=num_envs,
        eval_every=period,
        total_env_steps=10 * period,
    )


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


# ---------------------------------------------------------------- 4. update-only


def update_scan(
    agent: Agent, num_updates: int, vmapped: bool = False, extra_options: dict | None = None
) -> Callable[..., Any]:
    """Jitted lax.scan of `num_updates` SAC updates on one fixed batch; `vmapped`: over agents
    (every input with a leading seed axis), as in a seed sweep.
    `extra_options` are XLA options added to `compiler_options()` (`ab_xla_options.py`)."""

    def run(state: Any, batch: Transition, weights: jax.Array, hp: Any, key: jax.Array) -> Any:
        def body(s: Any, k: jax.Array) -> tuple[Any, jax.Array]:
            s, _, metrics = agent.update(s, batch, weights, jnp.arange(weights.shape[0]), hp, k)
            return s, metrics.critic_loss

        return jax.lax.scan(body, state, jax.random.split(key, num_updates))

    options = compiler_options() | (extra_options or {})
    return jax.jit(jax.vmap(run) if vmapped else run, compiler_options=options)


def update_call(
    cfg: Config,
    obs_dim: int,
    action_dim: int,
    num_updates: int,
    num_seeds: int = 1,
    extra_options: dict | None = None,
) -> tuple[Callable[[], Any], Any]:
    """The update-alone program of `cfg` (`update_scan`, compiled) and a call of it that continues
    from the last call's agents. `num_seeds` > 1 vmaps it over that many agents, one program as in
    a seed sweep (1: the unvmapped single-run program, as `train.over_runs` runs one seed); every
    agent starts from the same state and batch, each with its own key."""
    agent, state, batch, weights, hp = agent_and_inputs(cfg, obs_dim, action_dim)
    key = jax.random.key(3)
    if num_seeds > 1:
        seeds = lambda x: jnp.broadcast_to(x, (num_seeds, *x.shape))
        state, batch, weights, hp = jax.tree.map(seeds, (state, batch, weights, hp))
        key = jax.random.split(key, num_seeds)
    run = update_scan(agent, num_updates, num_seeds > 1, extra_options)
    compiled = run.lower(state, batch, weights, hp, key).compile()
    holder = {"state": state}

    def call() -> Any:
        holder["state"], losses = compiled(holder["state"], batch, weights, hp, key)
        return losses

    return call, compiled


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
        limit = limit_updates_per_s(b, cfg, HC_OBS_DIM, HC_ACTION_DIM)
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
    chains = [matmul_call(b.sizes, e, jnp.float32) for e in (1, 8)]
    update = bench_update_call(b, PAPER_UPDATE, HC_OBS_DIM, HC_ACTION_DIM)
    fractions = []
    for _ in range(2 * b.sizes.repeats):
        gflops = max(flop / 1e9 / min(time_calls(call, 1)) for call, flop in chains)
        updates_per_s = b.sizes.updates / time_calls(update, 1)[0]
        limit = limit_updates_per_s(b, PAPER_UPDATE, HC_OBS_DIM, HC_ACTION_DIM, gflops)
        fractions.append(updates_per_s / limit)
    return {
        "fraction_of_limit_interleaved": statistics.median(fractions),
        "fractions_interleaved": fractions,
    }


# ---------------------------------------------------------------- 5. full trainer


def trainer_config(
    sizes: Sizes, toy: bool, num_envs: int, update_before_add: bool = False
) -> Config:
    """One warm-up period plus `timed_periods` timed ones, 1 update per env step, 1 eval episode.

    The random warm-up (learning_starts = half a period) lies inside the first period, so every
    timed period is pure training."""
    period = sizes.period_env_steps
    iters_per_eval = period // num_envs
    fields: dict[str, Any] = dict(
        num_envs=num_envs,
        total_env_steps=(1 + sizes.timed_periods) * period,
        eval_every=period,
        learning_starts=period // 2,
        replay_capacity=sizes.trainer_capacity,
        num_eval_episodes=1,
        traces_per_eval=math.gcd(10, iters_per_eval),
        updates_per_env_step=1.0,
        hidden_sizes=sizes.trainer_hidden,
        batch_size=sizes.trainer_batch,
        update_before_add=update_before_add,
        **PLAIN_SAC,
    )
    if toy:
        fields |= dict(env_name="toy", episode_length=sizes.toy_episode_length)
    return Config(**fields)


def compile_trainer(trainer: Trainer, num_seeds: int) -> tuple[Any, Any, Any, dict[str, float]]:
    """Init and one-period `run_periods` over seeds, jitted as run.py does (`over_runs`, static
    num_periods, donated state). Returns the compiled chunk, state, hparams and the seconds of tracing and
    lowering (`lower_s`, never cached) and of the XLA compile (`compile_s`, cacheable)."""
    cfg = trainer.cfg
    hps = broadcast_seeds(hparams_from_config(cfg), num_seeds)
    keys = jax.random.split(jax.random.key(cfg.seed), num_seeds)
    state = block(jax.jit(over_runs(trainer.init))(keys, hps))
    run = jit_chunk(trainer)
    start = time.perf_counter()
    lowered = run.lower(state, hps, jnp.int32(0), 1)
    lowered_at = time.perf_counter()
    compiled = lowered.compile()
    seconds = {"lower_s": lowered_at - start, "compile_s": time.perf_counter() - lowered_at}
    return compiled, state, hps, seconds


def time_periods(trainer: Trainer, num_seeds: int, max_timed: int) -> dict:
    """Compile, run the warm-up period, then time up to `max_timed` following periods."""
    cfg = trainer.cfg
    compiled, state, hps, seconds = compile_trainer(trainer, num_seeds)
    start = time.perf_counter()
    state, _ = block(compiled(state, hps, jnp.int32(0)))
    warmup_s = time.perf_counter() - start
    times = []
    for p in range(1, min(cfg.num_evals, 1 + max_timed)):
        start = time.perf_counter()
        state, metrics = block(compiled(state, hps, jnp.int32(p)))
        times.append(time.perf_counter() - start)
    period_s = statistics.median(times)
    updates = cfg.iters_per_eval * cfg.updates_per_iter * num_seeds
    return summarize(times) | {
        "num_seeds": num_seeds,
        "num_envs": cfg.num_envs,
        "lower_s": seconds["lower_s"],
        "compile_s": seconds["lower_s"] + seconds["compile_s"],
        "xla_compile_s": seconds["compile_s"],
        "warmup_period_s": warmup_s,
        "env_steps_per_period": cfg.eval_every * num_seeds,
        "updates_per_period": updates,
        "env_steps_per_s": cfg.eval_every * num_seeds / period_s,
        "updates_per_s": updates / period_s,
        "last_eval_return": float(jnp.mean(metrics.eval_return)),
        "_agent_state": jax.tree.map(lambda x: x[0], state.agent),
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


def replay_scan(
    per: PrioritizedReplay,
    cfg: Config,
    obs_dim: int,
    action_dim: int,
    iters: int,
    num_seeds: int = 0,
) -> tuple[Callable[..., Any], Transition]:
    """Jitted scan of the trainer's replay work: add num_envs items, then updates_per_iter x
    (sample, set priorities from the sampled batch, so the gather is not optimized away).
    With `num_seeds` > 0 every iteration is vmapped over that many buffers (the state then has a
    leading seed axis), as in a seed-vmapped trainer."""
    example = example_transition(obs_dim, action_dim)

    def one_sample(r: Any, k: jax.Array) -> tuple[Any, jax.Array]:
        batch, idx, weights = per.sample(r, k, jnp.float32(0.5))
        touch = batch.reward + batch.obs.sum(-1) + batch.next_obs.sum(-1) + batch.action.sum(-1)
        r = per.set_priorities(r, idx, jnp.abs(touch) + 1e-3)
        return r, jnp.sum(weights)

    def iteration(r: Any, k: jax.Array) -> tuple[Any, jax.Array]:
        k_item, k_sample = jax.random.split(k)
        leaves, treedef = jax.tree.flatten(example)
        ks = jax.random.split(k_item, len(leaves))
        items = [
            jax.random.normal(kk, (cfg.num_envs, *x.shape))
            for kk, x in zip(ks, leaves, strict=True)
        ]
        r = per.add(r, jax.tree.unflatten(treedef, items))
        r, w = jax.lax.scan(one_sample, r, jax.random.split(k_sample, cfg.updates_per_iter))
        return r, jnp.sum(w)

    def step(r: Any, k: jax.Array) -> tuple[Any, jax.Array]:
        if num_seeds:
            return jax.vmap(iteration)(r, jax.random.split(k, num_seeds))
        return iteration(r, k)

    def run(r: Any, key: jax.Array) -> tuple[Any, jax.Array]:
        r, w = jax.lax.scan(step, r, jax.random.split(key, iters))
        return r, jnp.sum(w)

    return jax.jit(run, donate_argnums=0, compiler_options=compiler_options()), example


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
        limit = limit_updates_per_s(b, cfg, trainer.obs_dim, trainer.action_dim)
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


# ---------------------------------------------------------------- 5b. replay alone under seed vmap


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


# ---------------------------------------------------------------- 6. vmapped seeds


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


# ---------------------------------------------------------------- 7. cold / warm first step


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
    cmd = [sys.executable, str(Path(__file__).resolve()), "--first-step-child", "--cache-dir"]
    cmd += [cache_dir] + (["--quick"] if b.args.quick else [])
    cmd += ["--skip-mjx"] if b.args.skip_mjx else []
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=3600)
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
    out = {"cold": cold, "warm": warm, "command": "bench.py --first-step-child (fresh subprocess)"}
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


# ---------------------------------------------------------------- 8. memory


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
    mem_total = _mem_total_bytes()
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


def _mem_total_bytes() -> int | None:
    """MemTotal of /proc/meminfo, if there is one."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


# ---------------------------------------------------------------- 9. peers: Brax's own SAC


BRAX_VENV_ENV_VAR = "ARLD_BENCH_BRAX_VENV"
BENCH_CACHE = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "arld_jax_bench"
# Brax 0.14.2's trainers need jax < 0.10 (`jax.device_put_replicated`). This set resolves on PyPI
# (pip, 2026-11) and runs brax.training.agents.sac on MJX HalfCheetah; mujoco-mjx 3.17.0 asks for
# mujoco >= 3.17.0.dev0, so mujoco is pinned to the matching 3.17.0.
BRAX_VENV_PINS: tuple[str, ...] = (
    "jax==0.9.2",
    "jaxlib==0.9.2",
    "brax==0.14.2",
    "mujoco-mjx==3.17.0",
    "mujoco==3.17.0",
)
PEER_SCRIPT = Path(__file__).resolve().parent / "peers" / "brax_sac.py"
PEER_MARKER = "PEER_EVENT "  # = brax_sac.PEER_MARKER (that file must not import arld_jax)


@dataclass(frozen=True)
class PeerSizes:
    """Work of the peers section: the same on both sides (see `section_peers`)."""

    env_counts: tuple[int, ...]  # configs (parallel envs), 1 update per env step each
    period_env_steps: int  # env steps between evaluations (arld eval_every; one Brax epoch)
    eval_episodes: int  # episodes per evaluation (arld num_eval_episodes; Brax num_eval_envs)
    timed_periods: int  # periods timed after the warm-up period (which compiles)
    capacity: int  # replay capacity (arld replay_capacity; Brax max_replay_size)


PEERS_FULL = PeerSizes(
    env_counts=(16, 1), period_env_steps=4000, eval_episodes=5, timed_periods=3, capacity=100_000
)
PEERS_QUICK = PeerSizes(
    env_counts=(16,), period_env_steps=512, eval_episodes=1, timed_periods=1, capacity=10_000
)


def brax_venv_dir() -> Path:
    """The separate virtual environment of Brax's trainer ($ARLD_BENCH_BRAX_VENV overrides)."""
    return Path(os.environ.get(BRAX_VENV_ENV_VAR) or BENCH_CACHE / "brax-venv").expanduser()


def _venv_python(venv: Path) -> Path:
    return venv / ("Scripts/python.exe" if os.name == "nt" else "bin/python")


def _peer_env() -> dict[str, str]:
    """The child's environment: ours without PYTHONPATH/PYTHONHOME (the venv must see only its
    own site-packages; XLA_FLAGS and the rest are kept, so both trainers see the same flags)."""
    return {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}


def _peer_events(stdout: str) -> list[dict]:
    return [
        json.loads(ln[len(PEER_MARKER) :])
        for ln in stdout.splitlines()
        if ln.startswith(PEER_MARKER)
    ]


def _probe_brax_venv(python: Path) -> dict | None:
    """The venv's package versions (the child's info line), or None when it cannot run it."""
    if not python.exists():
        return None
    proc = subprocess.run(
        [str(python), str(PEER_SCRIPT), "--versions-only", "--num-envs", "1", "--num-timesteps",
         "1", "--num-evals", "1", "--num-eval-envs", "1", "--min-replay-size", "0",
         "--max-replay-size", "1"],
        capture_output=True, text=True, timeout=600, env=_peer_env(),
    )  # fmt: skip
    info = [e for e in _peer_events(proc.stdout) if e["event"] == "info"]
    return info[0] if proc.returncode == 0 and info else None


def _pins_met(versions: dict) -> bool:
    pinned = dict(p.split("==") for p in BRAX_VENV_PINS)
    return all(versions.get(k) == v for k, v in pinned.items())


def ensure_brax_venv() -> dict:
    """Create the venv (`python -m venv`) and `pip install` the pins when missing or different;
    return its versions, `pip freeze` and whether it was built now. Raises RuntimeError (with
    pip's output) when it cannot be built, e.g. without network."""
    venv = brax_venv_dir()
    python = _venv_python(venv)
    info = _probe_brax_venv(python)
    built, build_s, log_path = False, 0.0, venv.parent / f"{venv.name}-pip.log"
    if info is None or not _pins_met(info["versions"]):
        log(f"(building the Brax venv {venv}: pip install {' '.join(BRAX_VENV_PINS)}; ~0.5 GB)")
        start = time.perf_counter()
        venv.parent.mkdir(parents=True, exist_ok=True)
        steps = [
            [sys.executable, "-m", "venv", str(venv)],
            [str(python), "-m", "pip", "install", "--upgrade", *BRAX_VENV_PINS],
        ]
        with log_path.open("w") as fh:
            for cmd in steps:
                fh.write(f"$ {' '.join(cmd)}\n")
                fh.flush()
                proc = subprocess.run(
                    cmd, stdout=fh, stderr=subprocess.STDOUT, text=True, timeout=3600,
                    env=_peer_env(),
                )  # fmt: skip
                if proc.returncode:
                    tail = log_path.read_text()[-1500:]
                    raise RuntimeError(
                        f"cannot build the Brax venv {venv} ({' '.join(cmd[:4])} ... exit "
                        f"{proc.returncode}; log {log_path}): {tail}"
                    )
        build_s, built = time.perf_counter() - start, True
        info = _probe_brax_venv(python)
        if info is None or not _pins_met(info["versions"]):
            raise RuntimeError(f"Brax venv {venv} built but its versions do not match: {info}")
    freeze = subprocess.run(
        [str(python), "-m", "pip", "freeze"], capture_output=True, text=True, timeout=600
    ).stdout.split()
    return {
        "path": str(venv),
        "override_env_var": BRAX_VENV_ENV_VAR,
        "pins": list(BRAX_VENV_PINS),
        "versions": info["versions"],
        "python": info["python"],
        "devices": info["devices"],
        "pip_freeze": freeze,
        "built_now": built,
        "build_s": build_s,
        "pip_log": str(log_path) if built else None,
    }


def brax_run(venv: dict, num_envs: int, ps: PeerSizes) -> dict:
    """Brax's SAC (benchmarks/peers/brax_sac.py) in the venv; rate between the last two progress
    calls (one epoch of `period_env_steps` env steps + one evaluation, nothing compiling)."""
    period = ps.period_env_steps
    prefill = period // 2  # = arld's learning_starts in trainer_config (a multiple of num_envs)
    num_evals = 2 + ps.timed_periods  # initial eval + warm-up epoch (compiles) + timed epochs
    num_timesteps = prefill + (num_evals - 1) * period
    args = {
        "--num-envs": num_envs,
        "--num-timesteps": num_timesteps,
        "--num-evals": num_evals,
        "--num-eval-envs": ps.eval_episodes,
        "--min-replay-size": prefill,
        "--max-replay-size": ps.capacity,
        "--batch-size": PAPER_BATCH,
        "--episode-length": 1000,
    }
    cmd = [str(_venv_python(Path(venv["path"]))), str(PEER_SCRIPT)]
    cmd += [str(x) for kv in args.items() for x in kv]
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=4 * 3600, env=_peer_env())
    wall = time.perf_counter() - start
    events = _peer_events(proc.stdout)
    progress = [e for e in events if e["event"] == "progress"]
    done = [e for e in events if e["event"] == "done"]
    if proc.returncode or not done or len(progress) < 3:
        raise RuntimeError(f"Brax child failed ({proc.returncode}): {proc.stderr[-2000:]}")
    steps_per_epoch = done[0]["num_training_steps_per_epoch"] * num_envs
    if steps_per_epoch != period:
        raise RuntimeError(f"Brax epoch has {steps_per_epoch} env steps, expected {period}")
    intervals = [
        {
            "env_steps": b["step"] - a["step"],
            "seconds": b["t"] - a["t"],
            "env_steps_per_s": (b["step"] - a["step"]) / (b["t"] - a["t"]),
            "training_sps": b["metrics"].get("training/sps", float("nan")),
            "eval_s": b["metrics"].get("eval/epoch_eval_time", float("nan")),
        }
        for a, b in zip(progress[1:-1], progress[2:], strict=True)  # from the 2nd epoch on
    ]
    last = intervals[-1]
    return {
        "num_envs": num_envs,
        "command": " ".join(cmd),
        "train_kwargs": {
            "environment": "envs.get_environment('halfcheetah', backend='mjx')",
            "num_envs": num_envs,
            "grad_updates_per_step": num_envs,
            "batch_size": PAPER_BATCH,
            "min_replay_size": prefill,
            "max_replay_size": ps.capacity,
            "episode_length": 1000,
            "discounting": 0.99,
            "learning_rate": 3e-4,
            "reward_scaling": 1.0,
            "tau": 0.005,
            "normalize_observations": False,
            "deterministic_eval": True,
            "num_eval_envs": ps.eval_episodes,
            "num_timesteps": num_timesteps,
            "num_evals": num_evals,
            "network": "make_sac_networks default: 2x256 relu, tanh-normal policy, 2 critics",
        },
        "progress": progress,
        "steady_intervals": intervals,
        "env_steps_per_s": last["env_steps_per_s"],
        "env_steps_per_s_median": statistics.median(i["env_steps_per_s"] for i in intervals),
        "without_eval_env_steps_per_s": last["training_sps"],
        "eval_s": last["eval_s"],
        "to_first_progress_s": progress[0]["t"],
        "last_eval_return": progress[-1]["metrics"].get("eval/episode_reward", float("nan")),
        "child_wall_s": wall,
        "method": "env steps between the last two progress calls / seconds between them "
        "(one training epoch + one evaluation; compiles happen before the first epoch ends)",
    }


def arld_peer_run(b: Bench, num_envs: int, ps: PeerSizes, backend: str = "mjx") -> dict:
    """arld_jax's trainer at the peers config: `trainer_config` (1 update per env step,
    learning_starts half a period) with the peers' period, sizes and eval episodes, jitted as the
    driver does (`jit_chunk`, via `time_periods`); the median of the timed periods. `backend`:
    the physics of halfcheetah ('mjx' as Brax, or 'mujoco': MuJoCo's C engine, same model)."""
    sizes = dataclasses.replace(
        b.sizes,
        period_env_steps=ps.period_env_steps,
        timed_periods=ps.timed_periods,
        trainer_hidden=PAPER_HIDDEN,
        trainer_batch=PAPER_BATCH,
        trainer_capacity=ps.capacity,
    )
    cfg = trainer_config(sizes, False, num_envs).replace(
        num_eval_episodes=ps.eval_episodes,
        autotune_alpha=True,  # as Brax (arld computes the alpha step either way: same work)
        backend=backend,
    )
    trainer = make_train(cfg)
    timing = time_periods(trainer, 1, ps.timed_periods)
    eval_s = evaluate_seconds(b, trainer, timing["_agent_state"])
    out = {k: v for k, v in timing.items() if not k.startswith("_")}
    return out | {
        "env": cfg.env_name,
        "backend": cfg.backend,
        "eval_every": cfg.eval_every,
        "num_eval_episodes": cfg.num_eval_episodes,
        "learning_starts": cfg.learning_starts,
        "replay_capacity": cfg.replay_capacity,
        "hidden_sizes": list(cfg.hidden_sizes),
        "batch_size": cfg.batch_size,
        "updates_per_env_step": cfg.updates_per_env_step,
        "autotune_alpha": cfg.autotune_alpha,
        "eval_s": eval_s,
        "without_eval_env_steps_per_s": cfg.eval_every / (timing["median_s"] - eval_s),
        "method": "median over timed periods of eval_every env steps + one evaluation "
        "(time_periods); without eval: minus trainer.evaluate timed alone",
    }


def section_peers(b: Bench) -> dict:
    """Brax's own SAC trainer (brax.training.agents.sac.train, in a separate venv with jax 0.9.2)
    and arld_jax's trainer, side by side at the same configs on MJX HalfCheetah; arld_jax also with
    the same HalfCheetah stepped by MuJoCo's C engine (`--backend mujoco`), the speed a CPU user
    of arld_jax gets, reported beside (not instead of) the like-for-like MJX ratio.

    Equal work: both do 1 gradient update (batch 256, 2x256 actor and twin critics) per env step,
    evaluate every `period_env_steps` env steps with `eval_episodes` parallel 1,000-step episodes
    of the deterministic policy, and are timed over whole periods (training + evaluation) after a
    warm-up period that compiles. Differences that are part of each trainer and left in: arld_jax
    uses prioritized replay, Brax a uniform queue; Brax's alpha loss runs its own actor forward.
    """
    if b.args.skip_mjx:
        return {"skipped": "--skip-mjx: Brax's trainer runs MJX HalfCheetah only"}
    ps = PEERS_QUICK if b.args.quick else PEERS_FULL
    out: dict[str, Any] = {
        "sizes": dataclasses.asdict(ps),
        "evaluation": (
            f"included on both sides, equal: every {ps.period_env_steps} env steps, "
            f"{ps.eval_episodes} parallel episode(s) of 1000 steps, deterministic policy "
            "(arld: eval_every, num_eval_episodes; Brax: num_evals over num_timesteps, "
            "num_eval_envs, deterministic_eval=True)"
        ),
        "differences_kept": "arld_jax: prioritized replay (sum tree), fixed-size on device, "
        "compiler option xla_cpu_copy_insertion_use_region_analysis, jax of this process; Brax: "
        "uniform replay queue, alpha loss with its own actor forward, pmap over 1 device, "
        "jax 0.9.2 (venv); both tune alpha",
    }
    try:
        out["brax_venv"] = venv = ensure_brax_venv()
    except (RuntimeError, OSError, subprocess.SubprocessError) as err:
        out["error"] = f"Brax venv unavailable, nothing measured: {type(err).__name__}: {err}"
        log(f"!!! peers: {out['error'][:500]}")
        return out
    limit = float("nan")
    matmul = b.report["sections"].get("matmul", {})
    if "float32_e1" in matmul:  # only when the matmul section ran in this process
        limit = limit_updates_per_s(b, PAPER_UPDATE, HC_OBS_DIM, HC_ACTION_DIM)
    out["limit_updates_per_s_f32"] = limit
    for num_envs in ps.env_counts:
        log(f"(peers, {num_envs} env(s): Brax SAC in {venv['path']} ...)")
        brax = brax_run(venv, num_envs, ps)
        log(
            f"(peers, {num_envs} env(s): Brax {brax['env_steps_per_s']:.1f} env steps/s; arld_jax ...)"
        )
        arld = arld_peer_run(b, num_envs, ps)
        log(f"(peers, {num_envs} env(s): arld_jax {arld['env_steps_per_s']:.1f}; C physics ...)")
        arld_c = arld_peer_run(b, num_envs, ps, backend="mujoco")
        out[f"envs_{num_envs}"] = {
            "num_envs": num_envs,
            "env_steps_between_evals": ps.period_env_steps,
            "eval_episodes": ps.eval_episodes,
            "brax_env_steps_per_s": brax["env_steps_per_s"],
            "arld_env_steps_per_s": arld["env_steps_per_s"],
            "ratio_arld_over_brax": arld["env_steps_per_s"] / brax["env_steps_per_s"],
            "brax_without_eval_env_steps_per_s": brax["without_eval_env_steps_per_s"],
            "arld_without_eval_env_steps_per_s": arld["without_eval_env_steps_per_s"],
            "ratio_without_eval": arld["without_eval_env_steps_per_s"]
            / brax["without_eval_env_steps_per_s"],
            "brax_fraction_of_f32_limit": brax["env_steps_per_s"] / limit,
            "arld_fraction_of_f32_limit": arld["env_steps_per_s"] / limit,
            # The same trainer with Brax's halfcheetah stepped by MuJoCo's C engine: the same
            # model and task, other physics code than Brax's MJX (Config.backend = 'mujoco').
            "arld_mujoco_env_steps_per_s": arld_c["env_steps_per_s"],
            "ratio_arld_mujoco_over_brax": arld_c["env_steps_per_s"] / brax["env_steps_per_s"],
            "arld_mujoco_without_eval_env_steps_per_s": arld_c["without_eval_env_steps_per_s"],
            "ratio_arld_mujoco_without_eval": arld_c["without_eval_env_steps_per_s"]
            / brax["without_eval_env_steps_per_s"],
            "arld_mujoco_fraction_of_f32_limit": arld_c["env_steps_per_s"] / limit,
            "brax": brax,
            "arld": arld,
            "arld_mujoco": arld_c,
        }
        b.save()
    rows = [
        [
            f"{r['num_envs']} env(s)",
            f"{r['env_steps_between_evals']:,} / {r['eval_episodes']}",
            r["brax_env_steps_per_s"],
            r["arld_env_steps_per_s"],
            r["ratio_arld_over_brax"],
            r["brax_without_eval_env_steps_per_s"],
            r["arld_without_eval_env_steps_per_s"],
            r["ratio_without_eval"],
            f"{r['brax_fraction_of_f32_limit']:.2f} / {r['arld_fraction_of_f32_limit']:.2f}",
            r["arld_mujoco_env_steps_per_s"],
            r["ratio_arld_mujoco_over_brax"],
            r["ratio_arld_mujoco_without_eval"],
            f"{r['arld_mujoco_fraction_of_f32_limit']:.2f}",
        ]
        for r in out.values()
        if isinstance(r, dict) and "ratio_arld_over_brax" in r
    ]
    print_table(
        f"peers: Brax {venv['versions']['brax']} SAC (jax {venv['versions']['jax']}) vs arld_jax, "
        "HalfCheetah, 1 update per env step, B 256, 2x256; arld on MJX as Brax, and 'C' = arld "
        "with MuJoCo's C engine (--backend mujoco)",
        [
            "config",
            "steps/eval / episodes",
            "brax steps/s",
            "arld steps/s",
            "arld/brax",
            "brax no-eval",
            "arld no-eval",
            "arld/brax no-eval",
            "of f32 limit brax / arld",
            "arld C steps/s",
            "C/brax",
            "C/brax no-eval",
            "C of f32 limit",
        ],
        rows,
    )
    return out


# ---------------------------------------------------------------- summary


def _get(sections: dict, *path: str) -> Any:
    """sections[path[0]][path[1]]..., or nan when a section was skipped or failed."""
    node: Any = sections
    for p in path:
        if not isinstance(node, dict) or p not in node:
            return float("nan")
        node = node[p]
    return node


def print_summary(sections: dict) -> None:
    """The headline figures of every section that ran, in one table."""
    g = lambda *path: _get(sections, *path)
    env_rows = [
        [f"env only {k.replace('_', ', ')} env(s), env steps/s", v["env_steps_per_s"]]
        for k, v in sections.get("env", {}).items()
        if isinstance(v, dict) and "env_steps_per_s" in v
    ]
    seed_rows = [
        [
            f"{k.replace('_', ' ')} vmapped: total updates/s (x separate; update alone x 1 seed)",
            f"{v['total_updates_per_s']:,.0f} ({v['speedup_vs_separate_runs']:.2f}x; "
            f"{v['update_alone_speedup_vs_one_seed']:.2f}x)",
        ]
        for k, v in sections.get("seeds", {}).items()
        if isinstance(v, dict) and "total_updates_per_s" in v
    ]
    replay_rows = [
        [
            f"replay alone, capacity {v['capacity']:,}, {v['seeds']} seed(s): ms/iter per seed",
            v["ms_per_iteration_per_seed"],
        ]
        for v in sections.get("replay", {}).values()
        if isinstance(v, dict) and "ms_per_iteration_per_seed" in v
    ]
    peers = sections.get("peers", {})
    peer_rows = [
        [
            f"peers {v['num_envs']} env(s): env steps/s arld MJX / arld C / Brax (x Brax)",
            f"{v['arld_env_steps_per_s']:,.1f} / {v['arld_mujoco_env_steps_per_s']:,.1f} / "
            f"{v['brax_env_steps_per_s']:,.1f} ({v['ratio_arld_over_brax']:.2f}x / "
            f"{v['ratio_arld_mujoco_over_brax']:.2f}x)",
        ]
        for v in peers.values()
        if isinstance(v, dict) and "ratio_arld_over_brax" in v
    ]
    if "error" in peers:
        peer_rows.append(
            [
                "peers (Brax SAC vs arld_jax)",
                "ERROR " + " | ".join(peers["error"].splitlines())[:150],
            ]
        )
    rows = [
        ["matmul f32 256-wide, GFLOP/s (best)", g("flops", "matmul_gflops_f32_best")],
        ["matmul bf16-in/f32-acc 256-wide, GFLOP/s (best)", g("flops", "matmul_gflops_bf16_best")],
        ["one update B=256 2x256, GFLOP (XLA)", g("flops", "xla_cost_analysis_flops") / 1e9],
        [
            "one update B=256 2x256, GFLOP (analytic)",
            g("flops", "analytic_matmul_flops", "total") / 1e9,
        ],
        ["physical limit f32, updates/s", g("flops", "limit_updates_per_s_f32")],
        *env_rows,
        ["update only f32, updates/s", g("update", "float32", "updates_per_s")],
        ["update only f32, fraction of limit", g("update", "float32", "fraction_of_limit")],
        [
            "update only f32, fraction of limit (interleaved)",
            g("update", "float32", "fraction_of_limit_interleaved"),
        ],
        ["update only bf16, updates/s", g("update", "bfloat16", "updates_per_s")],
        [
            "update only f32 with noise draws, updates/s",
            g("update", "float32, noise draws (Noisy SAC program)", "updates_per_s"),
        ],
        ["trainer 1 env: env steps/s", g("trainer", "envs_1", "env_steps_per_s")],
        ["trainer 1 env: fraction of limit", g("trainer", "envs_1", "fraction_of_limit")],
        ["trainer 16 envs: env steps/s", g("trainer", "envs_16", "env_steps_per_s")],
        ["trainer 16 envs: fraction of limit", g("trainer", "envs_16", "fraction_of_limit")],
        *replay_rows,
        *seed_rows,
        ["first step cold, wall s", g("first_step", "cold", "wall_to_first_step_s")],
        ["first step warm, wall s", g("first_step", "warm", "wall_to_first_step_s")],
        ["replay at 1M, MiB/seed", g("memory", "replay_bytes_obs17_act6") / 2**20],
        ["TrainState at 1M, MiB/seed", g("memory", "train_state_bytes") / 2**20],
        *peer_rows,
    ]
    ran = [r for r in rows if not (isinstance(r[1], float) and math.isnan(r[1]))]
    print_table("summary (sections that ran)", ["figure", "value"], ran)


# ---------------------------------------------------------------- driver


SECTION_FUNCS: dict[str, Callable[[Bench], dict]] = {
    "matmul": section_matmul,
    "flops": section_flops,
    "env": section_env,
    "update": section_update,
    "trainer": section_trainer,
    "overlap": section_overlap,
    "replay": section_replay,
    "seeds": section_seeds,
    "first_step": section_first_step,
    "memory": section_memory,
    "peers": section_peers,
}


def run_section(b: Bench, name: str) -> None:
    """Run one section, record its result and wall time, and rewrite the JSON report."""
    log(f"\n>>> {name} ...")
    start = time.perf_counter()
    try:
        result = SECTION_FUNCS[name](b)
    except Exception as err:  # keep the other sections' figures
        log(f"!!! section {name} failed: {type(err).__name__}: {err}")
        result = {"error": f"{type(err).__name__}: {err}"}
    result["section_wall_s"] = time.perf_counter() - start
    b.report["sections"][name] = result
    b.save()
    log(f"<<< {name} done in {result['section_wall_s']:.1f} s (saved {b.out})")


def default_out(quick: bool) -> Path:
    """benchmarks/results/<host or 'cpu'>-<date>[-quick].json"""
    host = socket.gethostname() or "cpu"
    date = datetime.date.today().isoformat()
    return RESULTS_DIR / f"{host}-{date}{'-quick' if quick else ''}.json"


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="tiny sizes; toy env for the trainer")
    parser.add_argument("--skip-mjx", action="store_true", help="toy env everywhere, no MJX")
    parser.add_argument("--out", type=Path, default=None, help="JSON report path")
    parser.add_argument(
        "--only", default=None, help=f"comma-separated sections: {', '.join(SECTIONS)}"
    )
    parser.add_argument("--first-step-child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--cache-dir", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.only:
        unknown = set(args.only.split(",")) - set(SECTIONS)
        if unknown:
            parser.error(f"unknown section(s) {sorted(unknown)}; choose from {', '.join(SECTIONS)}")
    return args


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    if args.first_step_child:
        first_step_child(args)
        return
    selected = [s for s in SECTIONS if not args.only or s in args.only.split(",")]
    b = Bench(
        args=args,
        sizes=QUICK if args.quick else FULL,
        out=args.out or default_out(args.quick),
        report={"meta": machine_info(args), "sections": {}},
    )
    meta = b.report["meta"]
    log(f"arld_jax benchmark ({meta['mode']}): {meta['cpu_model']}, {meta['cpu_count']} cores")
    log(f"jax {meta['versions']['jax']}, brax {meta['versions']['brax']}; report: {b.out}")
    load = meta["load_average_at_start"][0]
    if load > 0.5 * (meta["cpus_usable"] or 1):
        log(f"WARNING: load average {load:.1f} at start: the machine is busy, figures will be low")
    start = time.perf_counter()
    for name in selected:
        if name not in b.report["sections"]:  # matmul may have run already as a dependency
            run_section(b, name)
    meta["load_average_at_end"] = list(os.getloadavg())
    meta["total_wall_s"] = time.perf_counter() - start
    b.save()
    print_summary(b.report["sections"])
    log(f"\ndone in {meta['total_wall_s']:.0f} s; report written to {b.out}")


if __name__ == "__main__":
    main()
