"""Argument parsing shared by the command lines: `python -m arld_jax.run` (`run.py` dispatches its
commands) and `python -m arld_jax.human` (`human/cli.py`, also `run.py demonstrate`).

What both need lives here once: an option per Config field, its help from the field's docstring in
config.py; values parsed by the type of the field's default, comma lists on sweepable fields
becoming swept fields (`apply_overrides`); the named presets; the options of how a run is driven
(`driver.RunOptions`); and unknown options refused with their close matches. This module imports
config, sweep and driver (for `RunOptions`) only, never `run` or `human`, so either command line
can import it.
"""

from __future__ import annotations

import argparse
import dataclasses
import difflib
import inspect
import re
import textwrap
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from arld_jax import config as config_mod
from arld_jax.config import FIELDS, STRATEGIES, SWEEPABLE
from arld_jax.driver import RunOptions
from arld_jax.sweep import RELEVANT_FOR, Sweep, SweepGroup


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Each option's default in its help (but for None, "" and a flag's False: not given, which
    the help text then explains), and descriptions and epilogs printed with their own line breaks
    (`paragraph` and `listing` wrap them)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.default is None or action.default == "" or action.default is False:
            return action.help
        return super()._get_help_string(action)


def escape(text: str) -> str:
    """`text` for an argparse help string: argparse %-formats every help string (not descriptions
    or epilogs without "%(prog)"), and a docstring may say "95%"."""
    return text.replace("%", "%%")


def paragraph(text: str, indent: str = "", hang: str = "") -> str:
    """`text` wrapped at 78 columns, its lines indented by `indent` and all but the first by
    `hang` more (descriptions and epilogs keep their line breaks)."""
    words = " ".join(text.split())
    return textwrap.fill(words, 78, initial_indent=indent, subsequent_indent=indent + hang)


def first_sentence(doc: str) -> str:
    """The first sentence of a docstring's first paragraph (a period followed by a capital)."""
    first = " ".join(doc.split("\n\n")[0].split())
    return re.split(r"(?<=\.)\s+(?=[A-Z])", first)[0]


def sentence(text: str) -> str:
    """`text` as a sentence: a capital first letter and a full stop."""
    return text[:1].upper() + text[1:] + ("" if text.endswith(".") else ".")


def listing(title: str, entries: Mapping[str, str]) -> str:
    """`title:` then one wrapped, indented paragraph per entry, for an epilog."""
    return "\n".join(
        [f"{title}:"] + [paragraph(f"{k}: {v}", "  ", "  ") for k, v in entries.items()]
    )


# ---------------------------------------------------------------- Config fields


def usage(options: str, lists: bool) -> str:
    """A usage line for a command with these `options` and the Config field options (the help
    lists each field; argparse's own usage would name all of them)."""
    fields = "[--FIELD V[,V...] ...]" if lists else "[--FIELD V ...]"
    return f"%(prog)s [-h] {options}\n       [options] {fields}"


def add_config_fields(parser: argparse.ArgumentParser, lists: bool) -> None:
    """One `--FIELD V` option per Config field, documented by its docstring; `lists`: the command
    takes comma lists on sweepable fields (marked [sweepable]), else one value each."""
    docs = config_mod.field_docs()
    title = "config fields " + (
        "(sweepable ones accept comma lists)" if lists else "(one value each)"
    )
    group = parser.add_argument_group(title)
    for name, f in FIELDS.items():
        mark = " [sweepable]" if lists and name in SWEEPABLE else ""
        text = f"{docs.get(name, '')}{mark} (Config default: {f.default!r})"
        group.add_argument(f"--{name}", default=None, metavar="V", help=escape(text))


def field_overrides(args: argparse.Namespace, extra: Iterable[str] = ()) -> dict[str, str]:
    """The Config field options (and the `extra` ones) given on the command line, as text."""
    names = [*FIELDS, *extra]
    return {n: getattr(args, n) for n in names if getattr(args, n, None) is not None}


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


