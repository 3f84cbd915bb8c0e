"""Pairwise comparisons of the paper's strategies across seeds (AQSAC - BQSAC, AQSAC - SAC, ...:
the differences of final, late and AUC return with Welch's and the stratified bootstrap's 95%
intervals, and the probability of improvement), of two run directories cell by cell, and the
plain-language reading.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from arld_jax.config import STRATEGIES, UNCERTAINTIES, paper_name
from arld_jax.rundir import (
    COMPARISON_CSV,
    COMPARISON_MD,
    FIGURES_DIR,
    SUMMARY_MD,
    Cell,
    RunDir,
    as_run,
    env_steps_axis,
    evaluation_index,
    expert_return,
    group_cells,
    run_field,
    swept_fields,
)
from arld_jax.stats import (
    BOOTSTRAP_REPS,
    area_under_curve,
    bootstrap_difference,
    late_return,
    late_window,
    welch_ci95,
)
from arld_jax.summary import cell_name, has_falls, summarize


def comparison_pairs(run: RunDir) -> list[tuple[str, Cell, Cell]]:
    """The comparisons the paper draws, as (name, cell a, cell b) meaning "a minus b": for each
    uncertainty measure every active cell against every Bernoulli, greedy and no-query cell (the
    passive strategies and no demonstrations that Fig. 1 says ARLD can fall behind), and for each
    strategy intrinsic against extrinsic (the cells alike in every other swept field). Named
    after the run's agent family (AQSAC - BQSAC for SAC, AQTD3 - BQTD3 for TD3); where a strategy
    has several cells (BQSAC with b 0.1 and 0.2), each side by its cell's name (BQSAC b=0.2)."""
    agent = run.agent
    by_key: dict[tuple[str, str], list[Cell]] = {}
    for cell in group_cells(run):
        strategy = run_field(run, cell.runs[0], "strategy", "none")
        uncertainty = run_field(run, cell.runs[0], "uncertainty", "intrinsic")
        by_key.setdefault((strategy, uncertainty), []).append(cell)

    def name(cell: Cell, strategy: str, uncertainty: str) -> str:
        if len(by_key[(strategy, uncertainty)]) == 1:
            return paper_name(strategy, agent, uncertainty)
        return cell_name(run, cell)

    pairs = []
    for u in UNCERTAINTIES:
        for a in by_key.get(("active", u), []):
            for other in ("bernoulli", "greedy", "none"):
                for b in by_key.get((other, u), []):
                    pairs.append((f"{name(a, 'active', u)} - {name(b, other, u)}", a, b))
    others = [f for f in swept_fields(run) if f not in ("strategy", "uncertainty")]
    for s in STRATEGIES[::-1]:
        for a in by_key.get((s, "intrinsic"), []):
            for b in by_key.get((s, "extrinsic"), []):
                alike = all(
                    run_field(run, a.runs[0], f) == run_field(run, b.runs[0], f) for f in others
                )
                if alike or len(by_key[(s, "intrinsic")]) == len(by_key[(s, "extrinsic")]) == 1:
                    pairs.append((f"{name(a, s, 'intrinsic')} - {name(b, s, 'extrinsic')}", a, b))
    return pairs


