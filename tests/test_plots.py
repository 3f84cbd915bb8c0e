"""The paper's figures (arld_jax.plots) tested through what they draw, on synthetic run directories.

Each figure function returns a matplotlib `Figure`; the tests read back its lines (x and y data),
bands, error bars, scatter points, legend texts, titles and axis labels, and compare them with
values computed here straight from the files (``metrics.npz`` and ``runs.json``), not through
`arld_jax.stats`. The run directories are those of tests/test_results.py (`write_run_dir`),
with seed 2's returns raised by SKEW so that a cell's mean over seeds is not its median:
eval_return[run, p] = 100 (cell + 1)(p + 1) + (0, 10, 60) for seeds (0, 1, 2), whose mean over
seeds (+ 70 / 3) and 95% CI can be worked out on paper.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from scipy import stats
from test_results import (
    BUDGET,
    DEMO_RATE,
    EVAL_EVERY,
    NONE_AND_BERNOULLI,
    PERIODS,
    SEEDS,
    TRACES,
    write_run_dir,
)

from arld_jax import plots, rundir
from arld_jax.stats import mean_ci95_columns

SAC_CELLS = [
    {"strategy": "none"},
    {"strategy": "greedy"},
    {"strategy": "bernoulli", "query_prob": 0.2},
    {"strategy": "active", "t_query": 0.1},
]
SAC_SWEEP = {"strategy": [c["strategy"] for c in SAC_CELLS]}
SAC_NAMES = ["SAC", "GQSAC", "BQSAC b=0.2", "AQSAC t_query=0.1"]
"""The paper's names of SAC_CELLS (a swept strategy; b and t_query shown where they apply)."""

NONE_AND_BERNOULLI_SWEEP = {"strategy": ["none", "bernoulli"]}

FULL_CELLS = [
    {"strategy": "none", "uncertainty": "intrinsic"},
    {"strategy": "active", "uncertainty": "intrinsic", "t_query": 0.1},
    {"strategy": "active", "uncertainty": "intrinsic", "t_query": 0.3},
    {"strategy": "bernoulli", "uncertainty": "extrinsic", "query_prob": 0.2},
    {"strategy": "bernoulli", "uncertainty": "extrinsic", "query_prob": 0.4},
    {"strategy": "active", "uncertainty": "extrinsic", "t_query": 0.1},
]
FULL_SWEEP = {
    "strategy": ["none", "bernoulli", "active"],
    "uncertainty": ["intrinsic", "extrinsic"],
    "query_prob": [0.2, 0.4],
    "t_query": [0.1, 0.3],
}
FULL_PERIODS = 3  # of 4: a partial run directory

SKEW = 40.0
"""Added to seed 2's eval_return: seed offsets 0, 10, 60, mean 70 / 3, median 10."""
SEED_OFFSET_MEAN = 70.0 / 3
HALF_SKEWED = 79.8539
"""95% CI half-width of offsets (0, 10, 60): sd = sqrt(((70/3)^2 + (40/3)^2 + (110/3)^2) / 2)
= 32.1455; t(0.975, 2) = 4.302653; 4.302653 * 32.1455 / sqrt(3) = 79.8539."""

TRACE_X = np.arange(1, PERIODS * TRACES + 1) * EVAL_EVERY / TRACES
"""Env steps of the trace points: slice j of period p ends at (p T + j + 1) eval_every / T."""


@pytest.fixture
def sac_dir(tmp_path: Path) -> Path:
    """SAC, GQSAC, BQSAC b=0.2 and AQSAC t_query=0.1, 3 seeds, 4 periods, expert 3000."""
    return _skewed(write_run_dir(tmp_path / "sac", SAC_CELLS, SAC_SWEEP))


@pytest.fixture
def full_dir(tmp_path: Path) -> Path:
    """Both uncertainty measures, two t_query and two b values; 3 of 4 periods present."""
    path = write_run_dir(
        tmp_path / "full", FULL_CELLS, FULL_SWEEP, periods=FULL_PERIODS, total_periods=4
    )
    return _skewed(path)


def _skewed(path: Path) -> Path:
    """Raise seed 2's eval_return by SKEW (in metrics.npz)."""
    metrics = dict(np.load(path / "metrics.npz"))
    runs = json.loads((path / "runs.json").read_text())
    seed2 = [entry["run"] for entry in runs if entry["seed"] == 2]
    metrics["eval_return"][seed2] += SKEW
    np.savez(path / "metrics.npz", **metrics)
    return path


# ---------------------------------------------------------------- reading the files and the figure


