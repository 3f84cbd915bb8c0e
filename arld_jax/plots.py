"""The paper's figures (section 4, appendix A.2) from a sweep's run directory: numpy + matplotlib.

`plot_all(run_dir)` writes PNGs into ``run_dir/figures/`` and skips the figures the run has no data
for; `plot_group(group_dir)` draws Fig. 1 of a group of runs (one program per agent family). Each ``fig*`` function takes the dict of `arld_jax.rundir.load_run` and returns a matplotlib
`Figure`, or None when there is nothing to plot.

Figures are drawn on the Agg canvas directly (``Figure`` + ``FigureCanvasAgg``), never through
pyplot: no global backend switch, no GUI, and nothing left open once a figure is saved.

Command line: ``python -m arld_jax.run plot RUN_DIR`` (summary and figures, also of a group).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import EngFormatter

from arld_jax.agents import REGISTRY
from arld_jax.compare import comparison_pairs, reading_steps
from arld_jax.config import SHORT_NAMES, STRATEGIES, UNCERTAINTIES
from arld_jax.rundir import (
    Cell,
    RunDir,
    env_steps_axis,
    expert_return,
    group_cells,
    group_members,
    load_run,
    run_field,
    swept_fields,
)
from arld_jax.stats import mean_ci95, mean_ci95_columns, welch_ci95
from arld_jax.summary import cell_name, has_falls, has_gait_rule

DPI = 110
SMOOTH_WINDOW = 5
"""Moving-average window of Fig. 3, in trace points."""

_LINESTYLES = ("-", "--", ":", "-.")

Run = RunDir


# -------------------------------------------------------------------------------------------------
# helpers
# -------------------------------------------------------------------------------------------------


def _new_figure(ncols: int = 1, nrows: int = 1, width: float = 6.4, height: float = 4.2):
    """A figure on the Agg canvas and its axes as a flat list."""
    fig = Figure(figsize=(width * ncols, height * nrows), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    return fig, list(axes.ravel())


def _partial_note(run: Run) -> str:
    """Suffix for titles of a partial run directory."""
    if not run.partial:
        return ""
    steps = env_steps_axis(run)
    total = run.cfg.get("total_env_steps")
    last = int(steps[-1]) if len(steps) else 0
    return f"\n[partial: {last:,} of {total:,} env steps]" if total else "\n[partial]"


def _steps_axis(ax: Axes) -> None:
    """Env steps on the x axis with engineering ticks (100k, 1M)."""
    ax.xaxis.set_major_formatter(EngFormatter(sep=""))
    ax.set_xlabel("environment steps")
    ax.grid(alpha=0.3)


def _eval_every(run: Run) -> int:
    """Env steps per evaluation period (config, else the spacing of the evaluations)."""
    value = run.cfg.get("eval_every")
    if value:
        return int(value)
    steps = env_steps_axis(run)
    return int(steps[1] - steps[0]) if len(steps) > 1 else int(steps[0])


def trace_env_steps(run: Run) -> np.ndarray:
    """[P * T] env steps of the trace points: period p, slice j -> (p + (j + 1) / T) * eval_every.

    Trace shape [R, P, T] is read from ``uncertainty_trace``.
    """
    periods, per_eval = run.metrics["uncertainty_trace"].shape[1:3]
    p = np.arange(periods)[:, None]
    j = np.arange(per_eval)[None, :]
    return ((p + (j + 1) / per_eval) * _eval_every(run)).ravel()


def _field(run: Run, cell: Cell, name: str, default: Any = None) -> Any:
    """A field of a cell (its first run; runs of a cell differ only in seed)."""
    return run_field(run, cell.runs[0], name, default)


def _queries(run: Run, cell: Cell) -> bool:
    """Whether the cell asks for demonstrations at all."""
    return _field(run, cell, "strategy", "none") != "none"


def uncertainty_title(run: Run, uncertainty: str | None, default: str) -> str:
    """What u(s) is for the run's agent family under this uncertainty measure (a panel's title)."""
    return REGISTRY[run.agent].uncertainty_titles.get(uncertainty or "", default)


def _colors(n: int) -> list[Any]:
    """n distinguishable colours (tab10, tab20, then viridis)."""
    if n <= 10:
        return [colormaps["tab10"](i) for i in range(n)]
    if n <= 20:
        return [colormaps["tab20"](i) for i in range(n)]
    return [colormaps["viridis"](x) for x in np.linspace(0, 0.95, n)]


def _cell_colors(cells: list[Cell]) -> dict[Any, Any]:
    """One colour per cell of the run, the same in every figure."""
    return dict(zip([c.cell for c in cells], _colors(len(cells)), strict=True))


def _by_uncertainty(run: Run, cells: list[Cell]) -> list[tuple[str | None, list[Cell]]]:
    """Cells split by uncertainty measure if both are present (intrinsic first), else one group."""
    present = [u for u in UNCERTAINTIES if any(_field(run, c, "uncertainty") == u for c in cells)]
    if len(present) < 2:
        return [(present[0] if present else None, cells)]
    return [(u, [c for c in cells if _field(run, c, "uncertainty") == u]) for u in present]


def _interval_band(
    ax: Axes, x: np.ndarray, lo: np.ndarray, hi: np.ndarray, color: Any, alpha: float = 0.18
) -> None:
    """Shade a 95% interval [lo, hi] along x where it is defined (a point with one seed, or one
    run per side, has none: nan)."""
    defined = np.isfinite(lo) & np.isfinite(hi)
    if defined.any():
        ax.fill_between(x, lo, hi, where=defined, color=color, alpha=alpha, lw=0)


def _legend(ax: Axes) -> None:
    """A small legend, two columns when crowded."""
    handles, _ = ax.get_legend_handles_labels()
    if handles:
        ax.legend(fontsize=7, ncol=1 if len(handles) <= 7 else 2, loc="best", framealpha=0.8)


def moving_average(y: np.ndarray, window: int) -> np.ndarray:
    """Trailing moving average ignoring NaNs; the first points average what is there so far."""
    y = np.asarray(y, dtype=np.float64)
    finite = np.isfinite(y)
    csum = np.concatenate([[0.0], np.cumsum(np.where(finite, y, 0.0))])
    count = np.concatenate([[0], np.cumsum(finite)])
    idx = np.arange(1, y.size + 1)
    lo = np.maximum(idx - window, 0)
    n = count[idx] - count[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, (csum[idx] - csum[lo]) / n, np.nan)


def uncertainty_before_depletion(run: Run, index: int) -> tuple[np.ndarray, np.ndarray]:
    """Run ``index``'s uncertainty trace flattened over periods and cut at budget depletion.

    Returns (env steps, u) up to and including the first trace point whose cumulative demonstrations
    reach the run's budget (that slice still had queries in it); the whole run when the budget is
    never reached or the run does not query.
    """
    metrics = run.metrics
    x = trace_env_steps(run)
    u = np.asarray(metrics["uncertainty_trace"][index], dtype=np.float64).ravel()
    if run_field(run, index, "strategy", "none") == "none" or "demos_trace" not in metrics:
        return x, u
    demos = np.asarray(metrics["demos_trace"][index]).ravel()
    budget = run_field(run, index, "budget")
    hit = np.flatnonzero(demos >= budget) if budget is not None else np.array([], int)
    stop = int(hit[0]) + 1 if hit.size else u.size
    return x[:stop], u[:stop]


def _min_max(u: np.ndarray) -> np.ndarray:
    """Min-max normalise to [0, 1]; NaN when the series is constant or empty."""
    finite = u[np.isfinite(u)]
    if finite.size < 2 or finite.max() == finite.min():
        return np.full_like(u, np.nan)
    return (u - finite.min()) / (finite.max() - finite.min())


def _seed_run(run: Run, cell: Cell) -> int:
    """The run of the cell with seed 0 (else its smallest seed)."""
    seeds = [s if s is not None else math.inf for s in cell.seeds]
    return cell.runs[int(np.argmin(seeds))]


# -------------------------------------------------------------------------------------------------
# figures
# -------------------------------------------------------------------------------------------------


def fig3_uncertainty(run: Run) -> Figure | None:
    """Fig. 3: moving average of the min-max normalised uncertainty before budget depletion.

    Per run: the uncertainty trace flattened over periods, cut where the demonstrations reach the
    budget (`uncertainty_before_depletion`), min-max normalised, then a trailing moving average of
    `SMOOTH_WINDOW` points. Per cell: the mean over seeds, drawn where at least half of the seeds
    have not yet depleted their budget. One line per querying cell, one panel per uncertainty
    measure when both are present. Without querying cells it shows every cell's whole run.
    """
    metrics = run.metrics
    if "uncertainty_trace" not in metrics or metrics["uncertainty_trace"].shape[1] == 0:
        return None
    cells = group_cells(run)
    colors = _cell_colors(cells)
    querying = [c for c in cells if _queries(run, c)]
    whole_run = not querying
    shown = cells if whole_run else querying
    x_all = trace_env_steps(run)
    groups = _by_uncertainty(run, shown)
    fig, axes = _new_figure(ncols=len(groups))
    drawn = 0
    for ax, (uncertainty, group) in zip(axes, groups, strict=True):
        for cell in group:
            series = np.full((len(cell.runs), x_all.size), np.nan)
            for row, index in enumerate(cell.runs):
                x, u = (
                    (x_all, np.asarray(metrics["uncertainty_trace"][index], float).ravel())
                    if whole_run
                    else uncertainty_before_depletion(run, index)
                )
                smooth = moving_average(_min_max(u), SMOOTH_WINDOW)
                series[row, : x.size] = smooth
            count = np.isfinite(series).sum(axis=0)
            enough = count >= max(1, math.ceil(len(cell.runs) / 2))
            if not enough.any():
                continue
            mean = np.nansum(series, axis=0) / np.maximum(count, 1)
            mean = np.where(enough, mean, np.nan)
            ax.plot(x_all, mean, color=colors[cell.cell], lw=1.5, label=cell_name(run, cell))
            drawn += 1
        ax.set_ylabel(f"normalised uncertainty (moving avg, {SMOOTH_WINDOW} points)")
        ax.set_title(uncertainty_title(run, uncertainty, "Uncertainty u(s)"), fontsize=10)
        _steps_axis(ax)
        _legend(ax)
    if not drawn:  # every trace constant or NaN: nothing to normalise
        return None
    span = "whole run (no cell queries)" if whole_run else "before budget depletion"
    fig.suptitle(f"Fig. 3: normalised uncertainty {span}, mean over seeds" + _partial_note(run))
    return fig


def fig4_5_returns(run: Run) -> Figure | None:
    """Figs. 4 and 5: evaluation return vs env steps per cell (mean over seeds, 95% CI band).

    Two panels when both uncertainty measures are present: intrinsic (SAC, Fig. 4) and extrinsic
    (Noisy SAC, Fig. 5). The expert's return is the black line when known.
    """
    metrics = run.metrics
    if run.periods == 0:
        return None
    cells = group_cells(run)
    colors = _cell_colors(cells)
    steps = env_steps_axis(run)
    expert = expert_return(run)
    groups = _by_uncertainty(run, cells)
    fig, axes = _new_figure(ncols=len(groups))
    marker = "o" if len(steps) <= 3 else None
    for ax, (uncertainty, group) in zip(axes, groups, strict=True):
        for cell in group:
            mean, half = mean_ci95_columns(metrics["eval_return"][cell.runs])
            color = colors[cell.cell]
            ax.plot(steps, mean, color=color, lw=1.5, marker=marker, label=cell_name(run, cell))
            _interval_band(ax, steps, mean - half, mean + half, color)
        if math.isfinite(expert):
            ax.axhline(expert, color="black", lw=1.5, label=f"expert ({expert:.0f})")
        title = uncertainty_title(run, uncertainty, "Evaluation return")
        if uncertainty is not None:
            title = ("Fig. 4 — " if uncertainty == "intrinsic" else "Fig. 5 — ") + title
        ax.set_title(title, fontsize=10)
        ax.set_ylabel("evaluation return (deterministic policy)")
        _steps_axis(ax)
        _legend(ax)
    fig.suptitle("Evaluation return, mean and 95% CI over seeds" + _partial_note(run))
    return fig


def _fig_parameter(run: Run, strategy: str, param: str, label: str, number: int) -> Figure | None:
    """Figs. 6 and 7: a query-strategy parameter's effect (learning curves and final return)."""
    metrics = run.metrics
    cells = [c for c in group_cells(run) if _field(run, c, "strategy") == strategy]
    if not cells or run.periods == 0:
        return None
    # Lines: cells that differ in anything swept but the strategy's parameter. t_query is irrelevant
    # to bernoulli and query_prob to active, so a full grid's duplicates collapse to their first
    # cell (same seeds, same program: pooling them would shrink the CI without new information).
    key_fields = [f for f in swept_fields(run) if f not in ("strategy", "query_prob", "t_query")]
    lines: dict[tuple, dict[float, Cell]] = {}
    for cell in cells:
        key = tuple(_field(run, cell, f) for f in key_fields)
        lines.setdefault(key, {}).setdefault(float(_field(run, cell, param)), cell)
    values = sorted({v for line in lines.values() for v in line})
    value_colors = dict(
        zip(
            values,
            [colormaps["viridis"](x) for x in np.linspace(0.0, 0.9, len(values))],
            strict=True,
        )
    )
    line_colors = _colors(len(lines))
    steps = env_steps_axis(run)
    expert = expert_return(run)
    fig, (curves, finals) = _new_figure(ncols=2)
    for k, line in enumerate(lines.values()):
        first = next(iter(line.values()))
        name = cell_name(run, first, exclude=(param,))
        style = _LINESTYLES[k % len(_LINESTYLES)]
        xs, means, halves = [], [], []
        for value in sorted(line):
            cell = line[value]
            mean, _ = mean_ci95_columns(metrics["eval_return"][cell.runs])
            suffix = f" ({name})" if len(lines) > 1 else ""
            curves.plot(
                steps,
                mean,
                color=value_colors[value],
                ls=style,
                lw=1.4,
                label=f"{SHORT_NAMES.get(param, param)}={value:g}{suffix}",
            )
            final_mean, final_half = mean_ci95(metrics["eval_return"][cell.runs, -1])
            xs.append(value)
            means.append(final_mean)
            halves.append(final_half if math.isfinite(final_half) else 0.0)
        finals.errorbar(
            xs,
            means,
            yerr=halves,
            color=line_colors[k],
            ls=style,
            marker="o",
            capsize=4,
            lw=1.4,
            label=name,
        )
    for ax in (curves, finals):
        if math.isfinite(expert):
            ax.axhline(expert, color="black", lw=1.2, label=f"expert ({expert:.0f})")
        ax.grid(alpha=0.3)
    curves.set_title(f"Evaluation return for each {label} (mean over seeds)", fontsize=10)
    curves.set_ylabel("evaluation return")
    _steps_axis(curves)
    finals.set_title(f"Final return vs {label} (mean ± 95% CI)", fontsize=10)
    finals.set_xlabel(label)
    finals.set_ylabel(f"evaluation return at {int(steps[-1]):,} env steps")
    if len(values) == 1:
        finals.set_xlim(values[0] - 0.1, values[0] + 0.1)
    _legend(curves)
    _legend(finals)
    fig.suptitle(f"Fig. {number}: effect of the {label}" + _partial_note(run))
    return fig


