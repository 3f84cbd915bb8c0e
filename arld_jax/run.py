"""Command line: the only impure code (timing, progress, checkpoints, files, plots).

    python -m arld_jax.run seed_sweep [--preset NAME] [--FIELD VALUE[,VALUE...]] [--seeds 0,1,2] [--out DIR]
    python -m arld_jax.run train_expert [--FIELD VALUE] [--seeds 0,1,2] [--out DIR]
    python -m arld_jax.run plot RUN_DIR

A comma-separated list for a sweepable field sweeps it inside one compiled program (vmap); the run
axis (cells x seeds) is sharded over devices when more than one is visible. The scan runs in chunks
of evaluation periods; after each chunk the complete training state is checkpointed (orbax), so
re-running the same command with the same --out resumes, and ends with results identical to an
uninterrupted run.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import difflib
import inspect
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from arld_jax import config as config_mod
from arld_jax.config import SWEEPABLE, Config
from arld_jax.sweep import (
    REPO_ROOT,
    SHIPPED_EXPERT,
    SWEEP_PRESETS,
    Sweep,
    SweepGroup,
    resolve_expert_path,
)

CHECKPOINT_DIR = "checkpoints"
METRICS_FILE = "metrics.npz"
LAYOUT_FILE = "state_layout.json"  # fingerprint of the checkpointed TrainState's tree and shapes


# ---------------------------------------------------------------- field docs and parsing


def field_docs() -> dict[str, str]:
    """Config field -> its docstring (the string literal under each field in config.py)."""
    tree = ast.parse(inspect.getsource(config_mod))
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "Config")
    docs, last = {}, None
    for node in cls.body:
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            last = node.target.id
        elif isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and last:
            docs[last] = " ".join(str(node.value.value).split())
            last = None
        else:
            last = None
    return docs


FIELDS = {f.name: f for f in dataclasses.fields(Config) if f.name != "notes"}


def parse_value(name: str, text: str) -> Any:
    """Parse one command-line value for Config field `name`, by the type of its default."""
    default = FIELDS[name].default
    try:
        if name == "hidden_sizes":
            return tuple(int(v) for v in text.replace("x", ",").split(",") if v)
        if name == "expert_path":
            return None if text.lower() in ("", "none") else text
        if isinstance(default, bool):
            if text.lower() in ("1", "true", "yes", "on"):
                return True
            if text.lower() in ("0", "false", "no", "off"):
                return False
            raise ValueError(text)
        if isinstance(default, int):
            return int(text)
        if isinstance(default, float):
            return float(text)
        return text
    except ValueError:
        kind = type(default).__name__ if default is not None else "str"
        raise SystemExit(f"error: --{name} {text!r} is not a valid {kind}") from None


def _non_negative_int(option: str, text: str) -> int:
    """An integer >= 0 from the command line, or a clear error naming the option."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise SystemExit(
            f"error: --{option} got {text!r}: expected integers >= 0"
            + (", comma-separated (e.g. --seeds 0,1,2)" if option == "seeds" else "")
        )
    return value


def apply_overrides(
    base: Sweep, overrides: dict[str, str], full_grid: bool = False
) -> Sweep | SweepGroup:
    """Apply --FIELD VALUE overrides: a comma list on a sweepable field sweeps it. `full_grid`
    keeps cells that differ only in fields their strategy ignores (see `sweep.RELEVANT_FOR`).
    A list of agent families (`--agent sac,td3`) gives a `SweepGroup`: one program per agent."""
    fields, sweep, seeds = {}, dict(base.sweep), base.seeds
    agents: tuple[str, ...] = ()
    for name, text in overrides.items():
        if name == "agent" and "," in text:
            agents = tuple(dict.fromkeys(parse_value(name, p) for p in text.split(",") if p))
            continue
        if name == "seeds":
            seeds = tuple(_non_negative_int("seeds", s) for s in text.split(",") if s.strip())
            continue
        if name == "num_seeds":
            seeds = tuple(range(_non_negative_int("num_seeds", text)))
            continue
        parts = [p for p in text.split(",")] if name != "hidden_sizes" else [text]
        values = [parse_value(name, p) for p in parts]
        if len(values) > 1:
            if name not in SWEEPABLE:
                raise SystemExit(
                    f"error: --{name} got a list ({text}) but {name} sets shapes or program structure "
                    f"and cannot be swept in one program; sweepable: {', '.join(SWEEPABLE)}"
                )
            sweep[name] = tuple(values)
        else:
            sweep.pop(name, None)
            fields[name] = values[0]
    try:
        out = Sweep(
            cfg=base.cfg.replace(**fields),
            sweep=sweep,
            seeds=seeds,
            prune=base.prune and not full_grid,
        )
        if len(agents) > 1:
            return SweepGroup.per_agent(out, agents)
        if agents:
            return dataclasses.replace(out, cfg=out.cfg.replace(agent=agents[0]))
        return out
    except ValueError as err:
        raise SystemExit(f"error: {err}") from None