def _files(path: Path) -> tuple[dict[str, np.ndarray], dict[int, list[int]]]:
    """metrics.npz as arrays, and each cell's run indices from runs.json."""
    metrics = dict(np.load(path / "metrics.npz"))
    runs = json.loads((path / "runs.json").read_text())
    cells: dict[int, list[int]] = {}
    for entry in runs:
        cells.setdefault(entry["cell"], []).append(entry["run"])
    return metrics, cells


def _lines(ax: Axes) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Label -> (x, y) of every labelled line of the axes."""
    return {
        line.get_label(): (np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float))
        for line in ax.get_lines()
        if not line.get_label().startswith("_")
    }


def _legend(ax: Axes) -> list[str]:
    return [text.get_text() for text in ax.get_legend().get_texts()]


def _band(ax: Axes, label_index: int) -> dict[float, tuple[float, float]]:
    """x -> (lowest, highest) y of the `label_index`-th CI band (fill_between) of the axes."""
    vertices = ax.collections[label_index].get_paths()[0].vertices
    out: dict[float, tuple[float, float]] = {}
    for x in np.unique(vertices[:, 0]):
        ys = vertices[vertices[:, 0] == x, 1]
        out[float(x)] = (float(ys.min()), float(ys.max()))
    return out


def _seed_mean(values: np.ndarray, runs: list[int]) -> np.ndarray:
    return np.asarray(values, float)[runs].mean(axis=0)


def _make(fig: Figure | None) -> Figure:
    assert isinstance(fig, Figure)
    return fig


# ---------------------------------------------------------------- Figs. 4 and 5: returns


def test_fig4_draws_each_cells_seed_mean_return_with_its_ci(sac_dir: Path) -> None:
    metrics, cells = _files(sac_dir)
    fig = _make(plots.fig4_5_returns(rundir.load_run(sac_dir)))
    (ax,) = fig.axes
    steps = metrics["env_steps"][0]
    np.testing.assert_array_equal(steps, [1000, 2000, 3000, 4000])
    lines = _lines(ax)
    assert _legend(ax) == [*SAC_NAMES, "expert (3000)"]
    for c, name in enumerate(SAC_NAMES):
        x, y = lines[name]
        np.testing.assert_array_equal(x, steps)
        mean = _seed_mean(metrics["eval_return"], cells[c])
        np.testing.assert_allclose(y, mean)
        np.testing.assert_allclose(mean, 100.0 * (c + 1) * np.arange(1, 5) + SEED_OFFSET_MEAN)
        # the band is mean -+ t(0.975, 2) sd / sqrt(3) of the seed offsets (0, 10, 60)
        band = _band(ax, c)
        assert sorted(band) == list(steps)
        for p, s in enumerate(steps):
            want = (mean[p] - HALF_SKEWED, mean[p] + HALF_SKEWED)
            np.testing.assert_allclose(band[s], want, atol=1e-4)
    np.testing.assert_allclose(lines["expert (3000)"][1], [3000.0, 3000.0])
    assert ax.get_title() == "Fig. 4 — Intrinsic uncertainty: SAC σθ(s)"
    assert ax.get_xlabel() == "environment steps"
    assert ax.get_ylabel() == "evaluation return (deterministic policy)"
    assert fig.get_suptitle() == "Evaluation return, mean and 95% CI over seeds"


def test_fig4_and_fig5_split_the_uncertainty_measures_of_a_partial_run(full_dir: Path) -> None:
    metrics, cells = _files(full_dir)
    fig = _make(plots.fig4_5_returns(rundir.load_run(full_dir)))
    intrinsic, extrinsic = fig.axes
    assert intrinsic.get_title() == "Fig. 4 — Intrinsic uncertainty: SAC σθ(s)"
    assert extrinsic.get_title() == "Fig. 5 — Extrinsic uncertainty: Noisy SAC Var[μ̃θ]"
    expert = "expert (3000)"
    assert _legend(intrinsic) == ["SAC", "AQSAC t_query=0.1", "AQSAC t_query=0.3", expert]
    assert _legend(extrinsic) == [
        "BQNoisySAC b=0.2",
        "BQNoisySAC b=0.4",
        "AQNoisySAC t_query=0.1",
        expert,
    ]
    names = {0: "SAC", 1: "AQSAC t_query=0.1", 2: "AQSAC t_query=0.3"}
    names |= {3: "BQNoisySAC b=0.2", 4: "BQNoisySAC b=0.4", 5: "AQNoisySAC t_query=0.1"}
    for c, name in names.items():
        ax = intrinsic if c < 3 else extrinsic
        x, y = _lines(ax)[name]
        np.testing.assert_array_equal(x, [1000, 2000, 3000])  # the periods present
        np.testing.assert_allclose(y, _seed_mean(metrics["eval_return"], cells[c]))
    assert fig.get_suptitle().endswith("[partial: 3,000 of 4,000 env steps]")


# ---------------------------------------------------------------- Fig. 3: uncertainty


def _normalised_before_depletion(u: np.ndarray, demos: np.ndarray | None) -> np.ndarray:
    """One run's Fig. 3 series over all trace points: the trace up to and including the first
    point whose cumulative demos reach BUDGET, min-max normalised, then the trailing mean of the
    last 5 points (fewer at the start); nan after the cut."""
    depleted = np.flatnonzero(demos >= BUDGET) if demos is not None else []
    stop = depleted[0] + 1 if len(depleted) else u.size
    kept = (u[:stop] - u[:stop].min()) / (u[:stop].max() - u[:stop].min())
    smooth = [kept[max(0, i - 4) : i + 1].mean() for i in range(stop)]
    return np.concatenate([smooth, np.full(u.size - stop, np.nan)])


def test_fig3_averages_the_normalised_uncertainty_of_the_seeds_before_depletion(
    sac_dir: Path,
) -> None:
    metrics, cells = _files(sac_dir)
    fig = _make(plots.fig3_uncertainty(rundir.load_run(sac_dir)))
    (ax,) = fig.axes
    querying = SAC_NAMES[1:]  # plain SAC spends no budget: not in Fig. 3
    assert _legend(ax) == querying
    # Seeds 0, 1, 2 spend 4, 6, 8 demos per trace point (DEMO_RATE): their series end after point
    # 20 (never depleted), 17 and 13. A point is drawn where at least 2 of the 3 seeds have it.
    assert [DEMO_RATE[s] for s in SEEDS] == [4, 6, 8]
    for c, name in enumerate(querying, start=1):
        series = np.stack(
            [
                _normalised_before_depletion(
                    metrics["uncertainty_trace"][r].ravel(), metrics["demos_trace"][r].ravel()
                )
                for r in cells[c]
            ]
        )
        assert [int(np.isfinite(row).sum()) for row in series] == [20, 17, 13]
        expected = np.full(series.shape[1], np.nan)
        expected[:13] = series[:, :13].mean(axis=0)
        expected[13:17] = series[:2, 13:17].mean(axis=0)
        x, y = _lines(ax)[name]
        np.testing.assert_allclose(x, TRACE_X)
        np.testing.assert_allclose(y, expected)
    assert ax.get_title() == "Intrinsic uncertainty: SAC σθ(s)"
    assert ax.get_xlabel() == "environment steps"
    assert ax.get_ylabel() == "normalised uncertainty (moving avg, 5 points)"
    assert fig.get_suptitle() == (
        "Fig. 3: normalised uncertainty before budget depletion, mean over seeds"
    )


def test_fig3_without_queries_draws_the_whole_run(tmp_path: Path) -> None:
    path = write_run_dir(tmp_path / "sac", [{"strategy": "none"}], {}, expert=None)
    metrics, cells = _files(path)
    run = rundir.load_run(path)
    fig = _make(plots.fig3_uncertainty(run))
    (ax,) = fig.axes
    series = [_normalised_before_depletion(metrics["uncertainty_trace"][r].ravel(), None)
              for r in cells[0]]  # fmt: skip
    x, y = _lines(ax)["SAC"]
    np.testing.assert_allclose(x, TRACE_X)
    np.testing.assert_allclose(y, np.mean(series, axis=0))
    span = "whole run (no cell queries)"
    assert fig.get_suptitle() == f"Fig. 3: normalised uncertainty {span}, mean over seeds"
    drawn = [name for name, make in plots.FIGURES.items() if make(run) is not None]
    assert drawn == ["fig3_uncertainty", "fig4_5_returns"]  # nothing queried, no gait


def test_uncertainty_is_cut_at_budget_depletion(tmp_path: Path) -> None:
    path = write_run_dir(tmp_path / "sweep", NONE_AND_BERNOULLI, NONE_AND_BERNOULLI_SWEEP)
    run = rundir.load_run(path)
    x = plots.trace_env_steps(run)
    # period p, slice j -> (p + (j + 1) / 5) * 1000: 200, 400, ..., 4000
    np.testing.assert_allclose(x, TRACE_X)
    np.testing.assert_allclose(x[:3], [200.0, 400.0, 600.0])
    bernoulli_runs = [3, 4, 5]  # cell 1, seeds 0, 1, 2 (see DEMO_RATE)
    lengths = [plots.uncertainty_before_depletion(run, r)[1].size for r in bernoulli_runs]
    assert lengths == [20, 17, 13]
    # a run that never queries keeps its whole trace
    assert plots.uncertainty_before_depletion(run, 0)[1].size == 20


# ---------------------------------------------------------------- Fig. 9: budget


def test_fig9_draws_the_seed_mean_of_the_demonstrations_and_the_budget(sac_dir: Path) -> None:
    metrics, cells = _files(sac_dir)
    fig = _make(plots.fig9_budget(rundir.load_run(sac_dir)))
    (ax,) = fig.axes
    assert _legend(ax) == [*SAC_NAMES[1:], f"budget ({BUDGET})"]
    # Seed s has min(100, (i + 1) DEMO_RATE[s]) demos at trace point i.
    i = np.arange(PERIODS * TRACES)
    by_hand = np.mean([np.minimum(BUDGET, (i + 1) * DEMO_RATE[s]) for s in SEEDS], axis=0)
    for c, name in enumerate(SAC_NAMES[1:], start=1):
        x, y = _lines(ax)[name]
        np.testing.assert_allclose(x, TRACE_X)
        np.testing.assert_allclose(y, _seed_mean(metrics["demos_trace"], cells[c]).ravel())
        np.testing.assert_allclose(y, by_hand)
    np.testing.assert_allclose(_lines(ax)[f"budget ({BUDGET})"][1], [BUDGET, BUDGET])
    assert ax.get_title() == "Fig. 9: budget spending, mean over seeds"
    assert ax.get_xlabel() == "environment steps"
    assert ax.get_ylabel() == "cumulative demonstrations (env steps)"
    assert ax.get_ylim()[0] == 0


# ---------------------------------------------------------------- Figs. 6 and 7: parameters


def _errorbars(ax: Axes) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Label -> (x, y, half-widths) of every error-bar series of the axes."""
    out = {}
    for container in ax.containers:
        data_line, _, (bars,) = container.lines
        segments = np.asarray(bars.get_segments())  # [n, 2 ends, (x, y)]
        half = (segments[:, 1, 1] - segments[:, 0, 1]) / 2
        xy = (np.asarray(data_line.get_xdata(), float), np.asarray(data_line.get_ydata(), float))
        out[container.get_label()] = (*xy, half)
    return out