def fig6_bernoulli(run: Run) -> Figure | None:
    """Fig. 6: final return (mean ± 95% CI) vs Bernoulli probability b, one line per uncertainty
    (and other swept fields), next to the learning curve of each b."""
    return _fig_parameter(run, "bernoulli", "query_prob", "Bernoulli probability b", 6)


def fig7_active(run: Run) -> Figure | None:
    """Fig. 7: final return (mean ± 95% CI) vs proportion threshold t_query of the active strategy,
    next to the learning curve of each t_query."""
    return _fig_parameter(run, "active", "t_query", "proportion threshold t_query", 7)


def _pca_2d(fit: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """Projection onto the first two principal components of ``fit`` [N, D] (numpy SVD)."""
    center = fit.mean(axis=0)
    _, _, vt = np.linalg.svd(fit - center, full_matrices=False)
    basis = vt[:2].T  # [D, <=2]
    if basis.shape[1] < 2:
        basis = np.pad(basis, ((0, 0), (0, 2 - basis.shape[1])))
    return lambda x: (x - center) @ basis


def fig8_states(run: Run, max_panels: int = 4) -> Figure | None:
    """Fig. 8: visited (grey) and queried (orange) states projected to 2-D by PCA.

    PCA is fitted on the visited states pooled over the runs of the cell; each panel shows the
    seed-0 run of one querying cell. Up to ``max_panels`` cells, taken in turn from the active,
    bernoulli and greedy cells (the paper shows AQSAC and BQSAC).
    """
    metrics = run.metrics
    needed = ("visited_obs", "visited_valid", "queried_obs", "queried_valid")
    if any(k not in metrics for k in needed):
        return None
    candidates: dict[str, list[Cell]] = {"active": [], "bernoulli": [], "greedy": []}
    for cell in group_cells(run):
        strategy = _field(run, cell, "strategy")
        if strategy in candidates and np.any(metrics["queried_valid"][cell.runs]):
            candidates[strategy].append(cell)
    chosen: list[Cell] = []
    while len(chosen) < max_panels and any(candidates.values()):
        for strategy in ("active", "bernoulli", "greedy"):
            if candidates[strategy] and len(chosen) < max_panels:
                chosen.append(candidates[strategy].pop(0))
    if not chosen:
        return None
    ncols, nrows = (len(chosen), 1) if len(chosen) <= 2 else (2, 2)
    fig, axes = _new_figure(ncols=ncols, nrows=nrows, width=5.2, height=4.4)
    for ax in axes[len(chosen) :]:
        ax.set_visible(False)
    for ax, cell in zip(axes, chosen, strict=False):
        idx = cell.runs
        pooled = metrics["visited_obs"][idx][metrics["visited_valid"][idx]].astype(np.float64)
        index = _seed_run(run, cell)
        visited = metrics["visited_obs"][index][metrics["visited_valid"][index]]
        queried = metrics["queried_obs"][index][metrics["queried_valid"][index]]
        if pooled.shape[0] < 2:
            pooled = np.concatenate([pooled, queried.astype(np.float64)])
        project = _pca_2d(pooled)
        v2, q2 = project(visited), project(queried)
        ax.scatter(
            v2[:, 0], v2[:, 1], s=5, color="0.6", alpha=0.5, lw=0, label=f"visited ({len(v2)})"
        )
        ax.scatter(
            q2[:, 0],
            q2[:, 1],
            s=14,
            color="orange",
            edgecolor="0.2",
            lw=0.3,
            label=f"queried ({len(q2)})",
        )
        seed = run_field(run, index, "seed")
        ax.set_title(f"{cell_name(run, cell)}, seed {seed}", fontsize=10)
        ax.set_xlabel("PC 1")
        ax.set_ylabel("PC 2")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="best", markerscale=1.5)
    fig.suptitle(
        "Fig. 8: visited and queried states (PCA of the visited states, uniform samples)"
        + _partial_note(run)
    )
    return fig


