"""Command line: parsing and validating options into a `Sweep` (or a `SweepGroup`), then
`arld_jax.driver` trains it (chunks, checkpoints, resume) in the format of `arld_jax.rundir`.

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
import dataclasses
import difflib
import inspect
import json
import sys
import time
from pathlib import Path
from typing import Any

from arld_jax import config as config_mod
from arld_jax import driver
from arld_jax.config import BACKENDS, SWEEPABLE, Config
from arld_jax.rundir import CONFIG_FILE, GROUP_FILE
from arld_jax.sweep import (
    REPO_ROOT,
    SHIPPED_EXPERT,
    SWEEP_PRESETS,
    Sweep,
    SweepGroup,
)

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
    docs = config_mod.field_docs()
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
            epilog=(
                "Without --preset: " + inspect.getdoc(SWEEP_PRESETS["default"])
                if name == "seed_sweep"
                else None
            ),
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
            text = f"{docs.get(field_name, '')}{sweepable} (Config default: {f.default!r})"
            # argparse %-formats help strings, and a docstring may say "12%".
            group.add_argument(
                f"--{field_name}", default=None, metavar="V", help=text.replace("%", "%%")
            )
    plot = sub.add_parser("plot", help="(re)draw figures and summary of a run directory")
    plot.add_argument("run_dir")
    comp = sub.add_parser(
        "compare",
        help="two run directories, cell by cell: a - b of the mean return and P(a > b) with 95% "
        "stratified-bootstrap CIs (rliable)",
    )
    for side in ("a", "b"):
        comp.add_argument(
            f"run_dir_{side}",
            metavar=f"RUN_DIR_{side.upper()}",
            help="a run directory, or several run with different seeds, comma-separated (pooled)",
        )
    comp.add_argument(
        "--at", default="", metavar="STEPS", help="also compare at these env steps (comma list)"
    )
    comp.add_argument("--out", default=None, help="also write the table to this markdown file")
    export = sub.add_parser(
        "export_expert",
        help="save the best run's actor from the latest checkpoint of a plain-SAC run as the expert",
    )
    export.add_argument("run_dir")
    check = sub.add_parser(
        "evaluate_expert",
        help="roll out a saved expert deterministically on fresh episodes: return and gait",
    )
    check.add_argument("expert_dir", nargs="?", default=str(SHIPPED_EXPERT))
    check.add_argument("--episodes", type=int, default=10)
    check.add_argument("--seed", type=int, default=12345, help="of the initial states")
    check.add_argument(
        "--backend",
        default=None,
        choices=BACKENDS,
        help="physics to roll out in (default: the one the expert was trained in)",
    )
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
    if args.command in ("plot", "compare", "export_expert", "evaluate_expert"):
        return args, None
    overrides = {
        n: getattr(args, n)
        for n in list(FIELDS) + ["seeds", "num_seeds"]
        if getattr(args, n, None) is not None
    }
    # The expert is trained with the plain-SAC preset (3 seeds, 100k steps).
    preset = "sac" if args.preset == "expert" else args.preset
    base = SWEEP_PRESETS[preset]()
    if isinstance(base, SweepGroup):  # a group preset: the overrides apply to every member
        if "agent" in overrides:
            raise SystemExit(
                f"error: preset {preset!r} names its agents; --agent cannot change them"
            )
        members = []
        for name, member in base.members:
            swept = apply_overrides(member, overrides, full_grid=args.full_grid)
            assert isinstance(swept, Sweep)
            members.append((name, swept))
        return args, SweepGroup(tuple(members))
    return args, apply_overrides(base, overrides, full_grid=args.full_grid)


def _default_out(command: str, preset: str) -> Path:
    stamp = time.strftime("%Y%m%d-%H%M%S")
    return REPO_ROOT / "runs" / f"{command}-{preset}-{stamp}"


def require_run_dir(path: Path) -> None:
    """Exit with a clear error unless `path` holds a run (its config.json)."""
    if not (path / CONFIG_FILE).exists():
        raise SystemExit(f"error: {path} is not a run directory (no {CONFIG_FILE})")


def run_dir_list(arg: str) -> list[Path]:
    """`compare`'s RUN_DIR argument: one directory, or directories joined by commas (a directory
    whose own name holds a comma is taken whole when it exists)."""
    if Path(arg).exists() or "," not in arg:
        return [Path(arg)]
    return [Path(part) for part in arg.split(",") if part.strip()]


def compare_command(args: argparse.Namespace) -> None:
    """`compare A B [--at STEPS] [--out FILE]`: print (and write) `results.compare_runs`."""
    from arld_jax import results

    try:
        at = [int(x.replace("_", "")) for x in args.at.split(",") if x.strip()]
    except ValueError:
        msg = f"error: --at {args.at!r}: a comma list of env steps, e.g. 100000,200000"
        raise SystemExit(msg) from None
    sides = [run_dir_list(args.run_dir_a), run_dir_list(args.run_dir_b)]
    for d in sides[0] + sides[1]:
        require_run_dir(d)
    try:
        a, b = (results.pool_runs(dirs) for dirs in sides)
        rows = results.compare_runs(a, b, at)
    except ValueError as err:
        raise SystemExit(f"error: {err}") from None
    text = (
        f"# {args.run_dir_a} against {args.run_dir_b}\n\n"
        f"Command: `python -m arld_jax.run compare {args.run_dir_a} {args.run_dir_b}"
        + (f" --at {args.at}" if args.at else "")
        + "`. a − b of the mean return over seeds and the probability that a run of a scores "
        f"higher than a run of b, {results.INTERVALS}\n\n" + results.format_comparison(rows) + "\n"
    )
    print(text, end="")
    if args.out:
        Path(args.out).write_text(text)


def main(argv: list[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["demonstrate"]:  # a person as the expert, in the browser (arld_jax.human)
        from arld_jax.human import main as demonstrate_main

        demonstrate_main(argv[1:])
        return
    args, sweep = parse_args(argv)
    if args.command == "export_expert":
        driver.export_expert(Path(args.run_dir), Path(args.out) if args.out else SHIPPED_EXPERT)
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
        print(
            f"expert {r['path']} ({r['backend']}): deterministic return {r['return_mean']:.1f} ± "
            f"{r['return_ci95']:.1f} (95% CI, {r['episodes']} fresh episodes), "
            f"{100 * r['upside_down']:.1f}% of states upside down"
        )
        return
    if args.command == "compare":
        compare_command(args)
        return
    if args.command == "plot":
        run_dir = Path(args.run_dir)
        if (run_dir / GROUP_FILE).exists():
            driver.write_group_results(run_dir, True, print)
            return
        require_run_dir(run_dir)
        driver.write_results(run_dir, True, print)
        return
    driver.enable_compilation_cache()
    options = driver.RunOptions(
        chunk_periods=args.chunk_periods,
        stop_after_chunks=args.stop_after_chunks,
        command="python -m arld_jax.run " + " ".join(argv),
        preset=args.preset,
        plots=not args.no_plots,
        log=lambda *a: print(*a, flush=True),
    )
    if args.command == "train_expert":
        if isinstance(sweep, SweepGroup):
            raise SystemExit("error: train_expert trains the SAC expert: --agent takes no list")
        driver.train_expert(sweep, Path(args.out) if args.out else SHIPPED_EXPERT, options)
        return
    out = Path(args.out) if args.out else _default_out(args.command, args.preset)
    if isinstance(sweep, SweepGroup):
        driver.run_group(sweep, out, options)
        return
    driver.run_and_report(sweep, out, options)


if __name__ == "__main__":
    main()