def test_fig7_draws_a_curve_per_t_query_and_the_final_return_against_it(full_dir: Path) -> None:
    metrics, cells = _files(full_dir)
    fig = _make(plots.fig7_active(rundir.load_run(full_dir)))
    curves, finals = fig.axes
    # Left: one curve per (uncertainty, t_query) of the active cells 1, 2 and 5.
    expected = {"t_query=0.1 (AQSAC)": 1, "t_query=0.3 (AQSAC)": 2, "t_query=0.1 (AQNoisySAC)": 5}
    assert _legend(curves) == [*expected, "expert (3000)"]
    for name, c in expected.items():
        x, y = _lines(curves)[name]
        np.testing.assert_array_equal(x, [1000, 2000, 3000])
        np.testing.assert_allclose(y, _seed_mean(metrics["eval_return"], cells[c]))
    # Right: final return vs t_query per measure; the last period (3) of cell c has seed mean
    # 300 (c + 1) + 70 / 3 and CI half-width HALF_SKEWED.
    bars = _errorbars(finals)
    assert set(bars) == {"AQSAC", "AQNoisySAC"}
    for name, cs in (("AQSAC", [1, 2]), ("AQNoisySAC", [5])):
        x, y, half = bars[name]
        np.testing.assert_allclose(x, [0.1, 0.3][: len(cs)])
        np.testing.assert_allclose(y, [metrics["eval_return"][cells[c], -1].mean() for c in cs])
        np.testing.assert_allclose(y, [300.0 * (c + 1) + SEED_OFFSET_MEAN for c in cs])
        np.testing.assert_allclose(half, HALF_SKEWED, atol=1e-4)
    label = "proportion threshold t_query"
    assert curves.get_title() == f"Evaluation return for each {label} (mean over seeds)"
    assert finals.get_title() == f"Final return vs {label} (mean ± 95% CI)"
    assert finals.get_xlabel() == label
    assert finals.get_ylabel() == "evaluation return at 3,000 env steps"
    assert fig.get_suptitle().startswith("Fig. 7: effect of the proportion threshold t_query")


