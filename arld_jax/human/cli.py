"""`python -m arld_jax.human` (also `python -m arld_jax.run demonstrate`): train one run with a
person as the expert, in the browser.

    python -m arld_jax.human [--port 8765] [--out DIR] [--preset human] [--FIELD VALUE ...]
    python -m arld_jax.human clone RUN_DIR_OR_DATASET --out EXPERT_DIR [--hidden_sizes 64,64]

The first starts the page's server on 127.0.0.1 (printing its address) and trains the one run the
Config describes (any `seed_sweep` field override, one value each) chunk by chunk, checkpointed like
`run.py`'s; rerunning the same command resumes, and demonstrations already given are replayed from
the dataset, not asked again. The second behaviour-clones a recorded demonstration set into an
expert for `--expert_path`. The options shared with `run.py` are `arld_jax.cli`'s.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import hashlib
import json
import logging
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np

from arld_jax import cli
from arld_jax.config import STRATEGIES, TASKS, Config
from arld_jax.driver import ChunkHooks, RunOptions, enable_compilation_cache, run_sweep
from arld_jax.envs import make_env
from arld_jax.human.dataset import DATASET_FILE, DemoDataset
from arld_jax.human.frames import action_names, task_frame
from arld_jax.human.server import ServerThread, make_app
from arld_jax.human.session import DemoSession, RunInfo
from arld_jax.sweep import REPO_ROOT, SWEEP_PRESETS, Sweep

PROG = "python -m arld_jax.human"
DEFAULT_PORT = 8765
SUMMARY = "train one run with you as the expert, in the browser"
"""The command's one line (also in `python -m arld_jax.run --help`, as `demonstrate`)."""
DESCRIPTION = cli.paragraph(
    cli.sentence(SUMMARY) + " A page on 127.0.0.1 asks for your action whenever the query "
    "strategy hands control to the expert. Rerun the same command to resume; demonstrations "
    "already given are replayed, not asked again."
)


def human_config(**overrides: Any) -> Config:
    """The `human` preset: AQSAC on HalfCheetah sized for one person's afternoon.

    One env (one cheetah to watch), one update per env step, 8k env steps, 1k warm-up, evaluation
    every 1k steps, N_r = 1k, t_query = 0.1 (the paper's best), C = 5 and a budget of 200
    demonstrated steps (40 queries: about a quarter of an hour of the person's time at 5 s a step)."""
    base: dict[str, Any] = dict(
        learning_starts=1_000,
        total_env_steps=8_000,
        replay_capacity=8_000,
        eval_every=1_000,
        num_eval_episodes=1,
        window_size=1_000,
        strategy="active",
        demo_steps=5,
        budget=200,
    )
    base.update(overrides)
    return Config(**base)


def run_info(cfg: Config) -> RunInfo:
    """What the page shows about `cfg`'s run."""
    env = make_env(cfg)
    if TASKS[cfg.env_name].pose is not None:  # a Brax task: its actuators' names
        names = tuple(action_names(cfg.env_name))
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
    frame_fn = None  # the toy tasks: the page shows the observation's numbers
    if TASKS[cfg.env_name].pose is not None:
        frame_fn = functools.partial(task_frame, cfg.env_name)
    return DemoSession(info, dataset, frame_fn=frame_fn, log=log)


def check_single_run(cfg: Config) -> None:
    """A person demonstrates one run with a strategy that asks."""
    if cfg.strategy == "none":
        asking = [s for s in STRATEGIES if s != "none"]
        raise SystemExit(f"error: --strategy none never asks the person; use {', '.join(asking)}")


def run_with_person(
    cfg: Config, out: Path, session: DemoSession, options: RunOptions
) -> dict[str, Any]:
    """Train `cfg`'s run into `out` with the person at `session` as the expert, driven as
    `options` say (chunks, early stop, figures, log); resumable.

    The driver is `arld_jax.driver.run_sweep` itself, unbatched (the person's ordered io_callback
    cannot be vmapped, and the lax.cond around it must stay a branch), so the run directory is an
    ordinary one (one run) plus the dataset; the session follows the chunks through `ChunkHooks`.
    Returns {"state": final TrainState (no run axis), "metrics", "complete", "timing"}."""
    from arld_jax.human.expert import make_human_expert  # flax.linen: only when training

    check_single_run(cfg)
    log = options.log

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
        dataclasses.replace(options, log=log),
        expert=make_human_expert(session),
        vmapped=False,
        hooks=hooks,
        record={"mode": "human"},
    )
    if result["complete"]:
        session.set_status("finished")
    return result | {"state": jax.tree.map(lambda x: x[0], result["state"])}


# ---------------------------------------------------------------- command line


def human_preset() -> Sweep:
    """AQSAC on MJX HalfCheetah sized for one person's afternoon (`human_config`): 1 env, 8k env
    steps, t_query 0.1, C 5, budget 200."""
    return Sweep(cfg=human_config(), seeds=(0,))