def fig9_budget(run: Run) -> Figure | None:
    """Fig. 9: cumulative demonstrations vs env steps per querying cell (mean over seeds), with the
    budget as a dashed line."""
    metrics = run.metrics
    if "demos_trace" not in metrics or metrics["demos_trace"].shape[1] == 0:
        return None
    cells = group_cells(run)
    colors = _cell_colors(cells)
    querying = [c for c in cells if _queries(run, c)]
    if not querying:
        return None
    x = trace_env_steps(run)
    fig, (ax,) = _new_figure()
    budgets: dict[float, Any] = {}
    for cell in querying:
        demos = np.asarray(metrics["demos_trace"][cell.runs], dtype=np.float64)
        mean = np.nanmean(demos.reshape(len(cell.runs), -1), axis=0)
        ax.plot(x, mean, color=colors[cell.cell], lw=1.5, label=cell_name(run, cell))
        budget = _field(run, cell, "budget")
        if budget is not None:
            budgets.setdefault(float(budget), colors[cell.cell])
    for budget, color in budgets.items():
        ax.axhline(
            budget,
            color="black" if len(budgets) == 1 else color,
            ls="--",
            lw=1.2,
            label=f"budget ({budget:,.0f})",
        )
    ax.set_ylim(bottom=0)
    ax.set_ylabel("cumulative demonstrations (env steps)")
    ax.set_title("Fig. 9: budget spending, mean over seeds" + _partial_note(run), fontsize=10)
    _steps_axis(ax)
    _legend(ax)
    return fig