def test_fig6_draws_a_curve_per_b(full_dir: Path) -> None:
    metrics, cells = _files(full_dir)
    fig = _make(plots.fig6_bernoulli(rundir.load_run(full_dir)))
    curves, finals = fig.axes
    assert _legend(curves) == ["b=0.2", "b=0.4", "expert (3000)"]  # one line: no suffix
    for name, c in (("b=0.2", 3), ("b=0.4", 4)):
        np.testing.assert_allclose(
            _lines(curves)[name][1], _seed_mean(metrics["eval_return"], cells[c])
        )
    x, y, _ = _errorbars(finals)["BQNoisySAC"]
    np.testing.assert_allclose(x, [0.2, 0.4])
    np.testing.assert_allclose(
        y, np.array([1200.0, 1500.0]) + SEED_OFFSET_MEAN
    )  # 300 (c + 1) + 70 / 3
    assert finals.get_xlabel() == "Bernoulli probability b"


# ---------------------------------------------------------------- Fig. 8: states


def test_fig8_projects_visited_and_queried_states_on_the_visited_pca(sac_dir: Path) -> None:
    """Panels: the seed-0 run of the active, bernoulli and greedy cells (in that order). Points: the
    run's valid states projected on the two leading principal axes of its cell's pooled visited
    states (computed here from the covariance's eigenvectors; an axis's sign is arbitrary)."""
    metrics, cells = _files(sac_dir)
    fig = _make(plots.fig8_states(rundir.load_run(sac_dir)))
    panels = [ax for ax in fig.axes if ax.get_visible()]
    order = [(3, "AQSAC t_query=0.1"), (2, "BQSAC b=0.2"), (1, "GQSAC")]
    assert [ax.get_title() for ax in panels] == [f"{name}, seed 0" for _, name in order]
    for ax, (c, _) in zip(panels, order, strict=True):
        runs = cells[c]
        pooled = metrics["visited_obs"][runs][metrics["visited_valid"][runs]]
        center = pooled.mean(axis=0)
        _, vectors = np.linalg.eigh(np.cov(pooled, rowvar=False))
        basis = vectors[:, ::-1][:, :2]  # the two largest eigenvalues
        seed0 = runs[0]
        visited = metrics["visited_obs"][seed0][metrics["visited_valid"][seed0]]
        queried = metrics["queried_obs"][seed0][metrics["queried_valid"][seed0]]
        assert _legend(ax) == [f"visited ({len(visited)})", f"queried ({len(queried)})"]
        for collection, states in zip(ax.collections, (visited, queried), strict=True):
            want = (states - center) @ basis
            got = np.asarray(collection.get_offsets())
            signs = np.sign(np.sum(got * want, axis=0))
            np.testing.assert_allclose(got, want * signs, atol=1e-9)
        assert (ax.get_xlabel(), ax.get_ylabel()) == ("PC 1", "PC 2")


