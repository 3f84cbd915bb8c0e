"""The summary table of a run directory (one row per cell: final return, AUC, interquartile mean,
gait, demonstrations, each with its 95% interval over seeds), and of a group's members together.

Command line: ``python -m arld_jax.run plot RUN_DIR`` writes summary.csv, summary.md and the figures.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from arld_jax import config, gait
from arld_jax.rundir import (
    GROUP_FILE,
    SUMMARY_CSV,
    SUMMARY_MD,
    Cell,
    RunDir,
    as_run,
    env_steps_axis,
    expert_return,
    group_cells,
    group_members,
    load_run,
    run_field,
    swept_fields,
)
from arld_jax.stats import area_under_curve, iqm_ci95, late_return, late_window, mean_ci95

STAT_COLUMNS: tuple[str, ...] = (
    "n_seeds",
    "final_return_mean",
    "final_return_ci95",
    "final_return_iqm",
    "final_return_iqm_lo",
    "final_return_iqm_hi",
    "late_return_mean",
    "late_return_ci95",
    "auc_mean",
    "auc_ci95",
    "demos_used_mean",
    "demos_used_ci95",
    "upside_down_late_mean",
    "upside_down_late_ci95",
    "upside_down_source",
    "asked_upside_down_mean",
    "asked_upside_down_ci95",
    "visited_upside_down_while_asking_mean",
    "visited_upside_down_while_asking_ci95",
    "asked_minus_visited_upside_down_mean",
    "asked_minus_visited_upside_down_ci95",
    "fell_late_mean",
    "fell_late_ci95",
    "episode_length_late_mean",
    "episode_length_late_ci95",
    "expert_return",
    "above_expert",
    "above_expert_late",
    "env_steps_per_second",
    "periods",
    "env_steps",
)
"""Columns of a summary row after ``cell``, ``cell_label`` and the swept fields."""


def cell_name(run: RunDir, cell: Cell, exclude: Sequence[str] = ()) -> str:
    """A cell's short name in the paper's names, e.g. "AQSAC t_query=0.1", "BQNoisySAC b=0.4 C=2"
    (`config.cell_name`: every swept field the cell's strategy uses, so it tells the cells apart as
    the cell_label does), for legends, tables and progress lines; ``exclude`` drops fields a figure
    panel already fixes."""
    if run_field(run, cell.runs[0], "strategy") is None:
        return cell.cell_label or f"cell {cell.cell}"
    swept = swept_fields(run)
    names = {"strategy", "uncertainty", "query_prob", "t_query", *swept}
    values = {name: run_field(run, cell.runs[0], name) for name in names}
    return config.cell_name(values, swept, run.agent, exclude)


def episodes_late(run: RunDir) -> tuple[np.ndarray, np.ndarray]:
    """[R] the share of training episodes that ended by a fall (a termination), and their mean
    length in env steps, over the episodes that finished in the last 30% of the periods present
    (`gait.LATE_FRACTION`), each period weighted by its episode count. nan where none finished, or
    for runs recorded before episodes could end early (no `fell` metric)."""
    metrics = run.metrics
    num_runs, periods = metrics["eval_return"].shape[:2]
    if periods == 0 or "fell" not in metrics:
        return np.full(num_runs, np.nan), np.full(num_runs, np.nan)
    late = max(1, math.ceil(gait.LATE_FRACTION * periods))
    count = np.asarray(metrics["episodes"], np.float64)[:, -late:]
    total = count.sum(axis=1)

    def weighted(name: str) -> np.ndarray:
        values = np.nan_to_num(np.asarray(metrics[name], np.float64)[:, -late:])
        return np.where(total > 0, (values * count).sum(axis=1) / np.maximum(total, 1), np.nan)

    return weighted("fell"), weighted("episode_length")


def has_falls(run: RunDir) -> bool:
    """Whether any training or evaluation episode of the run ended by a fall: the runs whose tables,
    readings and figures show the fall share and the episode length (never HalfCheetah's)."""
    m = run.metrics
    return any(
        name in m and np.nanmax(np.asarray(m[name]), initial=0.0) > 0
        for name in ("fell", "eval_fell")
    )


def has_gait_rule(run: RunDir) -> bool:
    """Whether the run's task has a gait rule (HalfCheetah's flipped torso, `TaskSpec.upside_down`):
    the runs whose tables show the upside-down share."""
    from arld_jax.tasks import REGISTRY

    spec = REGISTRY.get(run.cfg.get("env_name", "halfcheetah"))
    return spec is not None and spec.has_gait_rule


def _share(flags: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """[R] share of the masked entries of [R, K] `flags` that are true; nan where none is masked."""
    counts = mask.sum(axis=1)
    return np.where(counts > 0, (flags & mask).sum(axis=1) / np.maximum(counts, 1), np.nan)


def upside_down_late(run: RunDir) -> tuple[np.ndarray, str]:
    """[R] fraction of visited training states upside down in the last 30% of the periods present
    (`gait.LATE_FRACTION`), and where it came from: "periods" (the per-period metric
    `upside_down`), "sample" (runs recorded before that metric existed: the saved uniform sample
    of visited states, those seen in the last 30% of the env steps present) or "n/a" (no data, or
    not HalfCheetah)."""
    metrics = run.metrics
    num_runs, periods = run.metrics["eval_return"].shape[:2]
    nan = np.full(num_runs, np.nan)
    if periods == 0 or not has_gait_rule(run):
        return nan, "n/a"
    if "upside_down" in metrics:
        late = max(1, math.ceil(gait.LATE_FRACTION * periods))
        return np.mean(np.asarray(metrics["upside_down"], np.float64)[:, -late:], axis=1), "periods"
    if "visited_obs" not in metrics:
        return nan, "n/a"
    last = env_steps_axis(run)[-1]
    late = (metrics["visited_valid"]) & (
        metrics["visited_env_step"] > (1.0 - gait.LATE_FRACTION) * last
    )
    flipped = gait.upside_down(np.asarray(metrics["visited_obs"], np.float64))
    return _share(flipped, late), "sample"


def upside_down_when_asked(run: RunDir) -> tuple[np.ndarray, np.ndarray]:
    """[R] share of the sampled states where a query started that have the torso upside down, and
    the same share of the sampled visited states over the same env steps (up to the last sampled
    query): whether a strategy asks in flipped states more often than the run is in them, the
    question of the paper's Fig. 8 read with the gait rule. Both nan without a gait rule, the state
    samples (a reading at an earlier step drops them) or a sampled query."""
    metrics = run.metrics
    nan = np.full(np.asarray(metrics["eval_return"]).shape[0], np.nan)
    if not has_gait_rule(run) or "queried_obs" not in metrics:
        return nan, nan
    asked_valid = np.asarray(metrics["queried_valid"], bool)
    asked_steps = np.asarray(metrics["queried_env_step"])
    last_asked = np.where(asked_valid, asked_steps, -1).max(axis=1, initial=-1)
    meanwhile = np.asarray(metrics["visited_valid"], bool) & (
        np.asarray(metrics["visited_env_step"]) <= last_asked[:, None]
    )
    flipped = lambda name: gait.upside_down(np.asarray(metrics[name], np.float64))  # noqa: E731
    asked = _share(flipped("queried_obs"), asked_valid)
    visited = _share(flipped("visited_obs"), meanwhile)
    return asked, np.where(np.isnan(asked), np.nan, visited)


def summarize(run_dir: str | Path | RunDir) -> list[dict[str, Any]]:
    """One row per cell, in cell order, over the evaluation periods present.

    Row keys: ``cell``, ``cell_label``, ``name`` (`cell_name`: the paper's names), the swept fields' values, then `STAT_COLUMNS`:
    n_seeds; final_return_mean/ci95 (eval return at the last evaluation present);
    final_return_iqm/_lo/_hi (its interquartile mean and 95% bootstrap interval, `iqm_ci95`);
    late_return_mean/ci95 (each seed's mean return over its last `late_window` evaluations, nan
    with fewer than 20 evaluations); auc_mean/ci95
    (`area_under_curve`); demos_used_mean/ci95 (final cumulative demonstrations); expert_return
    (config.json, or nan); above_expert (how many seeds' final return is above the expert's, the
    paper's "ends above the expert" seed by seed; nan without an expert); above_expert_late (the same
    by the late return; nan without one); env_steps_per_second
    (timing.json, all runs together, or nan); periods
    (evaluation periods present) and env_steps (env steps at the last evaluation present).
    Means and 95% CIs are over the seeds of the cell (`mean_ci95`).
    """
    run = as_run(run_dir)
    metrics = run.metrics
    steps = env_steps_axis(run)
    eval_return = np.asarray(metrics["eval_return"], dtype=np.float64)
    auc = area_under_curve(eval_return, steps)
    periods = run.periods
    late = late_return(eval_return)
    demos = metrics.get("demos_used")
    flipped, flipped_source = upside_down_late(run)
    asked_flipped, visited_flipped = upside_down_when_asked(run)
    fell, lengths = episodes_late(run)
    expert = expert_return(run)
    sps = float(run.timing.get("env_steps_per_second", math.nan))
    fields = swept_fields(run)

    rows = []
    for cell in group_cells(run):
        idx = np.asarray(cell.runs)
        final = eval_return[idx, -1] if periods else np.full(idx.size, np.nan)
        final_demos = (
            np.asarray(demos, dtype=np.float64)[idx, -1]
            if demos is not None and periods
            else np.full(idx.size, np.nan)
        )
        row: dict[str, Any] = {
            "cell": cell.cell,
            "cell_label": cell.cell_label,
            "name": cell_name(run, cell),
        }
        for name in fields:
            row[name] = run_field(run, cell.runs[0], name)
        row["n_seeds"] = int(idx.size)
        row["final_return_mean"], row["final_return_ci95"] = mean_ci95(final)
        iqm, lo, hi = iqm_ci95(final)
        row.update(final_return_iqm=iqm, final_return_iqm_lo=lo, final_return_iqm_hi=hi)
        row["late_return_mean"], row["late_return_ci95"] = mean_ci95(late[idx])
        row["auc_mean"], row["auc_ci95"] = mean_ci95(auc[idx])
        row["demos_used_mean"], row["demos_used_ci95"] = mean_ci95(final_demos)
        row["upside_down_late_mean"], row["upside_down_late_ci95"] = mean_ci95(flipped[idx])
        row["upside_down_source"] = flipped_source
        row["asked_upside_down_mean"], row["asked_upside_down_ci95"] = mean_ci95(asked_flipped[idx])
        (
            row["visited_upside_down_while_asking_mean"],
            row["visited_upside_down_while_asking_ci95"],
        ) = mean_ci95(visited_flipped[idx])
        (  # paired over seeds: the same runs ask and visit
            row["asked_minus_visited_upside_down_mean"],
            row["asked_minus_visited_upside_down_ci95"],
        ) = mean_ci95(asked_flipped[idx] - visited_flipped[idx])
        row["fell_late_mean"], row["fell_late_ci95"] = mean_ci95(fell[idx])
        row["episode_length_late_mean"], row["episode_length_late_ci95"] = mean_ci95(lengths[idx])
        row["expert_return"] = expert
        row["above_expert"] = int(np.sum(final > expert)) if math.isfinite(expert) else math.nan
        row["above_expert_late"] = (
            int(np.sum(late[idx] > expert))
            if math.isfinite(expert) and late_window(periods)
            else math.nan
        )
        row["env_steps_per_second"] = sps
        row["periods"] = int(periods)
        row["env_steps"] = int(steps[-1]) if periods else 0
        rows.append(row)
    return rows


def format_mean_ci(mean: float, ci: float) -> str:
    """Format as "mean ± ci" (thousands separated), rounded to two significant digits of the CI.

    Never more precise than 4 decimals nor coarser than whole numbers; "± n/a" when the CI is
    unknown (one seed).
    """
    if not math.isfinite(mean):
        return "nan"
    if math.isfinite(ci) and ci > 0:
        decimals = min(4, max(0, 1 - math.floor(math.log10(ci))))
    else:
        magnitude = abs(mean)
        if magnitude == 0 or float(mean).is_integer():
            decimals = 0
        else:
            decimals = min(4, max(0, 2 - math.floor(math.log10(magnitude))))
    ci_text = f"{ci:,.{decimals}f}" if math.isfinite(ci) else "n/a"
    return f"{mean:,.{decimals}f} ± {ci_text}"


def format_iqm(row: dict[str, Any]) -> str:
    """A row's final-return IQM as "iqm [lo, hi]" (whole numbers), "iqm" alone with one seed."""
    point, lo, hi = row["final_return_iqm"], row["final_return_iqm_lo"], row["final_return_iqm_hi"]
    if not math.isfinite(point):
        return "nan"
    return f"{point:,.0f}" + (f" [{lo:,.0f}, {hi:,.0f}]" if math.isfinite(lo) else "")


def _format_percent(mean: float, ci: float) -> str:
    """A fraction as "mean ± ci %", or n/a."""
    if not math.isfinite(mean):
        return "n/a"
    return f"{100 * mean:.0f} ± {100 * ci:.0f} %" if math.isfinite(ci) else f"{100 * mean:.0f} %"


def _format_asked(row: dict[str, Any]) -> str:
    """The upside-down share when asked, the visited one meanwhile, and their paired difference in
    points with its interval: "a % (v %), +d [lo, hi]"; "a % (n/a)" where no visited state was
    sampled before the last query (a short run), no interval with one seed."""
    if not math.isfinite(row["asked_upside_down_mean"]):
        return "n/a"
    points = lambda x: int(round(x))  # noqa: E731  (no "-0")
    text = f"{points(100 * row['asked_upside_down_mean'])} %"
    meanwhile = row["visited_upside_down_while_asking_mean"]
    if not math.isfinite(meanwhile):
        return text + " (n/a)"
    diff = 100 * row["asked_minus_visited_upside_down_mean"]
    half = 100 * row["asked_minus_visited_upside_down_ci95"]
    text += f" ({points(100 * meanwhile)} %), {points(diff):+d}"
    return text + (
        f" [{points(diff - half)}, {points(diff + half)}]" if math.isfinite(half) else ""
    )


def _format_field(value: Any) -> str:
    """A swept field's value for the Markdown table."""
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _markdown(run: RunDir, rows: list[dict[str, Any]]) -> str:
    """The Markdown summary: a header stating what the numbers are, then one table row per cell."""
    config = run.config
    cfg = config.get("config", {})
    falls, flips = has_falls(run), has_gait_rule(run)
    asked = any(math.isfinite(row["asked_upside_down_mean"]) for row in rows)
    k = late_window(run.periods)
    total = int(cfg.get("total_env_steps") or 0)
    last = rows[0]["env_steps"] if rows else 0
    seeds = config.get("seeds", [])
    seed_counts = sorted({row["n_seeds"] for row in rows})
    per_cell = "/".join(str(n) for n in seed_counts)
    lines = [f"# Sweep summary: {run.name}", ""]
    if run.partial:
        note = (
            f"**Partial run directory**: {run.periods} of {run.expected_periods} evaluation "
            f"periods present ({last:,} of {total:,} env steps per run)"
        )
        if run.missing_runs:
            note += f", {run.missing_runs} runs not in metrics.npz yet"
        lines += [
            note + "; the sweep is probably still running and every number below is over "
            "the periods present.",
            "",
        ]
    header = [
        f"Env steps per run: {last:,}" + (f" of {total:,}" if total and total != last else ""),
        f"env: {cfg.get('env_name', '?')}",
        f"cells: {len(rows)}",
        f"seeds per cell: {per_cell} ({seeds})",
    ]
    expert = expert_return(run)
    if math.isfinite(expert):
        header.append(f"expert return: {expert:.1f}")
    sps = run.timing.get("env_steps_per_second")
    if sps is not None:
        header.append(f"throughput: {float(sps):,.0f} env steps/s (all runs together)")
    lines += [" · ".join(header) + ".", ""]
    lines += [
        "Cells are mean ± half-width of the 95% confidence interval of the mean over seeds "
        "(Student's t, n − 1 dof; n/a with one seed). Final return: evaluation return at the last "
        "evaluation present; its IQM: the interquartile mean over seeds (rliable's; 5 seeds: the "
        "middle 3) [95% percentile-bootstrap interval]. AUC: mean evaluation return over all evaluation points present. "
        "Demos: cumulative demonstrated env steps at the end."
        + (
            f" Late return: each seed's mean evaluation return over its last {k} evaluations "
            f"(from {int(env_steps_axis(run)[-k]):,} env steps; the last tenth of those present), "
            "less swayed than the final return by the policy's swings from one evaluation to the "
            "next."
            if k
            else ""
        )
        + (
            " Seeds above the expert: runs whose final return is above the expert's"
            + (" (in brackets: whose late return is)." if k else ".")
            if math.isfinite(expert)
            else ""
        )
        + (
            " Upside down: % of the visited training states with the torso upside down "
            "(|pitch| > 90°) in the last 30% of the periods present (the flipped gait)."
            if flips
            else ""
        )
        + (
            " Upside down when asked: % of the sampled states where a query started with the torso "
            "upside down, in brackets the same % of the sampled visited states up to the last "
            "sampled query, then their difference in points with its 95% interval over seeds "
            "(paired: each run's two shares); above 0 when a strategy asks in flipped states more "
            "than the run is in them."
            if asked
            else ""
        )
        + (
            " Fell: % of the training episodes finished in the last 30% of the periods that "
            "ended by a fall (the task's termination), and their mean length in env steps."
            if falls
            else ""
        )
        + (
            " Here from the saved sample of visited states (recorded before the per-period "
            "metric existed)."
            if rows and rows[0]["upside_down_source"] == "sample"
            else ""
        ),
        "",
    ]
    if config.get("command"):
        lines += [f"Command: `{config['command']}`", ""]
    if config.get("pooled_commands"):
        made = "; ".join(f"`{c}`" for c in config["pooled_commands"] if c) or "not recorded"
        lines += [f"Pooled from runs made by: {made}", ""]

    fields = swept_fields(run)
    columns = [
        "cell",
        *(fields or ["label"]),
        "seeds",
        "final return",
        "final IQM",
        *(["late return"] if k else []),
        "AUC (mean return)",
        "demos used",
        *(["seeds above the expert"] if math.isfinite(expert) else []),
        *(["upside down (last 30%)"] if flips else []),
        *(["upside down when asked (visited meanwhile), difference"] if asked else []),
        *(["fell (last 30%)", "episode length (last 30%)"] if falls else []),
    ]
    lines.append("| " + " | ".join(columns) + " |")
    text_columns = {"label"} | {f for f in fields if any(isinstance(row[f], str) for row in rows)}
    lines.append("|" + "|".join("---" if c in text_columns else "---:" for c in columns) + "|")
    for row in rows:
        values = [str(row["cell"])]
        values += [_format_field(row[f]) for f in fields] if fields else [row["cell_label"] or "-"]
        values += [
            str(row["n_seeds"]),
            format_mean_ci(row["final_return_mean"], row["final_return_ci95"]),
            format_iqm(row),
            *([format_mean_ci(row["late_return_mean"], row["late_return_ci95"])] if k else []),
            format_mean_ci(row["auc_mean"], row["auc_ci95"]),
            format_mean_ci(row["demos_used_mean"], row["demos_used_ci95"]),
        ]
        if math.isfinite(expert):
            late_above = f" (late: {row['above_expert_late']})" if k else ""
            values.append(f"{row['above_expert']} of {row['n_seeds']}{late_above}")
        if flips:
            values.append(
                _format_percent(row["upside_down_late_mean"], row["upside_down_late_ci95"])
            )
        if asked:
            values.append(_format_asked(row))
        if falls:
            values += [
                _format_percent(row["fell_late_mean"], row["fell_late_ci95"]),
                format_mean_ci(row["episode_length_late_mean"], row["episode_length_late_ci95"]),
            ]
        lines.append("| " + " | ".join(values) + " |")
    return "\n".join(lines) + "\n"


def summary_markdown(run_dir: str | Path | RunDir) -> str:
    """summary.md's text: `summarize`'s rows as a Markdown table under a header saying what they
    are."""
    run = as_run(run_dir)
    return _markdown(run, summarize(run))


def write_summary(run_dir: str | Path) -> tuple[Path, Path]:
    """Write ``summary.csv`` (one row per cell, columns as in `summarize`) and ``summary.md`` (a
    Markdown table of "mean ± ci" cells under a header stating env steps, seeds and what the CI is)
    into the run directory and return their paths."""
    run = load_run(run_dir)
    rows = summarize(run)
    columns = ["cell", "cell_label", "name", *swept_fields(run), *STAT_COLUMNS]
    csv_path = run.path / SUMMARY_CSV
    with csv_path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)
    md_path = run.path / SUMMARY_MD
    md_path.write_text(_markdown(run, rows))
    return csv_path, md_path


GROUP_COLUMNS: tuple[str, ...] = ("member", "agent", "cell", "cell_label", "name", *STAT_COLUMNS)
"""Columns of a group summary row (`write_group_summary`)."""


def summarize_group(group_dir: str | Path) -> list[dict[str, Any]]:
    """`summarize` of every member, each row with its member name and agent family in front."""
    rows = []
    for member in group_members(group_dir):
        run = load_run(member)
        rows += [{"member": member.name, "agent": run.agent, **row} for row in summarize(run)]
    return rows


def write_group_summary(group_dir: str | Path) -> tuple[Path, Path]:
    """summary.csv and summary.md of a group: one table, a row per (member, cell)."""
    group_dir = Path(group_dir)
    rows = summarize_group(group_dir)
    csv_path = group_dir / SUMMARY_CSV
    with csv_path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=GROUP_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    command = json.loads((group_dir / GROUP_FILE).read_text()).get("command", "")
    steps = sorted({row["env_steps"] for row in rows})
    lines = [
        f"# Group summary: {group_dir.name}",
        "",
        f"One compiled program per agent family; env steps per run at the last evaluation: "
        f"{', '.join(f'{s:,}' for s in steps)}. Mean ± half-width of the 95% CI over seeds "
        "(Student's t). Per-member details are in each member's own summary.md.",
        "",
    ]
    if command:
        lines += [f"Command: `{command}`", ""]
    flips = any(row["upside_down_source"] != "n/a" for row in rows)
    lines += [
        "| agent | cell | seeds | final return | AUC (mean return) | demos used |"
        + (" upside down (last 30%) |" if flips else ""),
        "|---|---|---:|---:|---:|---:|" + ("---:|" if flips else ""),
    ]
    for row in rows:
        lines.append(
            f"| {row['agent']} | {row['name']} | {row['n_seeds']} | "
            f"{format_mean_ci(row['final_return_mean'], row['final_return_ci95'])} | "
            f"{format_mean_ci(row['auc_mean'], row['auc_ci95'])} | "
            f"{format_mean_ci(row['demos_used_mean'], row['demos_used_ci95'])} |"
            + (
                f" {_format_percent(row['upside_down_late_mean'], row['upside_down_late_ci95'])} |"
                if flips
                else ""
            )
        )
    md_path = group_dir / SUMMARY_MD
    md_path.write_text("\n".join(lines) + "\n")
    return csv_path, md_path
