"""`python -m arld_jax.human`: train one run with a person as the expert, in the browser.

    python -m arld_jax.human [--port 8765] [--out DIR] [--preset human] [--FIELD VALUE ...]
    python -m arld_jax.human clone RUN_DIR_OR_DATASET --out EXPERT_DIR [--hidden_sizes 64,64]

The first starts the page's server on 127.0.0.1 (printing its address) and trains the one run the
Config describes (any `seed_sweep` field override, one value each) chunk by chunk, checkpointed like
`run.py`'s; rerunning the same command resumes, and demonstrations already given are replayed from
the dataset, not asked again. The second behaviour-clones a recorded demonstration set into an
expert for `--expert_path`.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from arld_jax.config import Config
from arld_jax.human.dataset import DATASET_FILE, DemoDataset
from arld_jax.human.session import DemoSession, RunInfo

DEFAULT_PORT = 8765


def human_config(**overrides: Any) -> Config:
    """The `human` preset: AQSAC on MJX HalfCheetah sized for one person's afternoon.

    One env (one cheetah to watch), one update per env step, 8k env steps, 1k warm-up, evaluation
    every 1k steps, N_r = 1k, t_query = 0.1 (the paper's best), C = 5 and a budget of 200
    demonstrated steps (40 queries: about a quarter of an hour of the person's time at 5 s a step)."""
    base: dict[str, Any] = dict(
        num_envs=1,
        learning_starts=1_000,
        total_env_steps=8_000,
        replay_capacity=8_000,
        eval_every=1_000,
        num_eval_episodes=1,
        window_size=1_000,
        strategy="active",
        t_query=0.1,
        demo_steps=5,
        budget=200,
    )
    base.update(overrides)
    return Config(**base)


def run_info(cfg: Config) -> RunInfo:
    """What the page shows about `cfg`'s run."""
    from arld_jax.envs import make_env

    env = make_env(cfg)
    if cfg.env_name == "halfcheetah":
        from arld_jax.human.frames import halfcheetah_action_names

        names = tuple(halfcheetah_action_names())
    else:
        names = tuple(f"a{i}" for i in range(env.action_dim))
    return RunInfo(
        env_name=cfg.env_name,
        obs_dim=env.obs_dim,
        action_dim=env.action_dim,
        action_names=names,
        strategy=cfg.strategy,
        uncertainty=cfg.uncertainty,
        demo_steps=cfg.demo_steps,
        budget=cfg.budget,
        total_env_steps=cfg.total_env_steps,
        num_envs=cfg.num_envs,
        query_prob=cfg.query_prob,
        t_query=cfg.t_query,
    )


def open_session(cfg: Config, out: Path, log: Callable[..., None] = print) -> DemoSession:
    """The session of the run in `out`, with its dataset (kept when it exists)."""
    info = run_info(cfg)
    header = {"env_name": info.env_name, "obs_dim": info.obs_dim, "action_dim": info.action_dim}
    header["action_names"] = list(info.action_names)
    dataset = DemoDataset(out / DATASET_FILE, header)
    frame_fn = None
    if cfg.env_name == "halfcheetah":
        from arld_jax.human.frames import halfcheetah_frame

        frame_fn = halfcheetah_frame
    return DemoSession(info, dataset, frame_fn=frame_fn, log=log)


def check_single_run(cfg: Config) -> None:
    """A person demonstrates one run with a strategy that asks."""
    if cfg.strategy == "none":
        raise SystemExit(
            "error: --strategy none never asks the person; use greedy, bernoulli or active"
        )


def run_with_person(
    cfg: Config,
    out: Path,
    session: DemoSession,
    chunk_periods: int | None = None,
    stop_after_chunks: int | None = None,
    command: str = "",
    preset: str = "",
    plots: bool = True,
    log: Callable[..., None] = print,
) -> dict[str, Any]:
    """Train `cfg`'s run into `out` with the person at `session` as the expert; resumable.

    The driver is `arld_jax.driver.run_sweep` itself, unbatched (the person's ordered io_callback
    cannot be vmapped, and the lax.cond around it must stay a branch), so the run directory is an
    ordinary one (one run) plus the dataset; the session follows the chunks through `ChunkHooks`.
    Returns {"state": final TrainState (no run axis), "metrics", "complete", "timing"}."""
    import jax

    from arld_jax.driver import ChunkHooks, run_sweep
    from arld_jax.human.expert import make_human_expert
    from arld_jax.sweep import Sweep

    check_single_run(cfg)

    def after_chunk(c: int, num_chunks: int, m: Any) -> None:
        done = int(np.asarray(m.env_steps)[0, -1])
        demos, latest = int(m.demos_used[0, -1]), float(m.eval_return[0, -1])
        session.set_status(
            "training",
            env_step=done,
            demos_used=demos,
            eval_return=latest,
            chunk=c + 1,
            num_chunks=num_chunks,
        )
        log(f"demonstrated {demos}/{cfg.budget} steps so far")

    def before_chunk(c: int) -> None:
        session.wait_while_paused()
        session.set_status("training")

    hooks = ChunkHooks(
        before_compile=lambda env_step: session.set_status("compiling", env_step=env_step),
        before_chunk=before_chunk,
        after_chunk=after_chunk,
        timing=lambda: {
            "asked": session.counts["asked"],
            "replayed_from_dataset": session.counts["replayed"],
        },
    )
    if len(session.dataset.records):
        log(f"{len(session.dataset.records)} demonstrated steps on record")
    result = run_sweep(
        Sweep(cfg=cfg, seeds=(cfg.seed,)),
        out,
        chunk_periods,
        stop_after_chunks,
        command=command,
        preset=preset,
        plots=plots,
        log=log,
        expert=make_human_expert(session),
        vmapped=False,
        hooks=hooks,
        record={"mode": "human"},
    )
    if result["complete"]:
        session.set_status("finished")
    return result | {"state": jax.tree.map(lambda x: x[0], result["state"])}


# ---------------------------------------------------------------- command line


def build_parser() -> argparse.ArgumentParser:
    """Options: the page's port and run.py's seed_sweep options (one value per field)."""
    from arld_jax.run import FIELDS, field_docs
    from arld_jax.sweep import SWEEP_PRESETS

    docs = field_docs()
    parser = argparse.ArgumentParser(
        prog="python -m arld_jax.human",
        description="Train one run with you as the expert: a local page asks for your action "
        "whenever the query strategy hands control to the expert.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--port", type=int, default=DEFAULT_PORT, help="port on 127.0.0.1")
    parser.add_argument(
        "--preset",
        default="human",
        choices=["human", *SWEEP_PRESETS],
        help="starting Config (human: AQSAC, 1 env, 8k steps, C 5, budget 200)",
    )
    parser.add_argument("--out", default=None, help="run directory (default: from the config)")
    parser.add_argument("--chunk_periods", type=int, default=None, help="periods per checkpoint")
    parser.add_argument("--stop_after_chunks", type=int, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--no_plots", action="store_true", help="skip the figures")
    group = parser.add_argument_group("config fields (one value each)")
    for name, f in FIELDS.items():
        group.add_argument(
            f"--{name}",
            default=None,
            metavar="V",
            help=f"{docs.get(name, '')} (default {f.default!r})",
        )
    return parser


def parse_args(argv: list[str]) -> tuple[argparse.Namespace, Config]:
    """The options and the run's Config (overrides as in run.py's `apply_overrides`)."""
    from arld_jax.run import FIELDS, apply_overrides
    from arld_jax.sweep import SWEEP_PRESETS, Sweep

    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    if unknown:
        import difflib

        options = [a for action in parser._actions for a in action.option_strings]  # noqa: SLF001
        hints = []
        for u in unknown:
            close = difflib.get_close_matches(u.split("=")[0], options, n=3, cutoff=0.6)
            hints.append(f"{u}" + (f" (did you mean {', '.join(close)}?)" if close else ""))
        parser.error("unknown argument(s): " + "; ".join(hints))
    overrides = {n: getattr(args, n) for n in FIELDS if getattr(args, n) is not None}
    base = (
        Sweep(cfg=human_config(), seeds=(0,))
        if args.preset == "human"
        else SWEEP_PRESETS[args.preset]()
    )
    sweep = apply_overrides(base, overrides)
    if not isinstance(sweep, Sweep):
        raise SystemExit("error: a person demonstrates one run: give one value for --agent")
    if sweep.sweep:
        raise SystemExit(
            f"error: a person demonstrates one run: give one value for {', '.join(sweep.sweep)}"
        )
    cfg = sweep.cfg
    if args.preset != "human" and cfg.env_name == "halfcheetah" and "strategy" not in overrides:
        cfg = cfg.replace(strategy="active")
    check_single_run(cfg)
    return args, cfg


def default_out(cfg: Config) -> Path:
    """runs/demonstrate-<env>-<strategy>-seed<seed>-<hash of the config>: the same command maps
    to the same directory, so rerunning it resumes."""
    from arld_jax.sweep import REPO_ROOT

    text = json.dumps(dataclasses.asdict(cfg), sort_keys=True, default=str)
    digest = hashlib.sha256(text.encode()).hexdigest()[:8]
    return REPO_ROOT / "runs" / f"demonstrate-{cfg.env_name}-{cfg.strategy}-seed{cfg.seed}-{digest}"


def clone_main(argv: list[str]) -> Path:
    """`clone RUN_DIR_OR_DATASET --out DIR`: behaviour-clone a recorded demonstration set."""
    from arld_jax.human.expert import clone_expert

    parser = argparse.ArgumentParser(prog="python -m arld_jax.human clone")
    parser.add_argument("dataset", help=f"a run directory or its {DATASET_FILE}")
    parser.add_argument("--out", required=True, help="expert directory to write")
    parser.add_argument("--hidden_sizes", default="64,64")
    parser.add_argument("--steps", type=int, default=2_000, help="Adam steps (full batch)")
    args = parser.parse_args(argv)
    path = Path(args.dataset)
    path = path / DATASET_FILE if path.is_dir() else path
    hidden = tuple(int(h) for h in args.hidden_sizes.replace("x", ",").split(",") if h)
    try:
        expert = clone_expert(path, args.out, hidden, args.steps)
    except (FileNotFoundError, ValueError) as err:
        raise SystemExit(f"error: {err}") from None
    print(
        f"cloned {expert.meta['num_demonstrations']} demonstrated steps (training MSE "
        f"{expert.meta['train_mse']:.4g}) into {Path(args.out).absolute()}: use --expert_path {args.out}"
    )
    return Path(args.out)


def main(argv: list[str] | None = None) -> None:
    """Serve the page and train; Ctrl-C stops (rerun the same command to resume)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["clone"]:
        clone_main(argv[1:])
        return
    from arld_jax.driver import enable_compilation_cache
    from arld_jax.human.server import ServerThread, make_app

    args, cfg = parse_args(argv)
    out = Path(args.out) if args.out else default_out(cfg)
    enable_compilation_cache()
    log = lambda *a: print(*a, flush=True)  # noqa: E731
    out.mkdir(parents=True, exist_ok=True)
    session = open_session(cfg, out, log)
    server = ServerThread(make_app(session), args.port).start()
    log(f"run directory: {out}")
    log(f"demonstration page: {server.url}  (open it in a browser on this machine)")
    result: dict[str, Any] = {}
    errors: list[BaseException] = []

    def train() -> None:
        try:
            result.update(
                run_with_person(
                    cfg,
                    out,
                    session,
                    args.chunk_periods,
                    args.stop_after_chunks,
                    command="python -m arld_jax.human " + " ".join(argv),
                    preset=args.preset,
                    plots=not args.no_plots,
                    log=log,
                )
            )
        except BaseException as err:  # reported by the main thread
            errors.append(err)
            session.set_status("error", error=str(err).splitlines()[0] if str(err) else repr(err))

    # Training runs in a worker thread: the main thread stays free for Ctrl-C, which a thread
    # blocked inside XLA (waiting for the person) would not see.
    worker = threading.Thread(target=train, name="training")
    worker.start()
    try:
        while worker.is_alive():
            worker.join(timeout=0.5)
    except KeyboardInterrupt:
        log("stopping: rerun the same command to resume (given demonstrations are kept)")
        import logging

        logging.getLogger("jax._src.callback").setLevel(logging.CRITICAL)  # the expected abort
        session.close()
        worker.join()
    finally:
        server.stop()
    if errors and not session.closed:
        raise errors[0]
    if result.get("complete"):
        log(f"results in {out}; demonstrations in {out / DATASET_FILE}")