# ---------------------------------------------------------------- the pairs along the run

PAIR_OFFSETS = np.array([0.0, -150.0, 240.0])
"""Added to AQSAC's seeds (0, 1, 2) in `test_pairs_...`: unequal variances, so Welch's df is not
n_a + n_b - 2."""


def test_pairs_draw_each_difference_with_welchs_interval_at_every_evaluation(
    sac_dir: Path,
) -> None:
    metrics, cells = _files(sac_dir)
    metrics["eval_return"][cells[3]] += PAIR_OFFSETS[:, None]
    np.savez(sac_dir / "metrics.npz", **metrics)
    fig = _make(plots.fig_pairs(rundir.load_run(sac_dir)))
    (ax,) = fig.axes
    names = ["AQSAC - BQSAC", "AQSAC - GQSAC", "AQSAC - SAC"]
    assert _legend(ax) == names
    assert ax.get_title() == "Intrinsic uncertainty: SAC σθ(s)"
    steps = metrics["env_steps"][0]
    ret = metrics["eval_return"]
    lines = _lines(ax)
    for i, (name, b) in enumerate(zip(names, (2, 1, 0), strict=True)):
        x, y = lines[name]
        np.testing.assert_array_equal(x, steps)
        a_runs, b_runs = ret[cells[3]], ret[cells[b]]
        np.testing.assert_allclose(y, a_runs.mean(axis=0) - b_runs.mean(axis=0))
        # 100 (4 - (b + 1)) (p + 1) apart, plus the mean of PAIR_OFFSETS
        np.testing.assert_allclose(y, 100.0 * (3 - b) * np.arange(1, 5) + 30.0)
        band = _band(ax, i)
        assert sorted(band) == list(steps)
        for p, s in enumerate(steps):
            welch = stats.ttest_ind(a_runs[:, p], b_runs[:, p], equal_var=False)
            want = welch.confidence_interval(0.95)
            np.testing.assert_allclose(band[s], (want.low, want.high), rtol=1e-6)
            assert want.low < y[p] - 180  # wide: the offsets' spread, not the cells' gap
    zero = [line for line in ax.get_lines() if list(line.get_ydata()) == [0.0, 0.0]]
    assert len(zero) == 1
    # dotted where comparison.md also reads the pairs: a quarter, half and three quarters
    dotted = [line.get_xdata()[0] for line in ax.get_lines() if line.get_linestyle() == ":"]
    assert dotted == [1000, 2000, 3000]


