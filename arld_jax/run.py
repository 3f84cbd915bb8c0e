"""Command line: every command of `python -m arld_jax.run` (COMMANDS; `--help` lists them) and
its dispatch. Parsing shared with `python -m arld_jax.human` is `arld_jax.cli`'s; a seed_sweep's
options become a `Sweep` (or a `SweepGroup`), which `arld_jax.driver` trains (chunks, checkpoints,
resume) in the format of `arld_jax.rundir`.

    python -m arld_jax.run seed_sweep [--preset NAME] [--FIELD VALUE[,VALUE...]] [--seeds 0,1,2] [--out DIR]
    python -m arld_jax.run train_expert [--FIELD VALUE] [--seeds 0,1,2] [--out DIR]
    python -m arld_jax.run demonstrate [--port 8765] [--FIELD VALUE]   (= python -m arld_jax.human)
    python -m arld_jax.run plot RUN_DIR

A comma-separated list for a sweepable field sweeps it inside one compiled program (vmap); the run
axis (cells x seeds) is sharded over devices when more than one is visible. The scan runs in chunks
of evaluation periods; after each chunk the complete training state is checkpointed (orbax), so
re-running the same command with the same --out resumes, and ends with results identical to an
uninterrupted run.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path

from arld_jax import cli, driver
from arld_jax.config import BACKENDS
from arld_jax.human import cli as human_cli
from arld_jax.rundir import CONFIG_FILE, GROUP_FILE, WRITTEN_FILES
from arld_jax.sweep import REPO_ROOT, SHIPPED_EXPERT, SWEEP_PRESETS, Sweep, SweepGroup
from arld_jax.tasks import REGISTRY as TASKS

PROG = "python -m arld_jax.run"


def expert_preset() -> Sweep:
    """The `sac` preset (plain SAC, 3 seeds, 100k env steps): how the shipped expert is trained."""
    base = SWEEP_PRESETS["sac"]()
    assert isinstance(base, Sweep)
    return base


TRAIN_PRESETS: dict[str, Callable[[], Sweep | SweepGroup]] = {
    "expert": expert_preset,
    **SWEEP_PRESETS,
}
"""`train_expert`'s presets: `expert` (its default) and every sweep preset."""

COMMANDS: dict[str, str] = {
    "seed_sweep": "train a sweep of runs (cells x seeds) in one compiled program",
    "train_expert": "train plain SAC over seeds and save the best actor as the expert",
    "demonstrate": human_cli.SUMMARY,
    "plot": "(re)draw the figures and summary of a run directory, or of several pooled (seeds "
    "run in two goes)",
    "summary": "print the summary table and the pairwise comparisons of a run directory, at "
    "its last evaluation or as if it had stopped at earlier ones (--at 100000,200000)",
    "compare": "two run directories, cell by cell: a - b of the mean return and P(a > b) with "
    "95% stratified-bootstrap CIs (rliable)",
    "export_expert": "save the best run's actor from the latest checkpoint of a plain-SAC run "
    "as the expert",
    "evaluate_expert": "roll out a saved expert deterministically on fresh episodes: return "
    "and gait",
}
"""Command -> its one-line description (the top-level --help lists them all)."""