def build_parser() -> argparse.ArgumentParser:
    docs = field_docs()
    parser = argparse.ArgumentParser(
        prog="python -m arld_jax.run",
        description="ARLD (SAC / Noisy SAC + expert queries) on MJX HalfCheetah.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    presets = "; ".join(
        f"{k}: {inspect.getdoc(v).splitlines()[0]}" for k, v in SWEEP_PRESETS.items()
    )
    for name, help_text in (
        ("seed_sweep", "train a sweep of runs (cells x seeds) in one compiled program"),
        ("train_expert", "train plain SAC over seeds and save the best actor as the expert"),
    ):
        p = sub.add_parser(
            name,
            help=help_text,
            description=help_text + ". A comma list on a sweepable field sweeps it (vmapped).",
            formatter_class=argparse.ArgumentDefaultsHelpFormatter,
        )
        p.add_argument(
            "--preset",
            default="default" if name == "seed_sweep" else "expert",
            choices=list(SWEEP_PRESETS) + (["expert"] if name == "train_expert" else []),
            help=f"named starting point ({presets})",
        )
        p.add_argument(
            "--out", default=None, help="output directory (resumes if it holds this run)"
        )
        p.add_argument("--seeds", default=None, help="comma-separated seeds, e.g. 0,1,2")
        p.add_argument("--num_seeds", default=None, help="seeds 0..N-1")
        p.add_argument(
            "--chunk_periods",
            type=int,
            default=None,
            help="evaluation periods per compiled chunk (checkpoint after each); default: ~10 chunks",
        )
        p.add_argument("--no_plots", action="store_true", help="skip the figures")
        p.add_argument(
            "--full_grid",
            action="store_true",
            help="keep every combination of the swept lists; by default a cell that differs only "
            "in a field its strategy ignores (b outside bernoulli, t_query outside active, C, "
            "budget and eps_demo under 'none') is trained once",
        )
        p.add_argument(
            "--stop_after_chunks",
            type=int,
            default=None,
            help="stop after this many chunks (to test resuming)",
        )
        group = p.add_argument_group("config fields (sweepable ones accept comma lists)")
        for field_name, f in FIELDS.items():
            sweepable = " [sweepable]" if field_name in SWEEPABLE else ""
            group.add_argument(
                f"--{field_name}",
                default=None,
                metavar="V",
                help=f"{docs.get(field_name, '')}{sweepable} (Config default: {f.default!r})",
            )
    plot = sub.add_parser("plot", help="(re)draw figures and summary of a run directory")
    plot.add_argument("run_dir")
    export = sub.add_parser(
        "export_expert",
        help="save the best run's actor from the latest checkpoint of a plain-SAC run as the expert",
    )
    export.add_argument("run_dir")
    export.add_argument("--out", default=None, help=f"expert directory (default {SHIPPED_EXPERT})")
    return parser