def non_negative_int(option: str, text: str) -> int:
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
    A list of agent families (`--agent sac,td3`) gives a `SweepGroup`: one program per agent.
    `seeds` (a comma list) and `num_seeds` (N: seeds 0..N-1) replace the base's seeds."""
    fields, sweep, seeds = {}, dict(base.sweep), base.seeds
    agents: tuple[str, ...] = ()
    for name, text in overrides.items():
        if name == "agent" and "," in text:
            agents = tuple(dict.fromkeys(parse_value(name, p) for p in text.split(",") if p))
            continue
        if name == "seeds":
            seeds = tuple(non_negative_int("seeds", s) for s in text.split(",") if s.strip())
            continue
        if name == "num_seeds":
            seeds = tuple(range(non_negative_int("num_seeds", text)))
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


def pruning_rule() -> str:
    """Which swept fields each strategy ignores (`sweep.RELEVANT_FOR`), in words: "query_prob
    outside bernoulli, ..., demo_steps/budget/eps_demo under none"."""
    groups: dict[tuple[str, ...], list[str]] = {}
    for name, strategies in RELEVANT_FOR.items():
        groups.setdefault(strategies, []).append(name)
    parts = []
    for strategies, names in groups.items():
        others = [s for s in STRATEGIES if s not in strategies]
        where = (
            f"outside {'/'.join(strategies)}"
            if len(strategies) <= len(others)
            else f"under {'/'.join(others)}"
        )
        parts.append(f"{'/'.join(names)} {where}")
    return ", ".join(parts)


# ---------------------------------------------------------------- presets and run options


def add_preset_option(
    parser: argparse.ArgumentParser, presets: Mapping[str, Callable[..., Any]], default: str
) -> None:
    """`--preset NAME` choosing among `presets` (name -> function; its docstring describes it)."""
    parser.add_argument(
        "--preset", default=default, choices=list(presets), help="named starting point (below)"
    )


def preset_listing(presets: Mapping[str, Callable[..., Any]]) -> str:
    """An epilog naming each preset with the first sentence of its docstring."""
    return listing(
        "presets", {k: first_sentence(inspect.getdoc(v) or "") for k, v in presets.items()}
    )


def add_run_options(parser: argparse.ArgumentParser) -> None:
    """The options of `driver.RunOptions` a person sets: chunking, stopping early, figures."""
    parser.add_argument(
        "--chunk_periods",
        type=int,
        default=None,
        help="evaluation periods per chunk (a checkpoint after each); default: ~10 chunks",
    )
    parser.add_argument(
        "--stop_after_chunks",
        type=int,
        default=None,
        help="stop after this many chunks (to test resuming)",
    )
    parser.add_argument("--no_plots", action="store_true", help="skip the figures")


def log(*parts: Any) -> None:
    """The command lines' log: print, flushed (progress shows at once when piped to a file)."""
    print(*parts, flush=True)


def run_options(args: argparse.Namespace, command: str, preset: str) -> RunOptions:
    """`driver.RunOptions` from the options `add_run_options` added; `command` is recorded in the
    run directory."""
    return RunOptions(
        chunk_periods=args.chunk_periods,
        stop_after_chunks=args.stop_after_chunks,
        command=command,
        preset=preset,
        plots=not args.no_plots,
        log=log,
    )


# ---------------------------------------------------------------- unknown options


def command_parser(parser: argparse.ArgumentParser, command: str) -> argparse.ArgumentParser:
    """The parser of `parser`'s subcommand `command` (argparse keeps its subparsers in the private
    `_actions`; there is no public accessor)."""
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[command]


def option_strings(parser: argparse.ArgumentParser) -> list[str]:
    """Every option `parser` accepts (kept in argparse's private `_actions`, as above)."""
    return [s for a in parser._actions for s in a.option_strings]


def reject_unknown(parser: argparse.ArgumentParser, unknown: list[str]) -> None:
    """Exit (status 2, through `parser.error`) naming each unknown argument, with the close
    matches among `parser`'s options for a misspelt option (the word after one, its value, is
    not named again); nothing happens when `unknown` is empty."""
    if not unknown:
        return
    options, msgs, after_option = option_strings(parser), [], False
    for u in unknown:
        if u.startswith("-"):
            key = u.split("=")[0]
            close = difflib.get_close_matches(key, options, n=3, cutoff=0.6)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            msgs.append(f"unknown option {key}{hint}")
            after_option = "=" not in u
        elif after_option:
            after_option = False
        else:
            msgs.append(f"unexpected argument {u!r}")
    parser.error("; ".join(msgs) + ". See --help for every option.")