def _add_training_arguments(p: argparse.ArgumentParser, command: str) -> None:
    """seed_sweep's and train_expert's options: preset, output, seeds, run options, fields."""
    presets = SWEEP_PRESETS if command == "seed_sweep" else TRAIN_PRESETS
    cli.add_preset_option(p, presets, default="default" if command == "seed_sweep" else "expert")
    out_help = "output directory (resumes if it holds this run)"
    if command == "train_expert":
        out_help += (
            "; default: the task's expert directory, where its runs find it (experiments/expert "
            "for halfcheetah, experiments/expert_<task> for the others)"
        )
    p.add_argument("--out", default=None, help=out_help)
    p.add_argument("--seeds", default=None, help="comma-separated seeds, e.g. 0,1,2")
    p.add_argument("--num_seeds", default=None, help="seeds 0..N-1")
    cli.add_run_options(p)
    p.add_argument(
        "--full_grid",
        action="store_true",
        help="keep every combination of the swept lists; by default a cell that differs only in "
        f"a field its strategy ignores ({cli.pruning_rule()}) is trained once",
    )
    cli.add_config_fields(p, lists=True)


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command (`demonstrate`'s options: `arld_jax.human.cli`)."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="ARLD (SAC / Noisy SAC + expert queries) on Brax's MuJoCo tasks (HalfCheetah, "
        "Hopper, Walker2d, Ant), stepped by MuJoCo's C engine on a CPU and by MJX on an "
        "accelerator (--backend).",
        epilog=f"{PROG} COMMAND --help shows a command's options.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    commands = {}
    for name, summary in COMMANDS.items():
        commands[name] = sub.add_parser(
            name,
            help=cli.escape(summary),
            description=cli.paragraph(cli.sentence(summary)),
            formatter_class=cli.HelpFormatter,
        )
    for name in ("seed_sweep", "train_expert"):
        p = commands[name]
        p.description = cli.paragraph(
            cli.sentence(COMMANDS[name]) + " A comma list on a sweepable field sweeps it (vmapped)."
        )
        p.epilog = cli.preset_listing(SWEEP_PRESETS if name == "seed_sweep" else TRAIN_PRESETS)
        p.usage = cli.usage("[--preset NAME] [--seeds S,S,...] [--out DIR]", lists=True)
        _add_training_arguments(p, name)
    human_cli.add_arguments(commands["demonstrate"])  # main hands `demonstrate` to human_cli
    commands["plot"].add_argument(
        "run_dir",
        help="a run directory, or a group's (one program per agent family), or several run "
        "directories of one experiment with different seeds, comma-separated, pooled into --out",
    )
    commands["plot"].add_argument(
        "--out", default=None, help="where several comma-separated directories are pooled"
    )
    summ = commands["summary"]
    summ.add_argument(
        "run_dir",
        help="a run directory, or several runs with different seeds, comma-separated (pooled)",
    )
    summ.add_argument(
        "--at",
        default="",
        metavar="STEPS",
        help="read at these env steps (comma list) instead of the last evaluation",
    )
    summ.add_argument("--out", default=None, help="also write the tables to this markdown file")
    comp = commands["compare"]
    for side in ("a", "b"):
        comp.add_argument(
            f"run_dir_{side}",
            metavar=f"RUN_DIR_{side.upper()}",
            help="a run directory, or several runs with different seeds, comma-separated (pooled)",
        )
    comp.add_argument(
        "--at", default="", metavar="STEPS", help="also compare at these env steps (comma list)"
    )
    comp.add_argument("--out", default=None, help="also write the table to this markdown file")
    export = commands["export_expert"]
    export.add_argument("run_dir", help="a plain-SAC run directory with a checkpoint")
    export.add_argument(
        "--out",
        default=None,
        help=f"expert directory (default: the run's task's, {SHIPPED_EXPERT} for halfcheetah)",
    )
    check = commands["evaluate_expert"]
    check.add_argument(
        "expert_dir", nargs="?", default=str(SHIPPED_EXPERT), help="a saved expert's directory"
    )
    check.add_argument(
        "--episodes", type=int, default=10, help="fresh episodes (at least 2, for the CI)"
    )
    check.add_argument("--seed", type=int, default=12345, help="of the initial states")
    check.add_argument(
        "--backend",
        default=None,
        choices=BACKENDS,
        help="physics to roll out in (default: the one the expert was trained in)",
    )
    return parser


def parse_args(argv: list[str]) -> tuple[argparse.Namespace, Sweep | SweepGroup | None]:
    """Parse the command line; unknown options fail with close matches. The Sweep (or group) is
    None for every command but seed_sweep and train_expert."""
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    cli.reject_unknown(cli.command_parser(parser, args.command), unknown)
    if args.command not in ("seed_sweep", "train_expert"):
        return args, None
    overrides = cli.field_overrides(args, extra=("seeds", "num_seeds"))
    base = TRAIN_PRESETS[args.preset]()
    if isinstance(base, SweepGroup):  # a group preset: the overrides apply to every member
        if "agent" in overrides:
            raise SystemExit(
                f"error: preset {args.preset!r} names its agents; --agent cannot change them"
            )
        members = []
        for name, member in base.members:
            swept = cli.apply_overrides(member, overrides, full_grid=args.full_grid)
            assert isinstance(swept, Sweep)
            members.append((name, swept))
        return args, SweepGroup(tuple(members))
    return args, cli.apply_overrides(base, overrides, full_grid=args.full_grid)


def _default_out(command: str, preset: str) -> Path:
    """runs/<command>-<preset>-<time stamp>: a new directory for a run not given --out."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    return REPO_ROOT / "runs" / f"{command}-{preset}-{stamp}"


def require_run_dir(path: Path) -> None:
    """Exit with a clear error unless `path` holds a run (its config.json)."""
    if not (path / CONFIG_FILE).exists():
        raise SystemExit(f"error: {path} is not a run directory (no {CONFIG_FILE})")


def require_free_out(out: str | None) -> None:
    """Exit with a clear error, before anything is computed, when the --out file of `summary` or
    `compare` would replace a file a run directory's own writers own (its summary.md, say)."""
    if out and Path(out).name in WRITTEN_FILES and (Path(out).parent / CONFIG_FILE).exists():
        raise SystemExit(
            f"error: --out {out} would replace the run directory's own {Path(out).name}; "
            "choose another name (e.g. readings.md); nothing was written"
        )


def run_dir_list(arg: str) -> list[Path]:
    """`compare`'s RUN_DIR argument: one directory, or directories joined by commas (a directory
    whose own name holds a comma is taken whole when it exists)."""
    if Path(arg).exists() or "," not in arg:
        return [Path(arg)]
    return [Path(part) for part in arg.split(",") if part.strip()]


def steps_list(text: str) -> list[int]:
    """An `--at` option: env steps, comma-separated; exits with a clear error otherwise."""
    try:
        return [int(x.replace("_", "")) for x in text.split(",") if x.strip()]
    except ValueError:
        msg = f"error: --at {text!r}: a comma list of env steps, e.g. 100000,200000"
        raise SystemExit(msg) from None


def summary_command(args: argparse.Namespace) -> None:
    """`summary RUN_DIR [--at STEPS] [--out FILE]`: print (and write) the summary table and the
    pairwise comparisons, read at the last evaluation or at each of STEPS (`rundir.read_at`)."""
    from arld_jax import compare, rundir, summary

    at = steps_list(args.at)
    require_free_out(args.out)
    dirs = run_dir_list(args.run_dir)
    for d in dirs:
        require_run_dir(d)
    try:
        run = rundir.pool_runs(dirs)
        readings = [(s, rundir.read_at(run, s)) for s in at] or [(None, run)]
    except ValueError as err:
        raise SystemExit(f"error: {err}") from None
    command = f"{PROG} summary {args.run_dir}" + (f" --at {args.at}" if args.at else "")
    parts = []
    for steps, reading in readings:
        title = f"# {run.name}" + (f", read at {steps:,} env steps" if steps else "")
        parts += [title, "", f"Printed by `{command}`.", "", summary.summary_markdown(reading)]
        if compare.comparable(reading):
            parts += [compare.comparison_markdown(reading, compare.compare(reading))]
    text = "\n".join(parts)
    print(text, end="")
    if args.out:
        Path(args.out).write_text(text)


def compare_command(args: argparse.Namespace) -> None:
    """`compare A B [--at STEPS] [--out FILE]`: print (and write) `compare.compare_runs`."""
    from arld_jax import (  # here, not at the top: scipy, which no other command needs
        compare,
        rundir,
    )

    at = steps_list(args.at)
    require_free_out(args.out)
    sides = [run_dir_list(args.run_dir_a), run_dir_list(args.run_dir_b)]
    for d in sides[0] + sides[1]:
        require_run_dir(d)
    try:
        a, b = (rundir.pool_runs(dirs) for dirs in sides)
        rows = compare.compare_runs(a, b, at)
    except ValueError as err:
        raise SystemExit(f"error: {err}") from None
    last = next(r["env_steps"] for r in rows if r["metric"] == "final return")
    text = (
        f"# {args.run_dir_a} against {args.run_dir_b}\n\n"
        f"Command: `{PROG} compare {args.run_dir_a} {args.run_dir_b}"
        + (f" --at {args.at}" if args.at else "")
        + "`. a − b of the mean return over seeds and the probability that a run of a scores "
        f"higher than a run of b, {compare.INTERVALS} Final return and AUC: at and up to "
        f"{last:,} env steps, the last evaluation both have.\n\n"
        + compare.format_comparison(rows)
        + "\n"
    )
    print(text, end="")
    if args.out:
        Path(args.out).write_text(text)


def pool_command(args: argparse.Namespace, argv: list[str]) -> None:
    """`plot A1,A2 --out DIR`: A1 and A2 (one experiment, different seeds) pooled into the run
    directory DIR, then summarised, compared and drawn there like any run."""
    from arld_jax import rundir

    sources = run_dir_list(args.run_dir)
    if args.out is None or len(sources) < 2:
        raise SystemExit(
            "error: plot pools run directories given as A1,A2 (comma-separated, at least two) "
            "into --out DIR; give both, or one run directory and no --out"
        )
    for d in sources:
        require_run_dir(d)
    out = Path(args.out)
    try:
        rundir.write_pooled(sources, out, command=f"{PROG} {' '.join(argv)}")
    except ValueError as err:
        raise SystemExit(f"error: {err}") from None
    driver.write_results(out, True, print)


def main(argv: list[str] | None = None) -> None:
    """Run the command `argv` names (default: the process's arguments)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["demonstrate"]:  # parsed as by python -m arld_jax.human (also its `clone`)
        human_cli.main(argv[1:], prog=f"{PROG} demonstrate")
        return
    args, sweep = parse_args(argv)
    if args.command == "export_expert":
        driver.export_expert(Path(args.run_dir), Path(args.out) if args.out else None)
        return
    if args.command == "evaluate_expert":
        if args.episodes < 2:
            raise SystemExit(f"error: --episodes {args.episodes}: at least 2 (for a CI)")
        try:
            r = driver.evaluate_expert(
                Path(args.expert_dir), args.episodes, args.seed, args.backend
            )
        except (FileNotFoundError, ValueError) as err:
            raise SystemExit(f"error: {err}") from None
        print(json.dumps(r, indent=1))
        spec = TASKS[r["env_name"]]
        health = []
        if spec.has_gait_rule:
            health.append(f"{100 * r['upside_down']:.1f}% of states upside down")
        if spec.can_terminate:
            health.append(
                f"{100 * r['fell']:.0f}% of episodes fell (mean length {r['episode_length']:.0f})"
            )
        print(
            f"expert {r['path']} ({r['env_name']}, {r['backend']}): deterministic return "
            f"{r['return_mean']:.1f} ± {r['return_ci95']:.1f} (95% CI, {r['episodes']} fresh "
            "episodes)" + "".join(", " + h for h in health)
        )
        return
    if args.command == "compare":
        compare_command(args)
        return
    if args.command == "summary":
        summary_command(args)
        return
    if args.command == "plot":
        if args.out is not None or len(run_dir_list(args.run_dir)) > 1:
            pool_command(args, argv)
            return
        run_dir = Path(args.run_dir)
        if (run_dir / GROUP_FILE).exists():
            driver.write_group_results(run_dir, True, print)
            return
        require_run_dir(run_dir)
        driver.write_results(run_dir, True, print)
        return
    driver.enable_compilation_cache()
    options = cli.run_options(args, command=f"{PROG} {' '.join(argv)}", preset=args.preset)
    if args.command == "train_expert":
        if isinstance(sweep, SweepGroup):
            raise SystemExit("error: train_expert trains the SAC expert: --agent takes no list")
        out = Path(args.out) if args.out else driver.default_expert_out(sweep.cfg.env_name)
        driver.train_expert(sweep, out, options)
        return
    out = Path(args.out) if args.out else _default_out(args.command, args.preset)
    if isinstance(sweep, SweepGroup):
        driver.run_group(sweep, out, options)
        return
    driver.run_and_report(sweep, out, options)


if __name__ == "__main__":
    main()
