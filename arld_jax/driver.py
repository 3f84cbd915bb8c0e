"""The resumable driver: trains sweeps period by period with checkpoints, exports experts.

`run_sweep` is the one place that compiles and runs a sweep (one program of one evaluation period:
`compile.jit_chunk`), printing a progress line after every period and saving after every chunk
of periods in the format of `arld_jax.rundir`; rerunning the same sweep into the same directory
resumes and ends with results identical to an uninterrupted run. `run_group` runs the
members of a `SweepGroup` (one program per agent family) one after another. The command line is
`arld_jax.run`.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from arld_jax import config as config_mod
from arld_jax.agents import REGISTRY
from arld_jax.config import Config
from arld_jax.rundir import (
    CHECKPOINT_DIR,
    CONFIG_FILE,
    GROUP_FILE,
    LAYOUT_FILE,
    METRICS_FILE,
    RUNS_FILE,
    TIMING_FILE,
    check_layout,
    check_or_write_identity,
    checkpoint_key,
    from_checkpoint,
    layout_error,
    save_npz,
    state_layout,
    state_samples,
    to_checkpoint,
)
from arld_jax.sweep import REPO_ROOT, Sweep, SweepGroup, expert_path_for, task_expert_dir


@dataclasses.dataclass(frozen=True)
class RunOptions:
    """How to drive a sweep (none of it changes what is computed)."""

    chunk_periods: int | None = None  # evaluation periods per checkpoint (None: ~10 checkpoints)
    stop_after_chunks: int | None = None  # stop early (to test resuming)
    command: str = ""  # recorded in config.json
    preset: str = ""
    plots: bool = True
    log: Callable[..., None] = print


def enable_compilation_cache() -> None:
    """Persistent XLA compilation cache: a second run of the same program skips the compile."""
    import jax

    cache = os.environ.get("ARLD_JAX_CACHE", str(REPO_ROOT / ".jax_cache"))
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


MAX_CELLS_SHOWN = 10
"""A progress line names at most this many cells (the best ones when a sweep has more)."""


def eta_seconds(
    done: int, warm: int, total: int, t_warm: float | None, t_learn: float | None
) -> float | None:
    """Seconds left of a run of `total` evaluation periods with `done` done, the first `warm` of
    them warm-up periods (`Config.warmup_periods`): the warm-up periods left at `t_warm` seconds
    each, the learning periods left at `t_learn` each (mean times measured on periods of that kind;
    None: none timed yet). None while a kind still to run has no time: warm-up periods do few or no
    gradient updates and run several times faster, so an ETA from them alone would be far short."""
    warm_left = max(warm - done, 0)
    learn_left = total - max(done, warm)
    if (warm_left and t_warm is None) or (learn_left and t_learn is None):
        return None
    return warm_left * (t_warm or 0.0) + learn_left * (t_learn or 0.0)


def _mean(xs: list[float]) -> float | None:
    return sum(xs) / len(xs) if xs else None


def format_eta(seconds: float | None) -> str:
    if seconds is None:
        return "ETA after the first learning period"
    if seconds < 60:
        return f"ETA {seconds:.0f} s"
    return f"ETA {seconds / 60:.1f} min" if seconds < 5400 else f"ETA {seconds / 3600:.1f} h"


def latest_returns(names: list[str], eval_return: np.ndarray) -> str:
    """ "SAC 12, AQSAC 340": each cell's latest evaluation return, the mean over its seeds
    (`eval_return` [runs], cell-major with as many seeds per cell), in cell order; the
    `MAX_CELLS_SHOWN` best with more cells than that."""
    per_cell = np.nanmean(np.asarray(eval_return, np.float64).reshape(len(names), -1), axis=1)
    order = range(len(names))
    if len(names) > MAX_CELLS_SHOWN:
        order = sorted(np.argsort(-per_cell, kind="stable")[:MAX_CELLS_SHOWN])
    text = ", ".join(f"{names[i]} {per_cell[i]:,.0f}" for i in order)
    if len(names) > MAX_CELLS_SHOWN:
        text += f" (the best {MAX_CELLS_SHOWN} of {len(names)} cells)"
    return text


def sweep_cell_names(sweep: Sweep) -> list[str]:
    """The sweep's cells in the paper's names (`config.cell_name`), in cell order."""
    configs = sweep.run_configs()[:: len(sweep.seeds)]  # the first run of each cell
    fields = ("strategy", "uncertainty", "query_prob", "t_query", *sweep.sweep)
    return [
        config_mod.cell_name({f: getattr(c, f) for f in fields}, sweep.sweep, c.agent)
        for c in configs
    ]


def choose_chunk(num_evals: int, requested: int | None) -> int:
    if requested is not None:
        if requested < 1 or num_evals % requested:
            raise SystemExit(
                f"error: --chunk_periods {requested} must be >= 1 and divide the number of "
                f"evaluation periods ({num_evals})"
            )
        return requested
    divisors = [d for d in range(1, num_evals + 1) if num_evals % d == 0]
    return min(divisors, key=lambda d: (abs(num_evals // d - 10), d))


@dataclasses.dataclass(frozen=True)
class ChunkHooks:
    """Calls around `run_sweep`'s chunk loop (a person's page follows the run through them)."""

    before_compile: Callable[[int], None] = lambda env_step: None  # env steps already done
    before_chunk: Callable[[int], None] = lambda chunk: None  # index of the chunk about to run
    after_chunk: Callable[[int, int, Any], None] = lambda chunk, num_chunks, metrics: None
    timing: Callable[[], dict[str, Any]] = dict  # extra entries of timing.json


def run_sweep(
    sweep: Sweep,
    out: Path,
    options: RunOptions = RunOptions(),
    *,
    expert: Any = None,
    vmapped: bool = True,
    hooks: ChunkHooks | None = None,
    record: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Train every run of `sweep` into `out` as `options` say, resuming from its checkpoint if
    there is one.

    `expert` replaces the one `cfg.expert_path` names; `vmapped=False` trains the sweep's single
    run without vmap (on a run axis of 1: the same files), for an expert that cannot be batched.
    `record`: extra entries of config.json (not part of the identity compared on resume).
    Returns {"metrics": {field: [R, periods, ...]}, "complete": bool, "state": [R, ...], ...}."""
    import jax
    import jax.numpy as jnp
    import orbax.checkpoint as ocp
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    from arld_jax.compile import jit_chunk, over_runs
    from arld_jax.train import make_train

    cfg = sweep.cfg
    hooks = hooks or ChunkHooks()
    log = options.log
    if not vmapped and sweep.num_runs != 1:
        raise ValueError(f"an unbatched run_sweep trains one run, this sweep has {sweep.num_runs}")
    if expert is None and sweep.needs_expert():
        expert = expert_for(cfg)
    if expert is not None and (note := expert_physics_note(expert.meta, cfg)):
        log(note)
    # The program's static config: the base, without actor noise draws when no run is noisy.
    trainer = make_train(sweep.program_config(), expert)
    identity = (
        sweep.to_json()
        | {
            "preset": options.preset,
            "command": options.command,
            "expert": expert.meta if expert is not None else None,
            "devices": [str(d) for d in jax.devices()],
        }
        | (record or {})
    )
    resumed = check_or_write_identity(out, identity)
    (out / RUNS_FILE).write_text(json.dumps(sweep.runs(), indent=1) + "\n")

    # Runs axis, padded to a multiple of the device count and sharded over devices.
    hps, keys = sweep.hparams_and_keys()
    num_runs = sweep.num_runs
    devices = jax.devices() if vmapped else jax.devices()[:1]
    padded = -(-num_runs // len(devices)) * len(devices)
    pad = lambda x: jnp.concatenate([x, jnp.repeat(x[-1:], padded - num_runs, 0)])  # noqa: E731
    hps, keys = jax.tree.map(pad, hps), pad(keys)
    mesh = Mesh(np.array(devices), ("runs",))
    sharding = NamedSharding(mesh, PartitionSpec("runs"))
    hps, keys = jax.device_put((hps, keys), sharding)

    chunk = choose_chunk(cfg.num_evals, options.chunk_periods)
    num_chunks = cfg.num_evals // chunk
    init = jax.jit(over_runs(trainer.init, vmapped), out_shardings=sharding)
    # One period per call, `chunk` calls per checkpoint: a progress line after every period, and
    # the same program (so the same numbers) whatever the chunk size.
    run_period = jit_chunk(trainer, vmapped=vmapped)

    mngr = ocp.CheckpointManager(
        (out / CHECKPOINT_DIR).absolute(),
        options=ocp.CheckpointManagerOptions(max_to_keep=2, create=True),
    )
    if resumed and mngr.latest_step() is None and (out / METRICS_FILE).exists():
        # A clone of a committed run, or a run whose checkpoints were removed: training again
        # from step 0 would overwrite its recorded periods at the first checkpoint.
        periods = np.load(out / METRICS_FILE)["eval_return"].shape[1]
        raise SystemExit(
            f"error: {out} holds {periods} of {cfg.num_evals} evaluation periods in {METRICS_FILE} "
            f"but no checkpoint to resume from ({CHECKPOINT_DIR}/ is empty). Nothing was "
            "overwritten: to train this run again from step 0, use another --out."
        )
    t0 = time.time()
    log(config_mod.physics_line(cfg, config_mod.jax_platform()))
    state = init(keys, hps)
    metrics: dict[str, np.ndarray] = {}
    done = 0
    layout = state_layout(state)
    if resumed and mngr.latest_step() is not None:
        done = mngr.latest_step()
        check_layout(out, layout, done)
        abstract = jax.tree.map(ocp.utils.to_shape_dtype_struct, to_checkpoint(state))
        try:
            restored = mngr.restore(done, args=ocp.args.StandardRestore(abstract))
        except Exception as err:  # a checkpoint from before LAYOUT_FILE existed, other layout
            raise SystemExit(layout_error(out, done, f"restoring it failed: {err}")) from None
        state = from_checkpoint(restored, state)
        saved = np.load(out / METRICS_FILE)
        metrics = {
            k: saved[k][:, : done * chunk] for k in saved.files if not k.startswith("state_")
        }
        log(
            f"resuming {out} after chunk {done}/{num_chunks} ({done * chunk * cfg.eval_every:,} env steps)"
        )
    (out / LAYOUT_FILE).write_text(json.dumps(layout) + "\n")  # the layout of what is saved below
    hooks.before_compile(done * chunk * cfg.eval_every)
    compile_start = time.time()
    compiled = run_period.lower(state, hps, jnp.int32(0), 1).compile()
    compile_seconds = time.time() - compile_start
    log(
        f"compiled in {compile_seconds:.0f} s; {num_runs} runs x {cfg.total_env_steps:,} env steps, "
        f"{cfg.num_evals} periods of {cfg.eval_every:,} steps ({cfg.warmup_periods} with "
        f"warm-up), a checkpoint every {chunk} period(s), {len(devices)} device(s)"
    )

    def save_chunk(c: int, parts: list[Any], state: Any) -> Any:
        """Append the chunk's periods to metrics.npz, then checkpoint (the order resuming needs)."""
        m = jax.tree.map(lambda *xs: np.concatenate(xs, axis=1), *parts)
        for k, v in dataclasses.asdict(m).items():
            metrics[k] = np.concatenate([metrics[k], v], axis=1) if k in metrics else v
        save_npz(out / METRICS_FILE, metrics | state_samples(state, num_runs))
        mngr.save(c + 1, args=ocp.args.StandardSave(to_checkpoint(state)))
        mngr.wait_until_finished()
        return m

    names = sweep_cell_names(sweep)
    timed: dict[bool, list[float]] = {True: [], False: []}  # warm-up period? -> seconds of each
    chunks_this_call = 0
    for c in range(done, num_chunks):
        hooks.before_chunk(c)
        parts = []
        for p in range(c * chunk, (c + 1) * chunk):
            start = time.time()
            state, m = compiled(state, hps, jnp.int32(p))
            m = jax.tree.map(lambda x: np.asarray(x)[:num_runs], m)  # waits for the period
            warm = p < cfg.warmup_periods
            timed[warm].append(time.time() - start)
            parts.append(m)
            last = p == (c + 1) * chunk - 1
            if last:
                m = save_chunk(c, parts, state)
            eta = eta_seconds(
                p + 1, cfg.warmup_periods, cfg.num_evals, _mean(timed[True]), _mean(timed[False])
            )
            log(
                f"period {p + 1}/{cfg.num_evals}{' (warm-up)' if warm else ''} | env steps "
                f"{(p + 1) * cfg.eval_every:,}/{cfg.total_env_steps:,} per run | "
                f"{cfg.eval_every * num_runs / max(timed[warm][-1], 1e-9):,.0f} env steps/s "
                f"(all runs) | {format_eta(eta)} | eval return "
                + latest_returns(names, parts[-1].eval_return[:, -1])
                + (f" | checkpoint {c + 1}/{num_chunks}" if last else "")
            )
        chunks_this_call += 1
        hooks.after_chunk(c, num_chunks, m)
        if options.stop_after_chunks is not None and chunks_this_call >= options.stop_after_chunks:
            break
    train_seconds = sum(timed[True]) + sum(timed[False])
    periods_this_call = len(timed[True]) + len(timed[False])
    complete = metrics and metrics["eval_return"].shape[1] == cfg.num_evals
    timing = {
        "wall_seconds": time.time() - t0,
        "train_seconds": train_seconds,
        "compile_seconds": compile_seconds,
        "env_steps_per_second": (
            periods_this_call * cfg.eval_every * num_runs / train_seconds
            if train_seconds
            else float("nan")
        ),
        "num_runs": num_runs,
        "devices": len(devices),
    } | hooks.timing()
    if complete:
        (out / TIMING_FILE).write_text(json.dumps(timing, indent=2) + "\n")
        write_results(out, options.plots, log)
    return {"metrics": metrics, "complete": bool(complete), "state": state, "timing": timing}


def _from_cwd(path: Path) -> Path:
    """`path` relative to the working directory when it lies inside it, else as given: what an
    exported expert records of its run, so that a shipped one reads the same on any machine."""
    try:
        return Path(path).resolve().relative_to(Path.cwd())
    except ValueError:
        return Path(path)


def expert_for(cfg: Config):  # noqa: ANN202
    """The expert that runs of `cfg` ask (`sweep.expert_path_for`: `--expert_path`, else the
    task's shipped one, else the toy tasks' closed-form expert), checked against the task before
    anything compiles: SystemExit with the reason when there is none or it does not fit."""
    from arld_jax.envs import make_env
    from arld_jax.expert import check_expert_task, load_expert, read_expert_meta, toy_expert

    try:
        path = expert_path_for(cfg)
        if path is None:
            return toy_expert()
        check_expert_task(read_expert_meta(path), path, cfg.env_name)  # before building the env
        env = make_env(cfg)  # traced, not compiled: its sizes
        return load_expert(path, env.obs_dim, env.action_dim, cfg.expert_stochastic, cfg.env_name)
    except (FileNotFoundError, ValueError) as err:
        raise SystemExit(f"error: {err}") from None


def write_results(out: Path, plots: bool, log) -> None:  # noqa: ANN001
    from arld_jax import compare, summary

    csv_path, md_path = summary.write_summary(out)
    log(md_path.read_text())
    comparison = compare.write_comparison(out)
    if comparison is not None:
        log(comparison.read_text())
    log(compare.plain_reading(out))
    if plots:
        from arld_jax import plots as plots_mod

        for p in plots_mod.plot_all(out):
            log(f"figure: {p}")


def run_and_report(sweep: Sweep, out: Path, options: RunOptions) -> dict[str, Any]:
    """`run_sweep` with `options`, saying where the results are or how to resume."""
    options.log(f"output directory: {out}")
    result = run_sweep(sweep, out, options)
    if result["complete"]:
        options.log(f"results in {out}")
    else:
        options.log(f"stopped before the end; rerun the same command to resume: {out}")
    return result


def train_expert(sweep: Sweep, out: Path, options: RunOptions) -> Path:
    """Train plain SAC over seeds into out/training, then save the best seed's actor in `out`."""
    if sweep.sweep:
        raise SystemExit("error: train_expert takes no swept fields (only --seeds)")
    sweep = dataclasses.replace(sweep, cfg=sweep.cfg.replace(strategy="none"))
    run_dir = out / "training"
    result = run_and_report(sweep, run_dir, options)
    if not result["complete"]:
        return run_dir
    return export_expert(run_dir, out)


def default_expert_out(env_name: str) -> Path:
    """Where `train_expert` and `export_expert` save a task's expert unless told: the task's
    expert directory (`sweep.task_expert_dir`), where its runs then find it."""
    try:
        return task_expert_dir(env_name)
    except ValueError as err:
        raise SystemExit(f"error: {err}: pass --out DIR") from None


def export_expert(run_dir: Path, out: Path | None = None) -> Path:
    """Save, as the expert, the actor of the run with the best latest evaluation return in the
    latest checkpoint of `run_dir` (a finished or a still-running plain-SAC run), into `out`
    (default: the run's task's expert directory). Its metadata records the task (`env_name`),
    which `expert.check_expert_task` checks against the runs that ask it."""
    import jax
    import orbax.checkpoint as ocp

    from arld_jax.envs import make_env
    from arld_jax.expert import save_expert
    from arld_jax.train import make_train

    saved = json.loads((run_dir / CONFIG_FILE).read_text())
    cfg_dict = dict(saved["config"], hidden_sizes=tuple(saved["config"]["hidden_sizes"]))
    cfg = Config(**cfg_dict)
    out = out if out is not None else default_expert_out(cfg.env_name)
    if not REGISTRY[cfg.agent].exports_expert:
        able = ", ".join(repr(n) for n, spec in REGISTRY.items() if spec.exports_expert)
        raise SystemExit(
            f"error: {run_dir} trained agent {cfg.agent!r}, whose actor cannot act as an expert "
            f"(paper A.1: a pre-trained prioritized SAC model); export a run of agent {able}"
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
    runs = json.loads((run_dir / RUNS_FILE).read_text())
    env_steps = int(metrics["env_steps"][best, periods - 1])
    meta = {
        "env_name": cfg.env_name,
        "backend": cfg.backend,
        **config_mod.physics_settings(cfg),
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
        "training_run": str(_from_cwd(run_dir)),
    }
    path = save_expert(out, actor, meta)
    print(
        f"expert (seed {meta['seed']}, {env_steps:,} env steps, eval return "
        f"{meta['eval_return']:.1f}) saved to {path}"
    )
    return path


def run_group(group: SweepGroup, out: Path, options: RunOptions) -> bool:
    """Train each member of `group` (one compiled program each) into `out/<member>`, one after
    another; a finished member is not run again, an unfinished one resumes. Then the combined
    summary (`summary.write_group_summary`) and figure. Returns True when all are complete."""
    out.mkdir(parents=True, exist_ok=True)
    names = [name for name, _ in group.members]
    path = out / GROUP_FILE
    if path.exists() and json.loads(path.read_text())["members"] != names:
        raise SystemExit(
            f"error: {out} holds another group of runs ({json.loads(path.read_text())['members']}, "
            f"now {names}). Nothing was overwritten: use another --out."
        )
    path.write_text(json.dumps({"members": names, "command": options.command}, indent=1) + "\n")
    complete = True
    for name, sweep in group.members:
        member = out / name
        if (member / TIMING_FILE).exists():  # written only when a run directory is complete
            options.log(f"{member}: complete")
            continue
        result = run_and_report(sweep, member, options)
        complete = complete and result["complete"]
        if not complete:
            break
    if complete:
        write_group_results(out, options.plots, options.log)
    return complete


def write_group_results(out: Path, plots: bool, log) -> None:  # noqa: ANN001
    from arld_jax import summary

    _, md_path = summary.write_group_summary(out)
    log(md_path.read_text())
    if plots:
        from arld_jax import plots as plots_mod

        path = plots_mod.plot_group(out)
        if path is not None:
            log(f"figure: {path}")


def expert_config(meta: dict[str, Any], backend: str | None = None) -> Config:
    """The Config an expert's episodes are played in: its task and the physics it was trained in
    (backend, and MuJoCo's solver options and contacts where its run set them), or the backend
    `backend`."""
    physics = {f: meta[f] for f in config_mod.PHYSICS_FIELDS if f in meta}
    return Config(
        env_name=meta["env_name"], backend=backend or meta.get("backend", "mjx"), **physics
    )


def expert_physics_note(meta: dict[str, Any], cfg: Config) -> str | None:
    """The line a run logs when its expert was trained in other physics than the run's
    (`PHYSICS_FIELDS`, read from its metadata as `expert_config` reads them), e.g. the expert of
    Gymnasium's physics asked in Brax's: allowed, since a demonstrator need not share the learner's
    simulator, but then its demonstrations play in physics it was not trained in and may fall where
    it ran. None where the two agree or the expert records no task."""
    if "env_name" not in meta:
        return None
    trained = config_mod.physics_settings(expert_config(meta))
    here = config_mod.physics_settings(cfg)
    if trained == here:
        return None

    def words(settings: dict[str, Any]) -> str:
        return " ".join(f"--{k} {v}" for k, v in sorted(settings.items())) or "Brax's own model"

    return (
        f"note: the expert was trained with {words(trained)}, this run has {words(here)}: its "
        "demonstrations play in physics it was not trained in (give the run the expert's options "
        "to ask it in its own)"
    )


def evaluate_expert(
    path: Path, episodes: int = 10, seed: int = 12345, backend: str | None = None
) -> dict[str, Any]:
    """Roll out the saved expert at `path` deterministically for `episodes` fresh episodes (new
    random initial states, seed `seed`, not a training seed) and report the mean return with its
    95% CI, every episode's return, the share of its states upside down (`env.upside_down`), the share
    of episodes that ended by a fall and their mean length.
    `backend`: the physics to roll out in (`Config.backend`); None = the one it was trained in
    (`expert_config`)."""
    import jax

    from arld_jax.envs import make_env
    from arld_jax.evaluate import rollout
    from arld_jax.expert import load_expert, read_expert_meta
    from arld_jax.stats import mean_ci95

    meta = read_expert_meta(path)
    cfg = expert_config(meta, backend)
    env = make_env(cfg)
    expert = load_expert(path, env.obs_dim, env.action_dim)

    key = jax.random.key(seed)
    act = lambda obs: expert.act(expert.params, obs, key)  # noqa: E731
    episodes_of = jax.jit(lambda k: rollout(env, act, k, episodes, cfg.episode_length))
    ev = jax.tree.map(np.asarray, episodes_of(key))
    returns = ev.episode_return
    mean, ci = mean_ci95(returns)
    return {
        "path": str(path),
        "env_name": cfg.env_name,
        "backend": cfg.backend,
        **config_mod.physics_settings(cfg),
        "episodes": episodes,
        "seed": seed,
        "return_mean": mean,
        "return_ci95": ci,
        "returns": returns.round(1).tolist(),
        "upside_down": float(ev.upside_down.mean()),
        "fell": float(ev.fell.mean()),
        "episode_length": float(ev.length.mean()),
        "meta_eval_return": meta.get("eval_return"),
    }