PERCENT = (0.0, 100.0)
"""The range of a share drawn in percent."""
NON_NEGATIVE = (0.0, np.inf)
"""The range of a count or a length."""


class Panel(NamedTuple):
    """One panel of `_cell_bands`: a metric of `metrics.npz` drawn as `scale` x its value, with
    the range its mean can take (its 95% band is cut to it)."""

    metric: str
    title: str
    ylabel: str
    scale: float
    bounds: tuple[float, float]


def _cell_bands(run: Run, panels: list[Panel], suptitle: str) -> Figure:
    """One panel per `Panel`: the metric per period and cell, mean and 95% CI over seeds (periods
    where a seed has no value, nan, are left out of that seed's mean). The band is cut to the
    panel's bounds: Student's t interval of a few seeds' shares can reach past 100% or below 0,
    where the true mean cannot be, so the cut band still covers it."""
    metrics, cells, steps = run.metrics, group_cells(run), env_steps_axis(run)
    colors = _cell_colors(cells)
    fig, axes = _new_figure(ncols=len(panels))
    for ax, panel in zip(axes, panels, strict=True):
        low, high = panel.bounds
        for cell in cells:
            values = panel.scale * np.asarray(metrics[panel.metric], float)[cell.runs]
            mean, half = mean_ci95_columns(values)
            color = colors[cell.cell]
            ax.plot(steps, mean, color=color, lw=1.5, label=cell_name(run, cell))
            band = np.clip(mean - half, low, high), np.clip(mean + half, low, high)
            _interval_band(ax, steps, *band, color)
        ax.set_ylabel(panel.ylabel)
        ax.set_title(panel.title, fontsize=10)
        _steps_axis(ax)
        _legend(ax)
    fig.suptitle(suptitle + _partial_note(run))
    return fig