def test_pairs_split_active_by_uncertainty_and_intrinsic_against_extrinsic(
    full_dir: Path,
) -> None:
    fig = _make(plots.fig_pairs(rundir.load_run(full_dir)))
    intrinsic, extrinsic, both = fig.axes
    assert _legend(intrinsic) == ["AQSAC t_query=0.1 - SAC", "AQSAC t_query=0.3 - SAC"]
    assert _legend(extrinsic) == [
        "AQNoisySAC - BQNoisySAC b=0.2",
        "AQNoisySAC - BQNoisySAC b=0.4",
    ]
    assert _legend(both) == ["AQSAC t_query=0.1 - AQNoisySAC"]
    assert both.get_title() == "Each strategy, intrinsic − extrinsic uncertainty"
    x, _ = _lines(both)["AQSAC t_query=0.1 - AQNoisySAC"]
    np.testing.assert_array_equal(x, [1000, 2000, 3000])  # the periods present
    assert fig.get_suptitle().endswith("[partial: 3,000 of 4,000 env steps]")


# ---------------------------------------------------------------- the gait


def test_gait_figure_draws_percent_upside_down_per_cell(tmp_path: Path) -> None:
    path = write_run_dir(tmp_path / "g", NONE_AND_BERNOULLI, NONE_AND_BERNOULLI_SWEEP)
    metrics = dict(np.load(path / "metrics.npz"))
    n = metrics["eval_return"].shape[0]
    metrics["upside_down"] = np.arange(PERIODS)[None, :] / 10 + np.arange(n)[:, None] / 100
    metrics["eval_upside_down"] = 1.0 - metrics["upside_down"]
    np.savez(path / "metrics.npz", **metrics)
    config = json.loads((path / "config.json").read_text())
    config["config"]["env_name"] = "halfcheetah"
    (path / "config.json").write_text(json.dumps(config))
    _, cells = _files(path)
    fig = _make(plots.fig_gait(rundir.load_run(path)))
    visited, evaluation = fig.axes
    assert (visited.get_title(), evaluation.get_title()) == (
        "Gait: visited training states",
        "Gait: evaluation",
    )
    for ax, name in ((visited, "upside_down"), (evaluation, "eval_upside_down")):
        assert _legend(ax) == ["SAC", "BQSAC b=0.2"]
        for c, label in enumerate(["SAC", "BQSAC b=0.2"]):
            x, y = _lines(ax)[label]
            np.testing.assert_array_equal(x, [1000, 2000, 3000, 4000])
            np.testing.assert_allclose(y, 100.0 * _seed_mean(metrics[name], cells[c]))
        assert ax.get_ylabel() == "% of states upside down (|pitch| > 90°)"
    # Cell 1 = runs 3, 4, 5: 100 (p / 10 + 0.04) percent of its visited states at period p.
    np.testing.assert_allclose(_lines(visited)["BQSAC b=0.2"][1], 10.0 * np.arange(PERIODS) + 4.0)


def _with_falls(path: Path) -> dict[str, np.ndarray]:
    """Give a run directory the episode metrics of a task that terminates: run r in period p
    finished 2 + r episodes, a share (p + r) / 20 of them by a fall, of mean length 100 + 10 p;
    period 0 of run 0 finished none (nan)."""
    metrics = dict(np.load(path / "metrics.npz"))
    n = metrics["eval_return"].shape[0]
    p, r = np.arange(PERIODS)[None, :], np.arange(n)[:, None]
    metrics["episodes"] = np.broadcast_to(2 + r, (n, PERIODS)).astype(np.int32).copy()
    metrics["fell"] = (p + r) / 20.0
    metrics["episode_length"] = np.broadcast_to(100.0 + 10 * p, (n, PERIODS)).copy()
    metrics["eval_fell"] = np.zeros((n, PERIODS))
    metrics["episodes"][0, 0] = 0
    metrics["fell"][0, 0] = metrics["episode_length"][0, 0] = np.nan
    np.savez(path / "metrics.npz", **metrics)
    return metrics


