"""The summary table of a sweep's run directory: numpy, scipy and the files `run.py` writes, no JAX.

A run directory holds (see `arld_jax.run`):

* ``config.json``: ``{"config": {...Config fields...}, "sweep": {field: [values]}, "seeds": [...],
  "preset": ..., "command": ..., "expert": {"eval_return": ...} | null}``
* ``runs.json``: one dict per run, in run order: run, cell, cell_label, seed and every sweepable
  field.
* ``metrics.npz``: arrays ``[num_runs, num_periods, ...]``, one period per evaluation.
* ``timing.json`` (optional): wall_seconds, env_steps_per_second, compile_seconds.

A sweep that is still running leaves a *partial* directory whose metrics hold fewer periods than
``total_env_steps // eval_every``. Everything here then summarises the periods present and says so.

Statistics are over seeds within a cell: the mean and the half-width of the 95% confidence interval
of the mean (Student's t with n - 1 degrees of freedom), see `mean_ci95`.

Command line: ``python -m arld_jax.run plot RUN_DIR`` writes summary.csv, summary.md and the figures.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from arld_jax import gait
from arld_jax.config import STRATEGIES, UNCERTAINTIES, paper_name

REQUIRED_FILES: tuple[str, ...] = ("config.json", "runs.json", "metrics.npz")
"""Files a run directory must have before it can be summarised or plotted."""

STAT_COLUMNS: tuple[str, ...] = (
    "n_seeds",
    "final_return_mean",
    "final_return_ci95",
    "auc_mean",
    "auc_ci95",
    "demos_used_mean",
    "demos_used_ci95",
    "upside_down_late_mean",
    "upside_down_late_ci95",
    "upside_down_source",
    "expert_return",
    "env_steps_per_second",
    "periods",
    "env_steps",
)
"""Columns of a summary row after ``cell``, ``cell_label`` and the swept fields."""


# -------------------------------------------------------------------------------------------------
# statistics
# -------------------------------------------------------------------------------------------------


def mean_ci95(values: np.ndarray) -> tuple[float, float]:
    """Mean and half-width of the 95% confidence interval of the mean.

    NaNs are dropped first. The half-width is ``t.ppf(0.975, n - 1) * sd / sqrt(n)`` with the sample
    standard deviation (ddof=1) and Student's t with n - 1 degrees of freedom. One value gives a
    half-width of nan (no spread to estimate); no values give ``(nan, nan)``.
    """
    x = np.asarray(values, dtype=np.float64).ravel()
    x = x[~np.isnan(x)]
    n = x.size
    if n == 0:
        return math.nan, math.nan
    mean = float(x.mean())
    if n == 1:
        return mean, math.nan
    sd = float(x.std(ddof=1))
    return mean, float(stats.t.ppf(0.975, n - 1) * sd / math.sqrt(n))


def mean_ci95_columns(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`mean_ci95` of every column of ``values`` [n, m] (e.g. runs x periods), NaNs dropped.

    Returns ``(mean [m], half_width [m])``; a column with one finite value has half-width nan, a
    column with none has mean nan too.
    """
    x = np.asarray(values, dtype=np.float64)
    if x.ndim != 2:
        raise ValueError(f"values must be 2-D [n, m], got shape {x.shape}")
    finite = ~np.isnan(x)
    n = finite.sum(axis=0)
    with warnings.catch_warnings(), np.errstate(invalid="ignore", divide="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nanmean(x, axis=0)
        sd = np.nanstd(x, axis=0, ddof=1)
        t = stats.t.ppf(0.975, np.maximum(n - 1, 1))
        half = t * sd / np.sqrt(n)
    half = np.where(n >= 2, half, np.nan)
    mean = np.where(n >= 1, mean, np.nan)
    return mean, half


def welch_ci95(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """95% confidence interval of mean(x) - mean(y), Welch's t (unequal variances): half-width
    ``t.ppf(0.975, df) * se`` with ``se**2 = s_x**2 / n_x + s_y**2 / n_y`` (ddof=1) and the
    Welch-Satterthwaite ``df``. Needs two values per side (else ``(nan, nan)``); two constant
    samples give the point ``(d, d)``.

    Why it sits beside the bootstrap intervals of `compare_runs`: with 5 seeds per side the
    percentile bootstrap interval of a difference is narrower than 95% (it resamples with the
    plug-in variance and normal-like quantiles): with no difference it excluded 0 in 12% of
    simulated normal pairs and 13.5% of skewed (lognormal) ones, Welch's in 4.8% and 2.3%
    (`experiments/stats/interval_coverage.md`, which has the command)."""
    x = np.asarray(x, np.float64).ravel()
    y = np.asarray(y, np.float64).ravel()
    n, m = x.size, y.size
    if n < 2 or m < 2:
        return math.nan, math.nan
    diff = float(x.mean() - y.mean())
    vx, vy = x.var(ddof=1) / n, y.var(ddof=1) / m
    se2 = vx + vy
    if se2 == 0.0:
        return diff, diff
    df = se2**2 / (vx**2 / (n - 1) + vy**2 / (m - 1))
    half = float(stats.t.ppf(0.975, df) * math.sqrt(se2))
    return diff - half, diff + half


def area_under_curve(eval_return: np.ndarray, env_steps: np.ndarray) -> np.ndarray:
    """Normalised area under each run's evaluation curve: its mean evaluation return.

    Definition: ``auc[r] = mean_p eval_return[r, p]``, the simple average of the evaluation returns
    over the P evaluation points (no trapezoid). With evaluations every ``eval_every`` env steps
    this is the area under the step curve that holds each evaluation for its period, divided by the
    length of the run, so it has the units of a return and is comparable between runs of different
    lengths (and between a partial run and a finished one, as "the average return so far"). A NaN
    evaluation makes that run's AUC NaN (and `mean_ci95` then leaves that run out).

    Args:
        eval_return: [R, P] evaluation returns.
        env_steps: [P] (or [R, P]) env steps of the evaluations; only checked against P, since the
            evaluations are equally spaced.

    Returns:
        [R] AUC per run.
    """
    ret = np.asarray(eval_return, dtype=np.float64)
    steps = np.asarray(env_steps)
    if ret.ndim != 2:
        raise ValueError(f"eval_return must be [runs, periods], got shape {ret.shape}")
    if steps.shape[-1] != ret.shape[1]:
        raise ValueError(
            f"env_steps has {steps.shape[-1]} evaluation points but eval_return has {ret.shape[1]}"
        )
    if ret.shape[1] == 0:
        return np.full(ret.shape[0], np.nan)
    return ret.mean(axis=1)


# -------------------------------------------------------------------------------------------------
# loading
# -------------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class RunDir:
    """A run directory as read by `load_run` (the one reader of what `arld_jax.run` writes)."""

    path: Path
    config: dict[str, Any]  # the whole config.json: config, sweep, seeds, preset, command, expert
    runs: list[dict[str, Any]]  # runs.json, one dict per run present in metrics.npz
    metrics: dict[str, np.ndarray]  # metrics.npz, arrays [runs, periods, ...]
    timing: dict[str, Any]  # timing.json, or {} if absent (a sweep still running)
    periods: int  # evaluation periods present
    expected_periods: int  # total_env_steps // eval_every
    partial: bool  # fewer periods or runs present than the sweep will write
    missing_runs: int  # runs listed in runs.json but not yet in metrics.npz (normally 0)
    sources: tuple[Path, ...] = ()  # the directories `pool_runs` read into this one, else ()

    @property
    def cfg(self) -> dict[str, Any]:
        """The run's Config fields (config.json's "config")."""
        return self.config.get("config", {})

    @property
    def agent(self) -> str:
        """The run's agent family (directories written before there was a choice trained SAC)."""
        return self.cfg.get("agent", "sac")

    @property
    def name(self) -> str:
        """The directory's name; pooled directories' names joined with "+"."""
        return "+".join(p.name for p in self.sources) or self.path.name

    @property
    def where(self) -> str:
        """The directory's path, for messages; pooled directories' paths joined with " + "."""
        return " + ".join(str(p) for p in self.sources) or str(self.path)


@dataclasses.dataclass(frozen=True)
class Cell:
    """Runs of one cell: same swept values, different seeds."""

    cell: Any  # the cell id of runs.json
    cell_label: str
    runs: list[int]  # run indices
    seeds: list[Any]
    fields: dict[str, Any]  # runs.json entry of its first run


def load_run(run_dir: str | Path) -> RunDir:
    """Load a run directory.

    Returns a `RunDir` (its fields say what each file holds).

    Raises:
        FileNotFoundError: the directory or one of config.json, runs.json, metrics.npz is missing.
        ValueError: the files are unreadable or inconsistent.
    """
    path = Path(run_dir)
    if not path.is_dir():
        raise FileNotFoundError(f"run directory {path} does not exist")
    missing = [name for name in REQUIRED_FILES if not (path / name).is_file()]
    if missing:
        raise FileNotFoundError(
            f"run directory {path} has no {' or '.join(missing)} (a run directory needs "
            f"{', '.join(REQUIRED_FILES)}). If a sweep is writing it, the sweep may not have "
            "finished its first chunk yet: metrics.npz appears after the first chunk of training."
        )
    config = json.loads((path / "config.json").read_text())
    runs = json.loads((path / "runs.json").read_text())
    try:
        with np.load(path / "metrics.npz", allow_pickle=False) as npz:
            metrics = {key: np.asarray(npz[key]) for key in npz.files}
    except (OSError, ValueError, EOFError) as err:
        raise ValueError(
            f"cannot read {path / 'metrics.npz'} ({err}); the sweep may be writing it right now, "
            "try again in a moment"
        ) from err
    timing_path = path / "timing.json"
    timing = json.loads(timing_path.read_text()) if timing_path.is_file() else {}

    if "eval_return" not in metrics:
        raise ValueError(f"{path / 'metrics.npz'} has no eval_return (has {sorted(metrics)})")
    num_runs, periods = metrics["eval_return"].shape[:2]
    if num_runs > len(runs):
        raise ValueError(
            f"{path}: metrics.npz has {num_runs} runs but runs.json lists only {len(runs)}"
        )
    missing_runs = len(runs) - num_runs
    runs = runs[:num_runs]
    cfg = config.get("config", {})
    eval_every = int(cfg.get("eval_every") or 0)
    total = int(cfg.get("total_env_steps") or 0)
    expected = total // eval_every if eval_every > 0 else periods
    return RunDir(
        path=path,
        config=config,
        runs=runs,
        metrics=metrics,
        timing=timing,
        periods=int(periods),
        expected_periods=int(expected),
        partial=bool(periods < expected or missing_runs > 0),
        missing_runs=int(missing_runs),
    )


POOL_MAY_DIFFER: tuple[str, ...] = ("seed", "total_env_steps")
"""Config fields in which directories pooled by `pool_runs` may differ (the run length: pooling
keeps the evaluations all of them have)."""


def pool_runs(run_dirs: Sequence[str | Path | RunDir]) -> RunDir:
    """Run directories of one experiment run with different seeds (seeds 0-4, later 5-9 with the
    same command and another --out), read as one: their runs side by side, in the order given,
    over the evaluations all of them have. Only ``eval_return`` and ``env_steps`` are pooled (what
    `compare_runs` reads); one directory is returned as loaded.

    Raises ValueError naming the directories and the difference when their configs differ in a
    field other than `POOL_MAY_DIFFER`, when their sweeps or experts differ, or when a cell has the
    same seed in two of them (its runs would be counted twice)."""
    runs = [_as_run(d) for d in run_dirs]
    if not runs:
        raise ValueError("pool_runs needs at least one run directory")
    if len(runs) == 1:
        return runs[0]
    first = runs[0]
    for other in runs[1:]:
        fields = sorted(set(first.cfg) | set(other.cfg))
        differ = [f for f in fields if f not in POOL_MAY_DIFFER
                  and first.cfg.get(f) != other.cfg.get(f)]  # fmt: skip
        for what in ("sweep", "expert"):
            a, b = first.config.get(what), other.config.get(what)
            if what == "sweep":
                a, b = [{k: v for k, v in (x or {}).items() if k != "seed"} for x in (a, b)]
            if a != b:
                differ.append(what)
        if differ:
            shown = ", ".join(
                f"{f} {first.cfg.get(f, first.config.get(f))!r} against "
                f"{other.cfg.get(f, other.config.get(f))!r}"
                for f in differ
            )
            raise ValueError(
                f"cannot pool {first.path} and {other.path}: they differ in {shown} (pooled "
                f"directories may differ only in {', '.join(POOL_MAY_DIFFER)})"
            )
    seen: dict[tuple[str, Any], Path] = {}
    for run in runs:
        for entry in run.runs:
            key = (str(entry.get("cell_label", "")), entry.get("seed"))
            if key in seen:
                raise ValueError(
                    f"cannot pool: seed {key[1]} of cell {key[0] or 'base'!r} is in both "
                    f"{seen[key]} and {run.path}; pool directories run with different --seeds"
                )
            seen[key] = run.path
    periods = min(run.periods for run in runs)
    eval_return = np.concatenate([r.metrics["eval_return"][:, :periods] for r in runs])
    steps = env_steps_axis(first)[:periods]
    entries = [dict(e, run=i) for i, e in enumerate(e for r in runs for e in r.runs)]
    seeds = [s for r in runs for s in r.config.get("seeds", [])]
    return RunDir(
        path=first.path,
        config=dict(first.config, seeds=seeds),
        runs=entries,
        metrics=dict(eval_return=eval_return, env_steps=np.tile(steps, (len(eval_return), 1))),
        timing={},
        periods=periods,
        expected_periods=max(r.expected_periods for r in runs),
        partial=any(r.partial or r.periods > periods for r in runs),
        missing_runs=sum(r.missing_runs for r in runs),
        sources=tuple(r.path for r in runs),
    )


def _as_run(run: RunDir | str | Path) -> RunDir:
    """Accept a loaded run directory or a path."""
    return run if isinstance(run, RunDir) else load_run(run)


def run_field(run: RunDir, index: int, name: str, default: Any = None) -> Any:
    """Field ``name`` of run ``index``: from runs.json, else from the config, else ``default``."""
    entry = run.runs[index]
    if name in entry:
        return entry[name]
    return run.cfg.get(name, default)


def swept_fields(run: RunDir) -> list[str]:
    """The swept fields that tell cells apart (the config's sweep keys, without seed)."""
    return [name for name in run.config.get("sweep") or {} if name != "seed"]


def env_steps_axis(run: RunDir) -> np.ndarray:
    """[P] env steps of the evaluations present (metrics env_steps is [R, P] or [P])."""
    metrics = run.metrics
    if "env_steps" in metrics:
        steps = np.asarray(metrics["env_steps"])
        return steps[0] if steps.ndim == 2 else steps
    eval_every = int(run.cfg.get("eval_every", 1))
    return (np.arange(run.periods) + 1) * eval_every


def group_cells(run: RunDir) -> list[Cell]:
    """The cells of a run directory in cell order; runs of one cell differ only in seed."""
    cells: dict[Any, Cell] = {}
    for index, entry in enumerate(run.runs):
        key = entry.get("cell", entry.get("cell_label", 0))
        if key not in cells:
            cells[key] = Cell(key, str(entry.get("cell_label", "")), [], [], dict(entry))
        cells[key].runs.append(index)
        cells[key].seeds.append(entry.get("seed", run_field(run, index, "seed")))
    out = list(cells.values())
    if all(isinstance(c.cell, int) for c in out):
        out.sort(key=lambda c: c.cell)
    return out


def expert_return(run: RunDir) -> float:
    """The expert's evaluation return from config.json, or nan when there is no expert."""
    expert = run.config.get("expert") or {}
    value = expert.get("eval_return") if isinstance(expert, dict) else None
    return float(value) if value is not None else math.nan


def upside_down_late(run: RunDir) -> tuple[np.ndarray, str]:
    """[R] fraction of visited training states upside down in the last 30% of the periods present
    (`gait.LATE_FRACTION`), and where it came from: "periods" (the per-period metric
    `upside_down`), "sample" (runs recorded before that metric existed: the saved uniform sample
    of visited states, those seen in the last 30% of the env steps present) or "n/a" (no data, or
    not HalfCheetah)."""
    metrics = run.metrics
    num_runs, periods = run.metrics["eval_return"].shape[:2]
    nan = np.full(num_runs, np.nan)
    if periods == 0:
        return nan, "n/a"
    if "upside_down" in metrics:
        late = max(1, math.ceil(gait.LATE_FRACTION * periods))
        return np.mean(np.asarray(metrics["upside_down"], np.float64)[:, -late:], axis=1), "periods"
    env_name = run.cfg.get("env_name")
    if env_name != "halfcheetah" or "visited_obs" not in metrics:
        return nan, "n/a"
    last = env_steps_axis(run)[-1]
    late = (metrics["visited_valid"]) & (
        metrics["visited_env_step"] > (1.0 - gait.LATE_FRACTION) * last
    )
    flipped = gait.upside_down(np.asarray(metrics["visited_obs"], np.float64))
    counts = late.sum(axis=1)
    out = np.where(counts > 0, (flipped & late).sum(axis=1) / np.maximum(counts, 1), np.nan)
    return out, "sample"


# -------------------------------------------------------------------------------------------------
# summary
# -------------------------------------------------------------------------------------------------


def summarize(run_dir: str | Path | RunDir) -> list[dict[str, Any]]:
    """One row per cell, in cell order, over the evaluation periods present.

    Row keys: ``cell``, ``cell_label``, the swept fields' values, then `STAT_COLUMNS`:
    n_seeds; final_return_mean/ci95 (eval return at the last evaluation present); auc_mean/ci95
    (`area_under_curve`); demos_used_mean/ci95 (final cumulative demonstrations); expert_return
    (config.json, or nan); env_steps_per_second (timing.json, all runs together, or nan); periods
    (evaluation periods present) and env_steps (env steps at the last evaluation present).
    Means and 95% CIs are over the seeds of the cell (`mean_ci95`).
    """
    run = _as_run(run_dir)
    metrics = run.metrics
    steps = env_steps_axis(run)
    eval_return = np.asarray(metrics["eval_return"], dtype=np.float64)
    auc = area_under_curve(eval_return, steps)
    demos = metrics.get("demos_used")
    flipped, flipped_source = upside_down_late(run)
    expert = expert_return(run)
    sps = float(run.timing.get("env_steps_per_second", math.nan))
    periods = run.periods
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
        row: dict[str, Any] = {"cell": cell.cell, "cell_label": cell.cell_label}
        for name in fields:
            row[name] = run_field(run, cell.runs[0], name)
        row["n_seeds"] = int(idx.size)
        row["final_return_mean"], row["final_return_ci95"] = mean_ci95(final)
        row["auc_mean"], row["auc_ci95"] = mean_ci95(auc[idx])
        row["demos_used_mean"], row["demos_used_ci95"] = mean_ci95(final_demos)
        row["upside_down_late_mean"], row["upside_down_late_ci95"] = mean_ci95(flipped[idx])
        row["upside_down_source"] = flipped_source
        row["expert_return"] = expert
        row["env_steps_per_second"] = sps
        row["periods"] = int(periods)
        row["env_steps"] = int(steps[-1]) if periods else 0
        rows.append(row)
    return rows


def format_mean_ci(mean: float, ci: float) -> str:
    """Format as "mean ± ci", rounded to two significant digits of the CI.

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
    ci_text = f"{ci:.{decimals}f}" if math.isfinite(ci) else "n/a"
    return f"{mean:.{decimals}f} ± {ci_text}"


def _format_percent(mean: float, ci: float) -> str:
    """A fraction as "mean ± ci %", or n/a."""
    if not math.isfinite(mean):
        return "n/a"
    return f"{100 * mean:.0f} ± {100 * ci:.0f} %" if math.isfinite(ci) else f"{100 * mean:.0f} %"


def _format_field(value: Any) -> str:
    """A swept field's value for the Markdown table."""
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _markdown(run: RunDir, rows: list[dict[str, Any]]) -> str:
    """The Markdown summary: a header stating what the numbers are, then one table row per cell."""
    config = run.config
    cfg = config.get("config", {})
    total = int(cfg.get("total_env_steps") or 0)
    last = rows[0]["env_steps"] if rows else 0
    seeds = config.get("seeds", [])
    seed_counts = sorted({row["n_seeds"] for row in rows})
    per_cell = "/".join(str(n) for n in seed_counts)
    lines = [f"# Sweep summary: {run.path.name}", ""]
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
        "evaluation present. AUC: mean evaluation return over all evaluation points present. "
        "Demos: cumulative demonstrated env steps at the end. Upside down: % of the visited "
        "training states with the torso upside down (|pitch| > 90°) in the last 30% of the "
        "periods present (the flipped gait; HalfCheetah only)."
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

    fields = swept_fields(run)
    columns = [
        "cell",
        *(fields or ["label"]),
        "seeds",
        "final return",
        "AUC (mean return)",
        "demos used",
        "upside down (last 30%)",
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
            format_mean_ci(row["auc_mean"], row["auc_ci95"]),
            format_mean_ci(row["demos_used_mean"], row["demos_used_ci95"]),
            _format_percent(row["upside_down_late_mean"], row["upside_down_late_ci95"]),
        ]
        lines.append("| " + " | ".join(values) + " |")
    return "\n".join(lines) + "\n"


def write_summary(run_dir: str | Path) -> tuple[Path, Path]:
    """Write ``summary.csv`` (one row per cell, columns as in `summarize`) and ``summary.md`` (a
    Markdown table of "mean ± ci" cells under a header stating env steps, seeds and what the CI is)
    into the run directory and return their paths."""
    run = load_run(run_dir)
    rows = summarize(run)
    columns = ["cell", "cell_label", *swept_fields(run), *STAT_COLUMNS]
    csv_path = run.path / "summary.csv"
    with csv_path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)
    md_path = run.path / "summary.md"
    md_path.write_text(_markdown(run, rows))
    return csv_path, md_path


GROUP_COLUMNS: tuple[str, ...] = ("member", "agent", "cell", "cell_label", *STAT_COLUMNS)
"""Columns of a group summary row (`write_group_summary`)."""


def group_members(group_dir: str | Path) -> list[Path]:
    """The member run directories of a `SweepGroup` output directory (its group.json), in order."""
    group_dir = Path(group_dir)
    path = group_dir / "group.json"
    if not path.is_file():
        raise FileNotFoundError(f"{group_dir} is not a group of runs (no group.json)")
    return [group_dir / name for name in json.loads(path.read_text())["members"]]


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
    csv_path = group_dir / "summary.csv"
    with csv_path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=GROUP_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    command = json.loads((group_dir / "group.json").read_text()).get("command", "")
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
    lines += [
        "| agent | cell | seeds | final return | AUC (mean return) | demos used |"
        " upside down (last 30%) |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        lines.append(
            f"| {row['agent']} | {row['cell_label'] or '-'} | {row['n_seeds']} | "
            f"{format_mean_ci(row['final_return_mean'], row['final_return_ci95'])} | "
            f"{format_mean_ci(row['auc_mean'], row['auc_ci95'])} | "
            f"{format_mean_ci(row['demos_used_mean'], row['demos_used_ci95'])} | "
            f"{_format_percent(row['upside_down_late_mean'], row['upside_down_late_ci95'])} |"
        )
    md_path = group_dir / "summary.md"
    md_path.write_text("\n".join(lines) + "\n")
    return csv_path, md_path


# -------------------------------------------------------------------------------------------------
# pairwise comparison of strategies (rliable)
# -------------------------------------------------------------------------------------------------


def comparison_pairs(run: RunDir) -> list[tuple[str, Cell, Cell]]:
    """The comparisons the paper draws, as (name, cell a, cell b) meaning "a minus b": for each
    uncertainty measure active vs Bernoulli, greedy and none (the passive strategies and no
    demonstrations that Fig. 1 says ARLD can fall behind), and for each strategy intrinsic vs
    extrinsic. Only where exactly one cell has each (strategy, uncertainty). Named after the run's
    agent family (AQSAC - BQSAC for SAC, AQTD3 - BQTD3 for TD3)."""
    agent = run.agent
    by_key: dict[tuple[str, str], list[Cell]] = {}
    for cell in group_cells(run):
        strategy = run_field(run, cell.runs[0], "strategy", "none")
        uncertainty = run_field(run, cell.runs[0], "uncertainty", "intrinsic")
        by_key.setdefault((strategy, uncertainty), []).append(cell)
    one = {k: v[0] for k, v in by_key.items() if len(v) == 1}
    pairs = []
    for u in UNCERTAINTIES:
        for other in ("bernoulli", "greedy", "none"):
            if ("active", u) in one and (other, u) in one:
                name = f"{paper_name('active', agent, u)} - {paper_name(other, agent, u)}"
                pairs.append((name, one[("active", u)], one[(other, u)]))
    for s in STRATEGIES[::-1]:
        if (s, "intrinsic") in one and (s, "extrinsic") in one:
            name = f"{paper_name(s, agent)} - {paper_name(s, agent, 'extrinsic')}"
            pairs.append((name, one[(s, "intrinsic")], one[(s, "extrinsic")]))
    return pairs


def probability_of_improvement(x: np.ndarray, y: np.ndarray) -> float:
    """P(X > Y) + P(X = Y) / 2 over all pairs of a run of x and a run of y: rliable's
    `metrics.probability_of_improvement` for one task (its Mann-Whitney U / (n m)), vectorised,
    because the bootstrap calls it tens of thousands of times (tested equal)."""
    x, y = np.asarray(x, np.float64)[:, None], np.asarray(y, np.float64)[None, :]
    return float(np.mean((x > y) + 0.5 * (x == y)))


BOOTSTRAP_REPS = 20_000
"""Resamples of the seeds behind every bootstrap interval `compare` and `compare_runs` give."""


def compare(run_dir: str | Path | RunDir, reps: int = BOOTSTRAP_REPS, seed: int = 0) -> list[dict]:
    """Pairwise differences of `comparison_pairs` with stratified-bootstrap 95% CIs (rliable,
    Agarwal et al. 2021): for the final and the area-under-curve return, the difference of the
    cells' means over seeds and the probability that a run of a beats a run of b. Rows: pair,
    metric and the keys of `bootstrap_difference`."""
    run = _as_run(run_dir)
    eval_return = np.asarray(run.metrics["eval_return"], dtype=np.float64)
    values = {
        "final return": eval_return[:, -1],
        "AUC": area_under_curve(eval_return, env_steps_axis(run)),
    }

    rows = []
    for name, a, b in comparison_pairs(run):
        for metric, v in values.items():
            rows.append(
                dict(pair=name, metric=metric)
                | bootstrap_difference(v[a.runs], v[b.runs], reps, seed)
            )
    return rows


def bootstrap_difference(x: np.ndarray, y: np.ndarray, reps: int, seed: int) -> dict[str, Any]:
    """mean(x) - mean(y) and P(a run of x > a run of y), each with its 95% stratified-bootstrap CI
    (rliable, Agarwal et al. 2021; x and y resampled separately, `reps` times, numpy seed `seed`).
    Also Welch's t interval of the difference (`welch_ci95`), better calibrated with few seeds.
    Keys: diff, diff_lo, diff_hi, welch_lo, welch_hi, p_improve, p_lo, p_hi, n_a, n_b."""
    from rliable import library as rly

    def stats_of(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.array([np.mean(a) - np.mean(b), probability_of_improvement(a[:, 0], b[:, 0])])

    x = np.asarray(x, np.float64)[:, None]  # [runs, 1 task]
    y = np.asarray(y, np.float64)[:, None]
    # rliable 1.2's StratifiedIndependentBootstrap draws its indices from numpy's *global* RNG
    # (`np.random.choice`), ignoring `random_state`: seed the global RNG for the call and put its
    # state back, so the same seed gives the same interval. `random_state` is still passed for a
    # rliable that honours it.
    global_state = np.random.get_state()
    np.random.seed(seed)
    try:
        with warnings.catch_warnings():  # arch's notice about rliable's RandomState argument
            warnings.simplefilter("ignore", FutureWarning)
            point, interval = rly.get_interval_estimates(
                {"x": (x, y)}, stats_of, reps=reps, random_state=np.random.RandomState(seed)
            )
    finally:
        np.random.set_state(global_state)
    (diff, p), ((diff_lo, p_lo), (diff_hi, p_hi)) = point["x"], interval["x"]
    welch_lo, welch_hi = welch_ci95(x[:, 0], y[:, 0])
    return dict(diff=float(diff), diff_lo=float(diff_lo), diff_hi=float(diff_hi),
                welch_lo=welch_lo, welch_hi=welch_hi,
                p_improve=float(p), p_lo=float(p_lo), p_hi=float(p_hi), n_a=len(x), n_b=len(y))  # fmt: skip


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
    a, b = _as_run(dir_a), _as_run(dir_b)
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
        hits = np.flatnonzero(steps == at)
        if len(hits) == 0:
            raise ValueError(
                f"no evaluation at {at:,} env steps in both runs: they share evaluations at "
                f"{int(steps[0]):,}, {int(steps[1] if len(steps) > 1 else steps[0]):,}, ..., "
                f"{int(steps[-1]):,}"
            )
        metrics.append((f"return at {at:,}", at, lambda r, i=int(hits[0]): r[:, i]))
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
    f"each with a 95% stratified-bootstrap CI (rliable, {BOOTSTRAP_REPS:,} resamples of the seeds, "
    "numpy seed 0), and the difference's Welch t 95% CI. With 5 seeds per side the bootstrap "
    "interval of a difference is too narrow: where there was no difference it excluded 0 in 12% "
    "of simulated pairs, not 5% (Welch's: 5%; `experiments/stats/interval_coverage.md`). Read a "
    "difference as separated when Welch's interval excludes 0."
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


def write_comparison(run_dir: str | Path | RunDir) -> Path | None:
    """comparison.md (and .csv) of `compare`, or None when the run has no such pairs."""
    run = _as_run(run_dir)
    if not comparison_pairs(run) or run.periods == 0:
        return None
    rows = compare(run)
    with (run.path / "comparison.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    lines = [
        f"# Pairwise comparison: {run.path.name}",
        "",
        "a − b: the difference of the cells' mean returns over seeds, and the probability that a "
        f"run of a scores higher than a run of b (Agarwal et al. 2021), {INTERVALS} "
        "At the last evaluation present: "
        f"{int(env_steps_axis(run)[-1]):,} "
        "env steps." + (" **Partial run directory.**" if run.partial else ""),
        "",
        format_comparison(rows),
    ]
    path = run.path / "comparison.md"
    path.write_text("\n".join(lines) + "\n")
    return path


# -------------------------------------------------------------------------------------------------
# a plain-language reading of the summary (printed by the driver at the end of a run)
# -------------------------------------------------------------------------------------------------


def _interval(row: dict[str, Any]) -> tuple[float, float]:
    half = row["final_return_ci95"]
    half = half if math.isfinite(half) else 0.0
    return row["final_return_mean"] - half, row["final_return_mean"] + half


def _cell_text(row: dict[str, Any]) -> str:
    lo, hi = _interval(row)
    return f"{row['cell_label'] or 'base'}: {row['final_return_mean']:,.0f} [{lo:,.0f}, {hi:,.0f}]"


def plain_reading(run_dir: str | Path | RunDir) -> str:
    """A few sentences a newcomer can read instead of the table: each querying cell's final return
    against plain SAC's (same uncertainty measure), with their 95% intervals and whether those
    overlap; the best querying cell; the expert's return; the gait; where the figures are."""
    run = _as_run(run_dir)
    rows = summarize(run)
    if not rows or run.periods == 0:
        return "Nothing to read yet: no evaluation period has finished."
    steps = rows[0]["env_steps"]
    seeds = "/".join(str(n) for n in sorted({r["n_seeds"] for r in rows}))
    lines = [
        f"Reading (final evaluation return at {steps:,} env steps per run, mean and 95% interval "
        f"over {seeds} seeds; intervals that do not overlap mean a difference the seeds support):"
    ]

    def field(row: dict[str, Any], name: str, default: str) -> str:
        cell = next(c for c in group_cells(run) if c.cell == row["cell"])
        return str(run_field(run, cell.runs[0], name, default))

    plain = {
        field(r, "uncertainty", "intrinsic"): r
        for r in rows
        if field(r, "strategy", "none") == "none"
    }
    querying = [r for r in rows if field(r, "strategy", "none") != "none"]
    for row in querying:
        base = plain.get(field(row, "uncertainty", "intrinsic"))
        if base is None:
            lines.append(f"- {_cell_text(row)}.")
            continue
        (lo, hi), (blo, bhi) = _interval(row), _interval(base)
        if lo > bhi:
            verdict = "above plain SAC, intervals apart"
        elif hi < blo:
            verdict = "below plain SAC, intervals apart"
        else:
            verdict = "not separated from plain SAC (intervals overlap)"
        lines.append(f"- {_cell_text(row)}: {verdict} ({_cell_text(base)}).")
    if not querying:
        lines += [f"- {_cell_text(r)}." for r in rows]
    if querying:
        best = max(querying, key=lambda r: r["final_return_mean"])
        lines.append(f"Best querying cell: {best['cell_label']}.")
    expert = expert_return(run)
    if math.isfinite(expert):
        above = [r["cell_label"] for r in rows if _interval(r)[0] > expert]
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
            + ", ".join(
                f"{r['cell_label'] or 'base'} ({100 * r['upside_down_late_mean']:.0f}%)"
                for r in flipped
            )
            + "."
        )
    if run.partial:
        lines.append("This run directory is partial: the numbers are over the periods present.")
    lines.append(f"Table: {run.path / 'summary.md'}; figures: {run.path / 'figures'}/.")
    return "\n".join(lines)