def fig_gait(run: Run) -> Figure | None:
    """The gait: % of visited training states (left) and of evaluation states (right) with the
    torso upside down, per period and cell, mean and 95% CI over seeds. A run that learned the
    flipped local optimum sits near 100% (`gait.upside_down`). Runs with the metric, of a task with
    a gait rule (HalfCheetah), only."""
    metrics = run.metrics
    if run.periods == 0 or "upside_down" not in metrics or not has_gait_rule(run):
        return None
    ylabel = "% of states upside down (|pitch| > 90°)"
    panels = [
        Panel(name, f"Gait: {title}", ylabel, 100.0, PERCENT)
        for name, title in (
            ("upside_down", "visited training states"),
            ("eval_upside_down", "evaluation"),
        )
        if name in metrics
    ]
    fig = _cell_bands(run, panels, "Upside-down (flipped) gait, mean and 95% CI over seeds")
    for ax in fig.axes:
        ax.set_ylim(-3, 103)
    return fig


def fig_falls(run: Run) -> Figure | None:
    """Health on a task where a fall ends the episode: % of the training episodes finished in each
    period that ended by a fall (left), their mean length (middle), and % of the evaluation
    episodes that fell (right), per cell, mean and 95% CI over seeds. Runs with a fall only
    (`summary.has_falls`)."""
    if run.periods == 0 or not has_falls(run):
        return None
    panels = [
        Panel("fell", "Training episodes that fell", "% of finished episodes", 100.0, PERCENT),
        Panel(
            "episode_length",
            "Training episode length",
            "mean length (env steps)",
            1.0,
            NON_NEGATIVE,
        ),
        Panel(
            "eval_fell", "Evaluation episodes that fell", "% of evaluation episodes", 100.0, PERCENT
        ),
    ]
    return _cell_bands(run, panels, "Falls and episode length, mean and 95% CI over seeds")


