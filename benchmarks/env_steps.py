"""Env steps per second of every task on each physics backend, at 1 env: what a run's physics costs.

    python -m benchmarks.env_steps                           # every Brax task, both backends
    python -m benchmarks.env_steps --backends mujoco         # the C engine only (a minute)
    python -m benchmarks.env_steps --tasks hopper,ant --steps 4000 --repeats 5
    python -m benchmarks.env_steps --tasks ant --solvers default,100/50   # what a solver costs
    python -m benchmarks.env_steps --tasks ant --contacts task,all        # what contacts cost
    python -m benchmarks.env_steps --tasks ant --integrators task,rk4     # what RK4 costs

Each (task, backend) is one jitted program, compiled as the driver compiles
(`compile.compiler_options()`): a `lax.scan` of `--steps` steps of one env with uniform-random
actions, the env reset from a fresh random initial state when it falls (a `lax.cond`, as taken at
1 env: the reset runs only then), so a task that falls is timed as a run steps it. The first call
compiles (its time is reported, not counted), then `--repeats` timed calls; env steps/s =
steps / median call time. No agent, no replay: at 1 env and one update per env step a SAC update
costs about as much again or more (benchmarks/README.md), so this is an upper bound of a run's
rate. `--solvers` times each task again under other MuJoCo solver options
(`Config.solver_iterations`, `Config.solver_ls_iterations`), `--contacts` under other contacts
(`Config.contacts`) and `--integrators` under other integrators (`Config.integrator`), in the
same run, so that their ratio means something on a machine whose speed drifts. A timing: run it
on a quiet machine (the report records the load average).

The JSON report goes to benchmarks/results/<YYYY-MM-DD>-env-steps.json (or `--out`), rewritten
after each measurement, with the package versions and the machine's description
(`harness.machine_info`).
"""

from __future__ import annotations

import argparse
import datetime
import itertools
import json
import os
import shlex
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp

from arld_jax.compile import compiler_options
from arld_jax.config import SOLVER_FIELDS, Config, solver_settings
from arld_jax.envs import Env, make_env
from arld_jax.tasks import BRAX_TASKS
from benchmarks.harness import RESULTS_DIR, block, log, machine_info, print_table, repo_path

BACKENDS = ("mujoco", "mjx")
CHOICE_LISTS: dict[str, str] = {"contacts": "contacts", "integrators": "integrator"}
"""Comma-list flags of physics choices -> the `Config` field each sets; their product is timed."""
SOLVER_FORMAT = "'default' (the task's own) or ITERATIONS/LS_ITERATIONS, for example 100/50"


def parse_solvers(text: str) -> list[dict[str, int]]:
    """`--solvers`: a comma list, each item 'default' or 'I/L' -> the `Config` solver fields it
    sets ({} for 'default'). Whether a task and backend take them is `config.validate`'s job."""
    solvers = []
    for item in (t.strip() for t in text.split(",")):
        if item == "default":
            solvers.append({})
            continue
        parts = item.split("/")
        if len(parts) != len(SOLVER_FIELDS) or not all(p.isdigit() and int(p) > 0 for p in parts):
            raise ValueError(f"--solvers: got {item!r}; allowed: {SOLVER_FORMAT}")
        solvers.append(dict(zip(SOLVER_FIELDS, map(int, parts), strict=True)))
    return solvers


def rollout(env: Env, steps: int) -> Callable[[jax.Array], tuple[jax.Array, jax.Array]]:
    """The timed program: reset one env, then `steps` random steps, resetting it when it falls.
    Returns (sum of rewards, number of falls), so nothing is dead code."""

    def run(key: jax.Array) -> tuple[jax.Array, jax.Array]:
        k_reset, k_steps = jax.random.split(key)

        def body(state: Any, k: jax.Array) -> tuple[Any, tuple[jax.Array, jax.Array]]:
            k_act, k_new = jax.random.split(k)
            action = jax.random.uniform(k_act, (1, env.action_dim), minval=-1.0, maxval=1.0)
            state = env.step(state, action)
            fell = state.terminated[0] > 0
            if env.can_terminate:
                state = jax.lax.cond(fell, lambda: env.reset(k_new, 1), lambda: state)
            return state, (state.reward[0], fell)

        state = env.reset(k_reset, 1)
        _, (rewards, falls) = jax.lax.scan(body, state, jax.random.split(k_steps, steps))
        return jnp.sum(rewards), jnp.sum(falls)

    return jax.jit(run, compiler_options=compiler_options())