def test_falls_figure_draws_the_fall_share_and_episode_length_per_cell(tmp_path: Path) -> None:
    path = write_run_dir(tmp_path / "f", NONE_AND_BERNOULLI, NONE_AND_BERNOULLI_SWEEP)
    assert plots.fig_falls(rundir.load_run(path)) is None  # no episode ever fell
    metrics = _with_falls(path)
    _, cells = _files(path)
    fig = _make(plots.fig_falls(rundir.load_run(path)))
    fell, length, evaluation = fig.axes
    assert fell.get_title() == "Training episodes that fell"
    # SAC = runs 0, 1, 2; at period 0 run 0 has no episode: the mean of runs 1, 2 = (1 + 2) / 20.
    x, y = _lines(fell)["SAC"]
    np.testing.assert_array_equal(x, [1000, 2000, 3000, 4000])
    np.testing.assert_allclose(y[0], 100 * 3 / 40)
    np.testing.assert_allclose(y[1:], 100 * (np.arange(1, PERIODS) + 1) / 20)
    np.testing.assert_allclose(_lines(length)["BQSAC b=0.2"][1], 100.0 + 10 * np.arange(PERIODS))
    np.testing.assert_allclose(
        _lines(evaluation)["SAC"][1], 100 * _seed_mean(metrics["eval_fell"], cells[0])
    )


def test_falls_bands_stay_within_what_a_share_and_a_length_can_be(tmp_path: Path) -> None:
    """Seeds that split between no falls and all falls (runs 0, 1, 2: 0%, 100%, 0%) give a
    Student's t interval past both 0 and 100%; the drawn band is that interval cut to [0, 100],
    a length's band is cut at 0 only, and a band inside the range is drawn as computed."""
    path = write_run_dir(tmp_path / "f", NONE_AND_BERNOULLI, NONE_AND_BERNOULLI_SWEEP)
    metrics = _with_falls(path)
    split = (np.arange(metrics["eval_return"].shape[0]) % 2)[:, None] + np.zeros((1, PERIODS))
    metrics["fell"] = split
    metrics["episode_length"] = 10.0 + 890.0 * split
    np.savez(path / "metrics.npz", **metrics)
    _, cells = _files(path)
    fell, length, _ = _make(plots.fig_falls(rundir.load_run(path))).axes
    for ax, name, scale, (low, high) in (
        (fell, "fell", 100.0, (0.0, 100.0)),
        (length, "episode_length", 1.0, (0.0, np.inf)),
    ):
        for c, runs in enumerate(cells.values()):
            mean, half = mean_ci95_columns(scale * metrics[name][runs])
            assert (mean - half < low).all()  # the interval itself reaches below the range
            band = _band(ax, c)
            drawn = np.array([band[x] for x in sorted(band)])
            np.testing.assert_allclose(drawn[:, 0], np.clip(mean - half, low, high))
            np.testing.assert_allclose(drawn[:, 1], np.clip(mean + half, low, high))
        if name == "fell":
            assert (drawn[:, 1] == 100.0).all()  # and above it, for a share
    metrics["episode_length"] = 100.0 + np.arange(split.shape[0])[:, None] + 0 * split
    np.savez(path / "metrics.npz", **metrics)
    length = _make(plots.fig_falls(rundir.load_run(path))).axes[1]
    mean, half = mean_ci95_columns(metrics["episode_length"][cells[0]])
    band = _band(length, 0)
    np.testing.assert_allclose([band[x] for x in sorted(band)], np.c_[mean - half, mean + half])


# ---------------------------------------------------------------- plot_all: which files


def _png_ok(path: Path) -> bool:
    return path.stat().st_size > 1000 and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_all_without_active_cells_skips_fig7(tmp_path: Path) -> None:
    path = write_run_dir(tmp_path / "sweep", NONE_AND_BERNOULLI, NONE_AND_BERNOULLI_SWEEP)
    paths = plots.plot_all(path)
    assert {p.stem for p in paths} == {
        "fig3_uncertainty",
        "fig4_5_returns",
        "fig6_bernoulli",
        "fig8_states",
        "fig9_budget",
    }
    assert all(p.parent == path / "figures" and _png_ok(p) for p in paths)
    assert not (path / "figures" / "fig7_active.png").exists()


def test_plot_all_of_a_full_sweep_writes_every_figure_but_the_gait(full_dir: Path) -> None:
    paths = {p.stem: p for p in plots.plot_all(full_dir)}
    assert set(paths) == set(plots.FIGURES) - {"gait", "falls"}  # the toy env: no gait, no fall
    assert all(_png_ok(p) for p in paths.values())