INTRINSIC_MINUS_EXTRINSIC = "intrinsic - extrinsic"
"""`fig_pairs`' panel of the pairs of one strategy under the two uncertainty measures."""


def fig_pairs(run: Run) -> Figure | None:
    """The paper's comparisons along the run: for each pair of `compare.comparison_pairs`
    (AQSAC - BQSAC, ..., intrinsic - extrinsic), the difference of the cells' mean evaluation
    returns over seeds at every evaluation, with Welch's 95% interval as its band (the reading
    rule of `comparison.md`), and dotted lines where `comparison.md` also reads the pairs (a quarter,
    half and three quarters of the run). So a reader sees whether, and when, a ranking changes with the length of
    the run. One panel per uncertainty measure for the pairs with an active cell, one for
    intrinsic - extrinsic. Runs with pairs only."""
    if run.periods == 0:
        return None
    pairs = comparison_pairs(run)
    if not pairs:
        return None
    eval_return = np.asarray(run.metrics["eval_return"], np.float64)
    steps = env_steps_axis(run)
    colors = _cell_colors(group_cells(run))
    panels: dict[str, list[tuple[str, Cell, Cell]]] = {}
    for name, a, b in pairs:
        same_strategy = _field(run, a, "strategy", "none") == _field(run, b, "strategy", "none")
        panel = (
            INTRINSIC_MINUS_EXTRINSIC
            if same_strategy
            else _field(run, a, "uncertainty", "intrinsic")
        )
        panels.setdefault(panel, []).append((name, a, b))
    fig, axes = _new_figure(ncols=len(panels))
    for ax, (panel, members) in zip(axes, panels.items(), strict=True):
        for name, a, b in members:
            x, y = eval_return[a.runs], eval_return[b.runs]
            diff = x.mean(axis=0) - y.mean(axis=0)
            lo, hi = np.array([welch_ci95(x[:, p], y[:, p]) for p in range(len(steps))]).T
            color = colors[(a if panel == INTRINSIC_MINUS_EXTRINSIC else b).cell]
            ax.plot(steps, diff, color=color, lw=1.5, label=name)
            _interval_band(ax, steps, lo, hi, color)
        ax.axhline(0.0, color="black", lw=1.0)
        for at in reading_steps(run):
            ax.axvline(at, color="grey", ls=":", lw=1.0)
        if panel == INTRINSIC_MINUS_EXTRINSIC:
            title = "Each strategy, intrinsic − extrinsic uncertainty"
        else:
            title = uncertainty_title(run, panel, panel)
        ax.set_title(title, fontsize=10)
        ax.set_ylabel("a − b, evaluation return")
        _steps_axis(ax)
        _legend(ax)
    fig.suptitle(
        "Pairs along the run: difference of mean return, Welch's 95% CI" + _partial_note(run)
    )
    return fig