def reading_steps(run: RunDir) -> list[int]:
    """The env steps at which `compare` also reads every pair, besides the last evaluation: a
    quarter, half and three quarters of the run's length (100k, 200k and 300k of a 400k run),
    where evaluated and present, so that a reader sees whether the ranking changes with the length
    of the run."""
    total = int(run.cfg.get("total_env_steps") or 0)
    steps = [int(s) for s in env_steps_axis(run)]
    return [at for at in (total // 4, total // 2, 3 * total // 4) if at in steps[:-1]]


def late_evaluations(run: RunDir) -> int:
    """How many of `run`'s last evaluations its late return averages (`stats.late_window`)."""
    return late_window(len(env_steps_axis(run)))


def late_return_label(run: RunDir) -> str:
    """The late return's metric name, with the env steps of its first and last evaluation."""
    steps = env_steps_axis(run)
    k = late_evaluations(run)
    return f"late return ({int(steps[-k]):,} to {int(steps[-1]):,})"


def compare(run_dir: str | Path | RunDir, reps: int = BOOTSTRAP_REPS, seed: int = 0) -> list[dict]:
    """Pairwise differences of `comparison_pairs` with stratified-bootstrap 95% CIs (rliable's,
    Agarwal et al. 2021): for the final, the late (`stats.late_return`) and the area-under-curve
    return, and the return at each of `reading_steps`, the difference of the cells' means over
    seeds and the probability that a run of a beats a run of b. Rows: pair, metric and the keys of
    `bootstrap_difference`."""
    run = as_run(run_dir)
    eval_return = np.asarray(run.metrics["eval_return"], dtype=np.float64)
    steps = [int(s) for s in env_steps_axis(run)]
    values = {f"return at {at:,}": eval_return[:, steps.index(at)] for at in reading_steps(run)}
    values["final return"] = eval_return[:, -1]
    if late_evaluations(run):
        values[late_return_label(run)] = late_return(eval_return)
    values["AUC"] = area_under_curve(eval_return, env_steps_axis(run))

    rows = []
    for name, a, b in comparison_pairs(run):
        for metric, v in values.items():
            rows.append(
                dict(pair=name, metric=metric)
                | bootstrap_difference(v[a.runs], v[b.runs], reps, seed)
            )
    return rows


def compare_runs(
    dir_a: str | Path | RunDir,
    dir_b: str | Path | RunDir,
    at_steps: Sequence[int] = (),
    reps: int = BOOTSTRAP_REPS,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """Cells of two run directories compared as `compare` compares cells of one: a − b of the mean
    return over seeds and P(a > b), with 95% stratified-bootstrap CIs (`bootstrap_difference`).

    Pairs: cells with the same label in both, or the only cell of each when each has one. Metrics:
    the return at each of `at_steps` env steps, at the last evaluation both have ("final return"),
    and the AUC over the evaluations both have. Raises ValueError, naming both, when the
    directories evaluate at different steps, share no cell, or miss a step of `at_steps`.
    Either side may be several directories of one experiment pooled by `pool_runs`.
    Rows: pair, metric, env_steps and the keys of `bootstrap_difference`."""
    a, b = as_run(dir_a), as_run(dir_b)
    every_a, every_b = a.cfg.get("eval_every"), b.cfg.get("eval_every")
    if every_a != every_b:
        raise ValueError(
            f"{a.where} evaluates every {every_a} env steps and {b.where} every {every_b}: "
            "their curves cannot be compared point by point"
        )
    periods = min(a.periods, b.periods)
    if periods == 0:
        raise ValueError(f"{a.where if a.periods == 0 else b.where} has no evaluation yet")
    steps = env_steps_axis(a)[:periods]
    cells_a, cells_b = group_cells(a), group_cells(b)
    if len(cells_a) == len(cells_b) == 1:
        pairs = [(cells_a[0], cells_b[0])]
    else:
        by_label = {c.cell_label: c for c in cells_b}
        pairs = [(c, by_label[c.cell_label]) for c in cells_a if c.cell_label in by_label]
    if not pairs:
        raise ValueError(
            f"no cell label is in both {a.where} ({[c.cell_label for c in cells_a]}) and "
            f"{b.where} ({[c.cell_label for c in cells_b]})"
        )
    ret_a = np.asarray(a.metrics["eval_return"], np.float64)[:, :periods]
    ret_b = np.asarray(b.metrics["eval_return"], np.float64)[:, :periods]
    metrics: list[tuple[str, int, Callable[[np.ndarray], np.ndarray]]] = []
    for at in at_steps:
        i = evaluation_index(steps, at)
        metrics.append((f"return at {at:,}", at, lambda r, i=i: r[:, i]))
    metrics.append(("final return", int(steps[-1]), lambda r: r[:, -1]))
    metrics.append(("AUC", int(steps[-1]), lambda r: area_under_curve(r, steps)))
    rows = []
    for ca, cb in pairs:
        name = f"{a.name}:{ca.cell_label or 'base'} − {b.name}:{cb.cell_label or 'base'}"
        for metric, at, value in metrics:
            x, y = value(ret_a[ca.runs]), value(ret_b[cb.runs])
            rows.append(
                dict(pair=name, metric=metric, env_steps=at)
                | bootstrap_difference(x, y, reps, seed)
            )
    return rows


INTERVALS = (
    "each with a 95% stratified-bootstrap CI (rliable's percentile method, "
    f"{BOOTSTRAP_REPS:,} resamples of the seeds, numpy seed 0), and the difference's Welch t 95% "
    "CI. With 5 seeds per side the bootstrap interval of a difference is too narrow: where there "
    "was no difference it excluded 0 in 12% of simulated pairs, not 5% (Welch's: 5%; "
    "`experiments/stats/interval_coverage.md`). Read a difference as separated when Welch's "
    "interval excludes 0."
)
"""What `format_comparison`'s intervals are and how to read them (above every comparison table)."""


def format_comparison(rows: list[dict[str, Any]]) -> str:
    """A markdown table of `compare_runs` rows."""
    lines = [
        "| a − b | metric | seeds | difference [bootstrap 95% CI] | Welch t 95% CI "
        "| P(a > b) [95% CI] |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['pair']} | {r['metric']} | {r['n_a']} / {r['n_b']} | "
            f"{r['diff']:,.0f} [{r['diff_lo']:,.0f}, {r['diff_hi']:,.0f}] | "
            f"[{r['welch_lo']:,.0f}, {r['welch_hi']:,.0f}] | "
            f"{r['p_improve']:.2f} [{r['p_lo']:.2f}, {r['p_hi']:.2f}] |"
        )
    return "\n".join(lines)


def comparable(run: RunDir) -> bool:
    """Whether `run` has pairs to compare (`comparison_pairs`) and an evaluation to compare at."""
    return bool(comparison_pairs(run)) and run.periods > 0


def write_comparison(run_dir: str | Path | RunDir) -> Path | None:
    """comparison.md (and .csv) of `compare`, or None when the run has no such pairs."""
    run = as_run(run_dir)
    if not comparable(run):
        return None
    rows = compare(run)
    with (run.path / COMPARISON_CSV).open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    path = run.path / COMPARISON_MD
    path.write_text(comparison_markdown(run, rows))
    return path


def comparison_markdown(run: RunDir, rows: list[dict[str, Any]]) -> str:
    """comparison.md's text: what the numbers are, at which env steps, then `rows` as a table."""
    k = late_evaluations(run)
    lines = [
        f"# Pairwise comparison: {run.name}",
        "",
        "a − b: the difference of the cells' mean returns over seeds, and the probability that a "
        f"run of a scores higher than a run of b (Agarwal et al. 2021), {INTERVALS} "
        "At the last evaluation present: "
        f"{int(env_steps_axis(run)[-1]):,} "
        "env steps"
        + "".join(f"; also at {at:,}" for at in reading_steps(run))
        + "."
        + (
            f" Late return: each run's mean return over its last {k} evaluations (the last "
            "tenth of those present), less swayed than the final return by the policy's swings "
            "from one evaluation to the next."
            if k
            else ""
        )
        + (" **Partial run directory.**" if run.partial else ""),
        "",
        format_comparison(rows),
    ]
    return "\n".join(lines) + "\n"


def _interval(row: dict[str, Any]) -> tuple[float, float]:
    half = row["final_return_ci95"]
    half = half if math.isfinite(half) else 0.0
    return row["final_return_mean"] - half, row["final_return_mean"] + half


def _cell_text(row: dict[str, Any]) -> str:
    """A cell's final return: mean [95% interval]."""
    lo, hi = _interval(row)
    return f"{row['final_return_mean']:,.0f} [{lo:,.0f}, {hi:,.0f}]"


def plain_reading(run_dir: str | Path | RunDir) -> str:
    """A few sentences a newcomer can read instead of the table: each querying cell's final return
    against the same agent without demonstrations (same uncertainty measure), with the difference
    and Welch's 95% interval of it (separated only when it excludes 0, see `welch_ci95`); whether
    asking for demonstrations beat not asking; the expert's return; the gait; where the figures are."""
    run = as_run(run_dir)
    rows = summarize(run)
    if not rows or run.periods == 0:
        return "Nothing to read yet: no evaluation period has finished."
    steps = rows[0]["env_steps"]
    seeds = "/".join(str(n) for n in sorted({r["n_seeds"] for r in rows}))
    lines = [
        f"Reading (final evaluation return at {steps:,} env steps per run, mean and 95% interval "
        f"over {seeds} seeds; a difference is separated when Welch's 95% interval of it excludes 0):"
    ]
    cells = {c.cell: c for c in group_cells(run)}
    final = np.asarray(run.metrics["eval_return"], dtype=np.float64)[:, -1]

    def field(row: dict[str, Any], name: str, default: str) -> str:
        return str(run_field(run, cells[row["cell"]].runs[0], name, default))

    def name(row: dict[str, Any]) -> str:
        return str(row["name"])  # the paper's names (`summary.cell_name`): "BQSAC b=0.1"

    plain = {
        field(r, "uncertainty", "intrinsic"): r
        for r in rows
        if field(r, "strategy", "none") == "none"
    }
    querying = [r for r in rows if field(r, "strategy", "none") != "none"]
    separated_above = []
    for row in querying:
        base = plain.get(field(row, "uncertainty", "intrinsic"))
        if base is None:
            lines.append(f"- {name(row)}: {_cell_text(row)}.")
            continue
        a, b = final[cells[row["cell"]].runs], final[cells[base["cell"]].runs]
        diff = float(np.nanmean(a) - np.nanmean(b))
        lo, hi = welch_ci95(a, b)
        if lo > 0:
            verdict = "above"
            separated_above.append(row)
        elif hi < 0:
            verdict = "below"
        else:
            verdict = "not separated from"
        lines.append(
            f"- {name(row)}: {_cell_text(row)}; {verdict} {name(base)} "
            f"({diff:+,.0f}, Welch [{lo:,.0f}, {hi:,.0f}])."
        )
    if not querying:
        lines += [f"- {name(r)}: {_cell_text(r)}." for r in rows]
    if querying:
        best = max(querying, key=lambda r: r["final_return_mean"])
        lines.append(f"Best querying cell: {name(best)}.")
        if separated_above:
            lines.append(
                "Asking for demonstrations beat not asking: "
                + ", ".join(name(r) for r in separated_above)
                + " ended above the same agent without them, Welch's interval excluding 0."
            )
        elif plain:
            lines.append(
                "Asking for demonstrations did not beat not asking here: no querying cell ended "
                "above the same agent without them with Welch's interval excluding 0."
            )
    expert = expert_return(run)
    if math.isfinite(expert):
        above = [r["name"] for r in rows if _interval(r)[0] > expert]
        lines.append(
            f"The expert's return is {expert:,.0f}; "
            + (
                f"above it with the whole interval: {', '.join(above)}."
                if above
                else "no cell's interval is above it."
            )
        )
    flipped = [
        r
        for r in rows
        if math.isfinite(r["upside_down_late_mean"]) and r["upside_down_late_mean"] > 0.05
    ]
    if flipped:
        lines.append(
            "Upside down in more than 5% of the late states (the flipped gait): "
            + ", ".join(f"{r['name']} ({100 * r['upside_down_late_mean']:.0f}%)" for r in flipped)
            + "."
        )
    if has_falls(run):
        lines.append(
            "Falls (share of the late training episodes that ended by a fall, and their mean "
            "length): "
            + ", ".join(
                f"{r['name']} {100 * r['fell_late_mean']:.0f}% "
                f"({r['episode_length_late_mean']:,.0f} steps)"
                for r in rows
                if math.isfinite(r["fell_late_mean"])
            )
            + "."
        )
    if run.partial:
        lines.append("This run directory is partial: the numbers are over the periods present.")
    lines.append(f"Table: {run.path / SUMMARY_MD}; figures: {run.path / FIGURES_DIR}/.")
    return "\n".join(lines)