# ---------------------------------------------------------------- Fig. 1: a group of agent families


TD3_CELLS = [
    {"strategy": "none", "uncertainty": "intrinsic"},
    {"strategy": "active", "uncertainty": "intrinsic"},
    {"strategy": "none", "uncertainty": "extrinsic"},
    {"strategy": "bernoulli", "uncertainty": "extrinsic"},
]
TD3_SWEEP = {"strategy": ["none", "bernoulli", "active"], "uncertainty": ["intrinsic", "extrinsic"]}
BOOT_CELLS = [{"strategy": "none"}, {"strategy": "greedy"}, {"strategy": "active"}]
BOOT_SWEEP = {"strategy": ["none", "greedy", "active"]}


def _member(path: Path, agent: str, cells: list[dict], sweep: dict, periods: int) -> Path:
    write_run_dir(path, cells, sweep, periods=periods, total_periods=PERIODS)
    config = json.loads((path / "config.json").read_text())
    config["config"]["agent"] = agent
    (path / "config.json").write_text(json.dumps(config))
    return path


def test_fig1_draws_a_panel_per_agent_variant_and_a_curve_per_strategy(tmp_path: Path) -> None:
    """A group of TD3 (with Noisy TD3 cells) and Bootstrapped TD3, the latter partial: three panels
    (TD3, Noisy TD3, Bootstrapped TD3) of learning curves in the paper's names, each the mean over
    seeds with a band, a strategy in one colour everywhere."""
    group = tmp_path / "group"
    td3 = _member(group / "agent-td3", "td3", TD3_CELLS, TD3_SWEEP, PERIODS)
    boot = _member(group / "agent-boot_td3", "boot_td3", BOOT_CELLS, BOOT_SWEEP, 3)
    (group / "group.json").write_text(json.dumps({"members": [td3.name, boot.name]}))
    fig = _make(plots.fig1_agents(group))
    axes = fig.axes
    assert [ax.get_title() for ax in axes] == [
        "TD3: twin-critic gap |Q₀ − Q₁|",
        "Extrinsic uncertainty: Noisy TD3 Var[μ̃]",
        "Bootstrapped TD3: the heads' disagreement",
    ]
    expert = "expert (3000)"
    assert [_legend(ax) for ax in axes] == [
        ["TD3", "AQTD3 t_query=0.1", expert],
        ["NoisyTD3", "BQNoisyTD3 b=0.2", expert],
        ["BootTD3", "GQBootTD3", "AQBootTD3 t_query=0.1", expert],
    ]
    panels = [(axes[0], td3, {0: "TD3", 1: "AQTD3 t_query=0.1"})]
    panels += [(axes[1], td3, {2: "NoisyTD3", 3: "BQNoisyTD3 b=0.2"})]
    panels += [(axes[2], boot, {0: "BootTD3", 1: "GQBootTD3", 2: "AQBootTD3 t_query=0.1"})]
    colors = {}
    for ax, path, names in panels:
        metrics, cells = _files(path)
        steps = metrics["env_steps"][0]
        assert len(ax.collections) == len(names)  # one CI band per curve
        for band_index, (c, name) in enumerate(names.items()):
            x, y = _lines(ax)[name]
            np.testing.assert_array_equal(x, steps)
            mean = _seed_mean(metrics["eval_return"], cells[c])
            np.testing.assert_allclose(y, mean)
            # seeds add 0, 10, 20: the band is mean -+ t(0.975, 2) * 10 / sqrt(3) = 24.84
            low, high = _band(ax, band_index)[float(steps[0])]
            np.testing.assert_allclose(
                [low, high], [mean[0] - 24.8414, mean[0] + 24.8414], atol=1e-3
            )
            strategy = name[:2] if name[:2] in ("GQ", "BQ", "AQ") else "none"
            line = next(ln for ln in ax.get_lines() if ln.get_label() == name)
            colors.setdefault(strategy, line.get_color())
            assert line.get_color() == colors[strategy], name
        assert ax.get_xlabel() == "environment steps"
    assert len(_lines(axes[2])["BootTD3"][0]) == 3  # the partial member's periods present
    assert axes[0].get_ylabel() == "evaluation return (deterministic policy)"
    assert fig.get_suptitle() == (
        "Fig. 1: evaluation return per agent and query strategy, mean and 95% CI over seeds"
        "\n[partial: 3,000 of 4,000 env steps]"
    )
    path = plots.plot_group(group)
    assert path == group / "figures" / "fig1_agents.png" and _png_ok(path)