def parse_args(argv: list[str]) -> tuple[argparse.Namespace, Sweep | SweepGroup | None]:
    """Parse the command line; unknown options fail with close matches."""
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    if unknown:
        options = ["--" + n for n in FIELDS] + ["--preset", "--out", "--seeds", "--num_seeds"]
        msgs = []
        for u in unknown:
            if u.startswith("--"):
                key = u.split("=")[0]
                close = difflib.get_close_matches(key, options, n=3, cutoff=0.6)
                hint = f" (did you mean {', '.join(close)}?)" if close else ""
                msgs.append(f"unknown option {key}{hint}")
            else:
                msgs.append(f"unexpected argument {u!r}")
        parser.error("; ".join(msgs) + ". See --help for every field.")
    if args.command in ("plot", "export_expert"):
        return args, None
    overrides = {
        n: getattr(args, n)
        for n in list(FIELDS) + ["seeds", "num_seeds"]
        if getattr(args, n, None) is not None
    }
    # The expert is trained with the plain-SAC preset (3 seeds, 100k steps).
    preset = "sac" if args.preset == "expert" else args.preset
    base = SWEEP_PRESETS[preset]()
    return args, apply_overrides(base, overrides, full_grid=args.full_grid)


# ---------------------------------------------------------------- the resumable driver


def _default_out(command: str, preset: str) -> Path:
    stamp = time.strftime("%Y%m%d-%H%M%S")
    return REPO_ROOT / "runs" / f"{command}-{preset}-{stamp}"


def _check_or_write_identity(out: Path, identity: dict[str, Any]) -> bool:
    """Write config.json, or check it matches. Returns True if the directory already held this run."""
    path = out / "config.json"
    if path.exists():
        saved = json.loads(path.read_text())
        keys = ("config", "sweep", "seeds")
        old = {k: saved.get(k) for k in keys}
        new = json.loads(json.dumps({k: identity[k] for k in keys}))
        # A Config field added after the run was saved, at its default, is what the run had (new
        # fields keep the old behaviour at their default), so it does not block resuming.
        for f in set(new["config"]) - set(old["config"] or {}):
            if f in FIELDS and new["config"][f] == json.loads(json.dumps(FIELDS[f].default)):
                del new["config"][f]
        if old != new:
            diffs = []
            for k in keys:
                if k == "config":
                    diffs += [
                        f"{f}: {old[k].get(f)!r} -> {new[k].get(f)!r}"
                        for f in sorted(set(old[k]) | set(new[k]))
                        if old[k].get(f) != new[k].get(f)
                    ]
                elif old[k] != new[k]:
                    diffs.append(f"{k}: {old[k]!r} -> {new[k]!r}")
            raise SystemExit(
                f"error: {out} holds a different run ({'; '.join(diffs)}). Nothing was overwritten: "
                "use another --out, or the same settings to resume."
            )
        return True
    out.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(identity, indent=2) + "\n")
    os.replace(tmp, path)
    return False


def _save_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, path)