def measure(cfg: Config, steps: int, repeats: int) -> dict[str, Any]:
    """Compile time and env steps/s of `rollout` for `cfg`'s task, backend and solver."""
    env = make_env(cfg)
    program = rollout(env, steps)
    key = jax.random.key(0)
    start = time.perf_counter()
    compiled = program.lower(key).compile()
    compile_s = time.perf_counter() - start
    block(compiled(key))  # a first, untimed call
    times, falls = [], 0
    for r in range(repeats):
        start = time.perf_counter()
        _, fell = block(compiled(jax.random.key(r + 1)))
        times.append(time.perf_counter() - start)
        falls += int(fell)
    median = statistics.median(times)
    return {
        "task": cfg.env_name,
        "backend": cfg.backend,
        "solver": solver_settings(cfg),
        "contacts": cfg.contacts,
        "integrator": cfg.integrator,
        "obs_dim": env.obs_dim,
        "action_dim": env.action_dim,
        "steps_per_call": steps,
        "compile_s": compile_s,
        "median_s": median,
        "min_s": min(times),
        "all_s": times,
        "env_steps_per_s": steps / median,
        "us_per_step": 1e6 * median / steps,
        "falls_per_1000_steps": 1000 * falls / (steps * repeats),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.env_steps",
        description="Env steps/s of every task on each physics backend at 1 env.",
    )
    parser.add_argument("--tasks", default=",".join(BRAX_TASKS), help="comma list of tasks")
    parser.add_argument("--backends", default=",".join(BACKENDS), help="comma list of backends")
    parser.add_argument("--steps", type=int, default=2000, help="env steps per timed call")
    parser.add_argument("--repeats", type=int, default=3, help="timed calls per measurement")
    parser.add_argument(
        "--solvers",
        default="default",
        help=f"comma list of MuJoCo solver settings to time each task under, each {SOLVER_FORMAT}",
    )
    for flag, field in CHOICE_LISTS.items():
        parser.add_argument(
            f"--{flag}",
            default="task",
            help=f"comma list of `Config.{field}` values to time each task under",
        )
    parser.add_argument("--note", default="", help="a remark recorded in the report")
    parser.add_argument("--out", default=None, help="the JSON report (default: by date)")
    args = parser.parse_args(argv)
    tasks = [t for t in args.tasks.split(",") if t]
    backends = [b for b in args.backends.split(",") if b]
    try:  # every setting is checked (`Config` validates itself) before anything compiles
        cfgs = [
            Config(
                env_name=task,
                backend=backend,
                **solver,
                **dict(zip(CHOICE_LISTS.values(), c, strict=True)),
            )
            for backend in backends
            for task in tasks
            for solver in parse_solvers(args.solvers)
            for c in itertools.product(*(getattr(args, f).split(",") for f in CHOICE_LISTS))
        ]
    except ValueError as e:
        parser.error(str(e))
    date = datetime.date.today().isoformat()
    out = Path(args.out) if args.out else RESULTS_DIR / f"{date}-env-steps.json"
    info = machine_info(argparse.Namespace(quick=False, skip_mjx="mjx" not in backends))
    info["command"] = shlex.join(["python", "-m", "benchmarks.env_steps", *sys.argv[1:]])
    report: dict[str, Any] = {"machine": info, "note": args.note, "results": []}
    del report["machine"]["mode"], report["machine"]["skip_mjx"]

    def save() -> None:
        out.parent.mkdir(parents=True, exist_ok=True)
        report["machine"]["load_average_at_end"] = list(os.getloadavg())
        out.write_text(json.dumps(report, indent=2) + "\n")

    rows = []
    for cfg in cfgs:
        solver = "/".join(map(str, solver_settings(cfg).values())) or "default"
        log(
            f"{cfg.env_name} on {cfg.backend}, solver {solver}, contacts {cfg.contacts}, "
            f"integrator {cfg.integrator} ..."
        )
        r = measure(cfg, args.steps, args.repeats)
        report["results"].append(r)
        save()
        rows.append(
            [cfg.env_name, cfg.backend, solver, cfg.contacts, cfg.integrator, r["env_steps_per_s"]]
            + [r["us_per_step"]]
            + [r["compile_s"], r["falls_per_1000_steps"]]
        )
        log(f"  {r['env_steps_per_s']:,.0f} env steps/s, compiled in {r['compile_s']:.0f} s")
    print_table(
        f"env steps/s at 1 env, random actions, {args.steps} scanned steps per call",
        [
            "task",
            "backend",
            "solver",
            "contacts",
            "integrator",
            "env steps/s",
            "us/step",
            "compile s",
            "falls/1k steps",
        ],
        rows,
    )
    log(f"\nreport: {repo_path(out)}")


if __name__ == "__main__":
    main()