FIGURES: dict[str, Callable[[Run], Figure | None]] = {
    "fig3_uncertainty": fig3_uncertainty,
    "fig4_5_returns": fig4_5_returns,
    "fig6_bernoulli": fig6_bernoulli,
    "fig7_active": fig7_active,
    "fig8_states": fig8_states,
    "fig9_budget": fig9_budget,
    "gait": fig_gait,
    "falls": fig_falls,
    "pairs": fig_pairs,
}
"""File stem -> figure function, in paper order."""


def plot_all(run_dir: str | Path) -> list[Path]:
    """Write every figure the run has data for to ``run_dir/figures/<name>.png``; return the paths.

    Figures without data (e.g. Fig. 7 without active cells, Fig. 8 without queried states) are
    skipped, not errors. Raises FileNotFoundError like `load_run` when the directory is incomplete.
    """
    run = load_run(run_dir)
    out_dir = run.path / "figures"
    out_dir.mkdir(exist_ok=True)
    paths = []
    for name, make in FIGURES.items():
        fig = make(run)
        if fig is None:
            continue
        path = out_dir / f"{name}.png"
        fig.savefig(path, dpi=DPI)
        fig.clear()
        paths.append(path)
    return paths


STRATEGY_COLORS: dict[str, Any] = {s: colormaps["tab10"](i) for i, s in enumerate(STRATEGIES)}
"""One colour per query strategy, the same in every panel of Fig. 1."""