def _choose_chunk(num_evals: int, requested: int | None) -> int:
    if requested is not None:
        if requested < 1 or num_evals % requested:
            raise SystemExit(
                f"error: --chunk_periods {requested} must be >= 1 and divide the number of "
                f"evaluation periods ({num_evals})"
            )
        return requested
    divisors = [d for d in range(1, num_evals + 1) if num_evals % d == 0]
    return min(divisors, key=lambda d: (abs(num_evals // d - 10), d))


def run_sweep(
    sweep: Sweep,
    out: Path,
    chunk_periods: int | None = None,
    stop_after_chunks: int | None = None,
    command: str = "",
    preset: str = "",
    plots: bool = True,
    log=print,  # noqa: ANN001
) -> dict[str, Any]:
    """Train every run of `sweep` into `out`, resuming from its checkpoint if there is one.

    Returns {"metrics": {field: [R, periods, ...]}, "complete": bool, ...}."""
    import jax
    import jax.numpy as jnp
    import orbax.checkpoint as ocp
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    from arld_jax.train import jit_chunk, make_train

    cfg = sweep.cfg
    expert = None
    if sweep.needs_expert():
        expert = _expert_for(cfg)
    trainer = make_train(cfg, expert)
    identity = sweep.to_json() | {
        "preset": preset,
        "command": command,
        "expert": expert.meta if expert is not None else None,
        "devices": [str(d) for d in jax.devices()],
    }
    resumed = _check_or_write_identity(out, identity)
    (out / "runs.json").write_text(json.dumps(sweep.runs(), indent=1) + "\n")

    # Runs axis, padded to a multiple of the device count and sharded over devices.
    hps, keys = sweep.hparams_and_keys()
    num_runs = sweep.num_runs
    devices = jax.devices()
    padded = -(-num_runs // len(devices)) * len(devices)
    pad = lambda x: jnp.concatenate([x, jnp.repeat(x[-1:], padded - num_runs, 0)])  # noqa: E731
    hps, keys = jax.tree.map(pad, hps), pad(keys)
    mesh = Mesh(np.array(devices), ("runs",))
    sharding = NamedSharding(mesh, PartitionSpec("runs"))
    hps, keys = jax.device_put((hps, keys), sharding)

    chunk = _choose_chunk(cfg.num_evals, chunk_periods)
    num_chunks = cfg.num_evals // chunk
    init = jax.jit(jax.vmap(trainer.init), out_shardings=sharding)
    run_chunk = jit_chunk(trainer)

    mngr = ocp.CheckpointManager(
        (out / CHECKPOINT_DIR).absolute(),
        options=ocp.CheckpointManagerOptions(max_to_keep=2, create=True),
    )
    t0 = time.time()
    state = init(keys, hps)
    metrics: dict[str, np.ndarray] = {}
    done = 0
    layout = state_layout(state)
    if resumed and mngr.latest_step() is not None:
        done = mngr.latest_step()
        _check_layout(out, layout, done)
        abstract = jax.tree.map(ocp.utils.to_shape_dtype_struct, to_checkpoint(state))
        try:
            restored = mngr.restore(done, args=ocp.args.StandardRestore(abstract))
        except Exception as err:  # a checkpoint from before LAYOUT_FILE existed, other layout
            raise SystemExit(_layout_error(out, done, f"restoring it failed: {err}")) from None
        state = from_checkpoint(restored, state)
        saved = np.load(out / METRICS_FILE)
        metrics = {
            k: saved[k][:, : done * chunk] for k in saved.files if not k.startswith("state_")
        }
        log(
            f"resuming {out} after chunk {done}/{num_chunks} ({done * chunk * cfg.eval_every:,} env steps)"
        )
    (out / LAYOUT_FILE).write_text(json.dumps(layout) + "\n")  # the layout of what is saved below
    compile_start = time.time()
    compiled = run_chunk.lower(state, hps, jnp.int32(0), chunk).compile()
    compile_seconds = time.time() - compile_start
    log(
        f"compiled in {compile_seconds:.0f} s; {num_runs} runs x {cfg.total_env_steps:,} env steps, "
        f"{num_chunks} chunks of {chunk * cfg.eval_every:,} steps, {len(devices)} device(s)"
    )

    train_seconds = 0.0
    chunks_this_call = 0
    for c in range(done, num_chunks):
        start = time.time()
        state, m = compiled(state, hps, jnp.int32(c * chunk))
        m = jax.tree.map(lambda x: np.asarray(x)[:num_runs], m)
        train_seconds += time.time() - start
        for k, v in dataclasses.asdict(m).items():
            metrics[k] = np.concatenate([metrics[k], v], axis=1) if k in metrics else v
        samples = _state_samples(state, num_runs)
        _save_npz(out / METRICS_FILE, metrics | samples)  # before the checkpoint (see resume)
        mngr.save(c + 1, args=ocp.args.StandardSave(to_checkpoint(state)))
        mngr.wait_until_finished()
        chunks_this_call += 1
        steps_done = (c + 1) * chunk * cfg.eval_every
        rate = chunks_this_call * chunk * cfg.eval_every * num_runs / max(train_seconds, 1e-9)
        eta = (num_chunks - c - 1) * train_seconds / chunks_this_call
        latest = np.nanmean(m.eval_return[:, -1])
        log(
            f"[{c + 1}/{num_chunks}] env steps {steps_done:,}/{cfg.total_env_steps:,} per run | "
            f"{rate:,.0f} env steps/s (all runs) | ETA {eta / 60:.1f} min | "
            f"eval return {latest:.1f} (mean of runs)"
        )
        if stop_after_chunks is not None and chunks_this_call >= stop_after_chunks:
            break
    complete = metrics and metrics["eval_return"].shape[1] == cfg.num_evals
    timing = {
        "wall_seconds": time.time() - t0,
        "train_seconds": train_seconds,
        "compile_seconds": compile_seconds,
        "env_steps_per_second": (
            chunks_this_call * chunk * cfg.eval_every * num_runs / train_seconds
            if train_seconds
            else float("nan")
        ),
        "num_runs": num_runs,
        "devices": len(devices),
    }
    if complete:
        (out / "timing.json").write_text(json.dumps(timing, indent=2) + "\n")
        _write_results(out, plots, log)
    return {"metrics": metrics, "complete": bool(complete), "state": state, "timing": timing}


def _expert_for(cfg: Config):  # noqa: ANN202
    from arld_jax.envs import make_env
    from arld_jax.expert import load_expert, read_expert_meta, toy_expert

    if cfg.env_name == "toy" and cfg.expert_path is None:
        return toy_expert()
    if cfg.expert_path is None:
        raise SystemExit(
            "error: a query strategy other than 'none' needs an expert: set --expert_path "
            f"(the shipped HalfCheetah expert is {SHIPPED_EXPERT})"
        )
    try:
        path = resolve_expert_path(cfg.expert_path)
        read_expert_meta(path)  # fail fast, before building the env
        env = make_env(cfg)
        return load_expert(path, env.obs_dim, env.action_dim, cfg.expert_stochastic)
    except (FileNotFoundError, ValueError) as err:
        raise SystemExit(f"error: {err}") from None


def _is_key(x: Any) -> bool:
    import jax

    return hasattr(x, "dtype") and jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key)


def checkpoint_key(index: int) -> str:
    """The orbax key of the state's leaf number `index` (leaves in `jax.tree.leaves` order)."""
    return f"{index:05d}"


def to_checkpoint(state: Any) -> dict[str, Any]:
    """The state's leaves as a flat {index: array} dict for orbax: typed PRNG keys become their raw
    uint32 data, and zero-size leaves (orbax refuses them; e.g. MJX's empty actuator arrays) are
    left out: `from_checkpoint` takes them from a template state."""
    import jax

    leaves = jax.tree.leaves(state)
    return {
        checkpoint_key(i): jax.random.key_data(x) if _is_key(x) else x
        for i, x in enumerate(leaves)
        if x.size > 0
    }


def state_layout(state: Any) -> dict[str, Any]:
    """A fingerprint of the state's leaves: each leaf's path (field and parameter names), shape and
    dtype, in order. The checkpoint stores leaves by position, so a run saved by code with another
    state layout (e.g. before the twin critics became `q0`/`q1`) must not be restored into this one.
    Class names and static pytree data are not part of it (MJX's print with object addresses that
    change from process to process), so code that keeps the leaves keeps its runs resumable.
    The leading (runs) axis is left out: its padding depends on the device count, not the code."""
    import hashlib

    import jax

    flat, _ = jax.tree_util.tree_flatten_with_path(state)
    text = "".join(f"{jax.tree_util.keystr(path)}{x.shape[1:]}{x.dtype};" for path, x in flat)
    return {"sha256": hashlib.sha256(text.encode()).hexdigest(), "num_leaves": len(flat)}


def _layout_error(out: Path, done: int, why: str) -> str:
    return (
        f"error: {out} holds a checkpoint (chunk {done}) of a training state with another layout "
        f"than this version of arld_jax builds ({why}); it was probably written by an older version "
        "(or, if only the number of runs differs, on a different number of devices). "
        f"Nothing was overwritten: its metrics up to chunk {done} stay in {out / METRICS_FILE}. "
        "Use another --out to start afresh, or the arld_jax version that wrote it to resume."
    )


def _check_layout(out: Path, layout: dict[str, Any], done: int) -> None:
    path = out / LAYOUT_FILE
    if path.exists():
        saved = json.loads(path.read_text())
        if saved != layout:
            raise SystemExit(_layout_error(out, done, f"saved {saved}, now {layout}"))


def from_checkpoint(saved: dict[str, Any], template: Any) -> Any:
    """Inverse of `to_checkpoint`, with structure, key types and empty leaves from `template`."""
    import jax

    leaves, treedef = jax.tree.flatten(template)
    out = []
    for i, x in enumerate(leaves):
        if x.size == 0:
            out.append(x)
        else:
            data = saved[checkpoint_key(i)]
            out.append(jax.random.wrap_key_data(data) if _is_key(x) else data)
    return jax.tree.unflatten(treedef, out)


def _state_samples(state, num_runs: int) -> dict[str, np.ndarray]:  # noqa: ANN001
    out = {}
    for name in ("visited", "queried"):
        s = getattr(state, name)
        out[f"{name}_obs"] = np.asarray(s.obs)[:num_runs]
        out[f"{name}_env_step"] = np.asarray(s.env_step)[:num_runs]
        out[f"{name}_valid"] = np.asarray(s.key)[:num_runs] >= 0
    return out


def _write_results(out: Path, plots: bool, log) -> None:  # noqa: ANN001
    from arld_jax import results

    csv_path, md_path = results.write_summary(out)
    log(md_path.read_text())
    if plots:
        from arld_jax import plots as plots_mod

        for p in plots_mod.plot_all(out):
            log(f"figure: {p}")


# ---------------------------------------------------------------- commands


def train_expert(args: argparse.Namespace, sweep: Sweep, argv: list[str]) -> Path:
    """Train plain SAC over seeds, then save the best seed's actor as the expert."""
    if sweep.sweep:
        raise SystemExit("error: train_expert takes no swept fields (only --seeds)")
    sweep = dataclasses.replace(sweep, cfg=sweep.cfg.replace(strategy="none"))
    out = Path(args.out) if args.out else SHIPPED_EXPERT
    run_dir = out / "training"
    result = _run_from_args(args, sweep, run_dir, argv)
    if not result["complete"]:
        return run_dir
    return export_expert(run_dir, out)


def export_expert(run_dir: Path, out: Path) -> Path:
    """Save, as the expert, the actor of the run with the best latest evaluation return in the
    latest checkpoint of `run_dir` (a finished or a still-running plain-SAC run)."""
    import jax
    import orbax.checkpoint as ocp

    from arld_jax.envs import make_env
    from arld_jax.expert import save_expert
    from arld_jax.train import make_train

    saved = json.loads((run_dir / "config.json").read_text())
    cfg_dict = dict(saved["config"], hidden_sizes=tuple(saved["config"]["hidden_sizes"]))
    cfg = Config(**cfg_dict)
    if cfg.agent != "sac":
        raise SystemExit(
            f"error: {run_dir} trained agent {cfg.agent!r}; the expert is a SAC actor (paper A.1: "
            "a pre-trained prioritized SAC model), export a run of agent 'sac'"
        )
    mngr = ocp.CheckpointManager((run_dir / CHECKPOINT_DIR).absolute())
    step = mngr.latest_step()
    if step is None:
        raise SystemExit(f"error: {run_dir} has no checkpoint yet")
    restored = mngr.restore(step, args=ocp.args.StandardRestore())
    # Which flat leaves are the actor's: the structure of one run's TrainState (no compile).
    trainer = make_train(cfg)
    hp = config_mod.hparams_from_config(cfg)
    template = jax.eval_shape(trainer.init, jax.random.key(0), hp)
    flat, _ = jax.tree_util.tree_flatten_with_path(template)
    actor_leaves = {}
    for i, (path, _) in enumerate(flat):
        keys = jax.tree_util.keystr(path)
        if keys.startswith(".agent.actor_params"):
            actor_leaves[i] = np.asarray(restored[checkpoint_key(i)])
    metrics = np.load(run_dir / METRICS_FILE)
    periods = metrics["eval_return"].shape[1]
    latest = metrics["eval_return"][:, periods - 1]
    best = int(np.nanargmax(latest))
    actor_flat = [actor_leaves[i][best] for i in sorted(actor_leaves)]
    actor_template = template.agent.actor_params
    actor = jax.tree.unflatten(jax.tree.structure(actor_template), actor_flat)
    env = make_env(cfg)
    runs = json.loads((run_dir / "runs.json").read_text())
    env_steps = int(metrics["env_steps"][best, periods - 1])
    meta = {
        "env_name": cfg.env_name,
        "backend": cfg.backend,
        "obs_dim": env.obs_dim,
        "action_dim": env.action_dim,
        "hidden_sizes": list(cfg.hidden_sizes),
        "log_std_min": cfg.log_std_min,
        "log_std_max": cfg.log_std_max,
        "seed": runs[best]["seed"],
        "train_env_steps": env_steps,
        "run_total_env_steps": cfg.total_env_steps,
        "checkpoint_step": step,
        "eval_return": float(latest[best]),
        "eval_episodes": cfg.num_eval_episodes,
        "eval_return_all_runs": {
            f"run {r['run']} ({r['cell_label']}, seed {r['seed']})": float(ret)
            for r, ret in zip(runs, latest, strict=True)
        },
        "training_command": saved.get("command"),
        "training_run": str(run_dir),
    }
    path = save_expert(out, actor, meta)
    print(
        f"expert (seed {meta['seed']}, {env_steps:,} env steps, eval return "
        f"{meta['eval_return']:.1f}) saved to {path}"
    )
    return path


def main(argv: list[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    args, sweep = parse_args(argv)
    if args.command == "export_expert":
        export_expert(Path(args.run_dir), Path(args.out) if args.out else SHIPPED_EXPERT)
        return
    if args.command == "plot":
        run_dir = Path(args.run_dir)
        if (run_dir / GROUP_FILE).exists():
            _write_group_results(run_dir, True, print)
            return
        if not (run_dir / "config.json").exists():
            raise SystemExit(f"error: {run_dir} is not a run directory (no config.json)")
        _write_results(run_dir, True, print)
        return
    _enable_compilation_cache()
    if args.command == "train_expert":
        if isinstance(sweep, SweepGroup):
            raise SystemExit("error: train_expert trains the SAC expert: --agent takes no list")
        train_expert(args, sweep, argv)
        return
    out = Path(args.out) if args.out else _default_out(args.command, args.preset)
    if isinstance(sweep, SweepGroup):
        run_group(sweep, out, args, argv)
        return
    _run_from_args(args, sweep, out, argv)


GROUP_FILE = "group.json"
"""In the output directory of a `SweepGroup`: its members' subdirectory names and the command."""


def run_group(group: SweepGroup, out: Path, args: argparse.Namespace, argv: list[str]) -> bool:
    """Train each member of `group` (one compiled program each) into `out/<member>`, one after
    another; a finished member is not run again, an unfinished one resumes. Then the combined
    summary (`results.write_group_summary`) and figure. Returns True when all are complete."""
    out.mkdir(parents=True, exist_ok=True)
    names = [name for name, _ in group.members]
    path = out / GROUP_FILE
    if path.exists() and json.loads(path.read_text())["members"] != names:
        raise SystemExit(
            f"error: {out} holds another group of runs ({json.loads(path.read_text())['members']}, "
            f"now {names}). Nothing was overwritten: use another --out."
        )
    command = "python -m arld_jax.run " + " ".join(argv)
    path.write_text(json.dumps({"members": names, "command": command}, indent=1) + "\n")
    complete = True
    for name, sweep in group.members:
        member = out / name
        if (member / "timing.json").exists():  # written only when a run directory is complete
            print(f"{member}: complete", flush=True)
            continue
        result = _run_from_args(args, sweep, member, argv)
        complete = complete and result["complete"]
        if not complete:
            break
    if complete:
        _write_group_results(out, not args.no_plots, print)
    return complete


def _write_group_results(out: Path, plots: bool, log) -> None:  # noqa: ANN001
    from arld_jax import results

    _, md_path = results.write_group_summary(out)
    log(md_path.read_text())
    if plots:
        from arld_jax import plots as plots_mod

        log(f"figure: {plots_mod.plot_group(out)}")


def _run_from_args(
    args: argparse.Namespace, sweep: Sweep, out: Path, argv: list[str]
) -> dict[str, Any]:
    print(f"output directory: {out}", flush=True)
    result = run_sweep(
        sweep,
        out,
        args.chunk_periods,
        args.stop_after_chunks,
        command="python -m arld_jax.run " + " ".join(argv),
        preset=args.preset,
        plots=not args.no_plots,
        log=lambda *a: print(*a, flush=True),
    )
    if result["complete"]:
        print(f"results in {out}")
    else:
        print(f"stopped before the end; rerun the same command to resume: {out}")
    return result


def _enable_compilation_cache() -> None:
    """Persistent XLA compilation cache: a second run of the same program skips the compile."""
    import jax

    cache = os.environ.get("ARLD_JAX_CACHE", str(REPO_ROOT / ".jax_cache"))
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


if __name__ == "__main__":
    main()