PRESETS = {"human": human_preset, **SWEEP_PRESETS}
"""The starting Configs a person can demonstrate: `human` (the default) and every sweep preset."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Make `parser` (a new one, or `run.py`'s `demonstrate`) this command's: its description,
    epilog and options: the page's port, the preset and run directory, how the run is driven, and
    every Config field (one value each)."""
    parser.description = DESCRIPTION
    parser.epilog = epilog(parser.prog)
    parser.usage = cli.usage("[--port PORT] [--preset NAME] [--out DIR]", lists=False)
    parser.add_argument("--port", type=int, default=DEFAULT_PORT, help="port on 127.0.0.1")
    cli.add_preset_option(parser, PRESETS, default="human")
    parser.add_argument(
        "--out", default=None, help="run directory (default: runs/demonstrate-..., from the config)"
    )
    cli.add_run_options(parser)
    cli.add_config_fields(parser, lists=False)


def epilog(prog: str) -> str:
    """The presets, and the `clone` command (parsed apart, by `clone_main`)."""
    clone = cli.paragraph(
        f"behaviour-clone the demonstrations recorded in a run directory (its {DATASET_FILE}) "
        f"into an expert for --expert_path; {prog} clone --help for its options",
        "    ",
    )
    return (
        cli.preset_listing(PRESETS)
        + "\n\nalso:\n  clone RUN_DIR_OR_DATASET --out EXPERT_DIR\n"
        + clone
    )


def build_parser(prog: str = PROG) -> argparse.ArgumentParser:
    """The command line of a person's run."""
    parser = argparse.ArgumentParser(prog=prog, formatter_class=cli.HelpFormatter)
    add_arguments(parser)
    return parser


def parse_args(argv: list[str], prog: str = PROG) -> tuple[argparse.Namespace, Config]:
    """The options and the run's Config (overrides as in `cli.apply_overrides`, one value each).
    A sweep preset other than `human` demonstrates with the active strategy unless --strategy
    says otherwise (its own may not query)."""
    parser = build_parser(prog)
    args, unknown = parser.parse_known_args(argv)
    cli.reject_unknown(parser, unknown)
    overrides = cli.field_overrides(args)
    base = PRESETS[args.preset]()
    if not isinstance(base, Sweep):
        raise SystemExit(
            f"error: preset {args.preset!r} is one program per agent; a person demonstrates one run"
        )
    sweep = cli.apply_overrides(base, overrides)
    if not isinstance(sweep, Sweep):
        raise SystemExit("error: a person demonstrates one run: give one value for --agent")
    if sweep.sweep:
        raise SystemExit(
            f"error: a person demonstrates one run: give one value for {', '.join(sweep.sweep)}"
        )
    cfg = sweep.cfg
    if args.preset != "human" and TASKS[cfg.env_name].pose and "strategy" not in overrides:
        cfg = cfg.replace(strategy="active")
    check_single_run(cfg)
    return args, cfg


def default_out(cfg: Config) -> Path:
    """runs/demonstrate-<env>-<strategy>-seed<seed>-<hash of the config>: the same command maps
    to the same directory, so rerunning it resumes."""
    text = json.dumps(dataclasses.asdict(cfg), sort_keys=True, default=str)
    digest = hashlib.sha256(text.encode()).hexdigest()[:8]
    return REPO_ROOT / "runs" / f"demonstrate-{cfg.env_name}-{cfg.strategy}-seed{cfg.seed}-{digest}"


def clone_main(argv: list[str], prog: str = PROG) -> Path:
    """`clone RUN_DIR_OR_DATASET --out DIR`: behaviour-clone a recorded demonstration set."""
    from arld_jax.human.expert import clone_expert  # flax.linen and optax: only when cloning

    parser = argparse.ArgumentParser(
        prog=f"{prog} clone",
        description="Behaviour-clone a recorded demonstration set into an expert for "
        "--expert_path.",
        formatter_class=cli.HelpFormatter,
    )
    parser.add_argument("dataset", help=f"a run directory or its {DATASET_FILE}")
    parser.add_argument("--out", required=True, help="expert directory to write")
    parser.add_argument("--hidden_sizes", default="64,64", help="the actor's hidden layers")
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


def main(argv: list[str] | None = None, prog: str = PROG) -> None:
    """Serve the page and train; Ctrl-C stops (rerun the same command to resume). `prog`: how the
    command was invoked (`python -m arld_jax.run demonstrate` also lands here)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["clone"]:
        clone_main(argv[1:], prog)
        return
    args, cfg = parse_args(argv, prog)
    out = Path(args.out) if args.out else default_out(cfg)
    enable_compilation_cache()
    options = cli.run_options(args, command=f"{prog} {' '.join(argv)}", preset=args.preset)
    log = options.log
    out.mkdir(parents=True, exist_ok=True)
    session = open_session(cfg, out, log)
    server = ServerThread(make_app(session), args.port).start()
    log(f"run directory: {out}")
    log(f"demonstration page: {server.url}  (open it in a browser on this machine)")
    result: dict[str, Any] = {}
    errors: list[BaseException] = []

    def train() -> None:
        try:
            result.update(run_with_person(cfg, out, session, options))
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
        logging.getLogger("jax._src.callback").setLevel(logging.CRITICAL)  # the expected abort
        session.close()
        worker.join()
    finally:
        server.stop()
    if errors and not session.closed:
        raise errors[0]
    if result.get("complete"):
        log(f"results in {out}; demonstrations in {out / DATASET_FILE}")