def fig1_agents(group_dir: str | Path) -> Figure | None:
    """Fig. 1: evaluation return vs env steps of each agent under each query strategy, mean over
    seeds with its 95% CI band, as the paper draws it (Noisy TD3 left, Bootstrapped TD3 right).

    One panel per agent variant of the group (`arld_jax.run plot` of a `SweepGroup` directory):
    a member is split by uncertainty measure, so the `fig1` preset's TD3 member gives TD3 and
    Noisy TD3, and its Bootstrapped TD3 member the third panel. One curve per cell, in the
    paper's names (AQNoisyTD3, BQBootTD3, ...), a strategy in the same colour in every panel;
    cells of one strategy that differ in another swept field take other line styles."""
    runs = [load_run(member) for member in group_members(group_dir)]
    panels = [
        (run, uncertainty, cells)
        for run in runs
        if run.periods
        for uncertainty, cells in _by_uncertainty(run, group_cells(run))
    ]
    if not panels:
        return None
    fig = Figure(figsize=(5.0 * len(panels), 4.6), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(panels), squeeze=False, sharey=True)[0]
    for ax, (run, uncertainty, cells) in zip(axes, panels, strict=True):
        steps = env_steps_axis(run)
        drawn: dict[str, int] = {}
        for cell in cells:
            strategy = _field(run, cell, "strategy", "none")
            style = _LINESTYLES[drawn.get(strategy, 0) % len(_LINESTYLES)]
            drawn[strategy] = drawn.get(strategy, 0) + 1
            color = STRATEGY_COLORS.get(strategy, "0.4")
            mean, half = mean_ci95_columns(run.metrics["eval_return"][cell.runs])
            ax.plot(steps, mean, color=color, ls=style, lw=1.5, label=cell_name(run, cell))
            _interval_band(ax, steps, mean - half, mean + half, color, alpha=0.15)
        expert = expert_return(run)
        if math.isfinite(expert):
            ax.axhline(expert, color="black", lw=1.2, label=f"expert ({expert:.0f})")
        display = REGISTRY[run.agent].variant(uncertainty or "intrinsic")
        ax.set_title(uncertainty_title(run, uncertainty, display), fontsize=10)
        _steps_axis(ax)
        _legend(ax)
    axes[0].set_ylabel("evaluation return (deterministic policy)")
    partial = next((_partial_note(run) for run in runs if run.partial), "")
    fig.suptitle(
        "Fig. 1: evaluation return per agent and query strategy, mean and 95% CI over seeds"
        + partial
    )
    return fig


def plot_group(group_dir: str | Path) -> Path | None:
    """Write Fig. 1 (`fig1_agents`) of a group's members to group_dir/figures/fig1_agents.png and
    return its path (None before any member has an evaluation)."""
    group_dir = Path(group_dir)
    fig = fig1_agents(group_dir)
    if fig is None:
        return None
    out = group_dir / "figures"
    out.mkdir(exist_ok=True)
    path = out / "fig1_agents.png"
    fig.savefig(path, dpi=DPI)
    fig.clear()
    return path
