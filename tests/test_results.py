"""Tests of reading results back (arld_jax.rundir's reader, stats, summary, compare: the summary
table, comparisons, the gait summary) on synthetic run directories.

No training here (but for one test of the `compare` command): the run directories are written by
hand in the format of arld_jax.run (`write_run_dir`, also used by tests/test_plots.py),
with numbers chosen so that every summary value can be worked out on paper.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats as scipy_stats

from arld_jax import compare, plots, rundir, stats, summary

EVAL_EVERY = 1000
PERIODS = 4
TRACES = 5  # traces_per_eval
OBS_DIM = 4
K = 16  # state samples per run
BUDGET = 100
SEEDS = (0, 1, 2)
DEMO_RATE = {0: 4, 1: 6, 2: 8}
"""Demonstrations per trace slice of a querying run, by seed: cumulative demos at trace point i
(0-based, over the whole run) are min(BUDGET, (i + 1) * rate). Seed 0 never reaches the budget
(80 at the end), seed 1 reaches it at point 16 (6 * 17 = 102), seed 2 at point 12 (8 * 13 = 104)."""

BASE_FIELDS: dict[str, Any] = {
    "strategy": "none",
    "uncertainty": "intrinsic",
    "query_prob": 0.2,
    "t_query": 0.1,
    "demo_steps": 1,
    "budget": BUDGET,
    "eps_demo": 1.0,
    "actor_lr": 3e-4,
    "critic_lr": 3e-4,
    "alpha_lr": 3e-4,
    "gamma": 0.99,
    "tau": 0.005,
    "reward_scale": 1.0,
    "init_alpha": 0.2,
}


def write_run_dir(
    path: Path,
    cells: list[dict[str, Any]],
    sweep: dict[str, list[Any]],
    periods: int = PERIODS,
    total_periods: int = PERIODS,
    expert: float | None = 3000.0,
    seeds: tuple[int, ...] = SEEDS,
) -> Path:
    """Write a run directory in run.py's format: len(cells) cells x 3 seeds, ``periods`` of
    ``total_periods`` evaluation periods present (fewer = a partial sweep).

    eval_return[run, p] = 100 * (cell + 1) * (p + 1) + 10 * seed; querying cells spend demos at
    DEMO_RATE[seed] per trace slice up to BUDGET; 'none' cells never query.
    """
    path.mkdir(parents=True, exist_ok=True)
    config = {
        **BASE_FIELDS,
        "env_name": "toy",
        "num_envs": 1,
        "total_env_steps": total_periods * EVAL_EVERY,
        "eval_every": EVAL_EVERY,
        "episode_length": 100,
        "window_size": 50,
        "traces_per_eval": TRACES,
        "state_sample_size": K,
        "seed": 0,
    }
    (path / "config.json").write_text(
        json.dumps(
            {
                "config": config,
                "sweep": sweep,
                "seeds": list(seeds),
                "preset": "default",
                "command": "python -m arld_jax.run --synthetic",
                "expert": None if expert is None else {"eval_return": expert},
            }
        )
    )
    runs = []
    for c, overrides in enumerate(cells):
        fields = {**BASE_FIELDS, **overrides}
        label = " ".join(f"{k}={fields[k]}" for k in sweep)
        for s in seeds:
            runs.append({"run": len(runs), "cell": c, "cell_label": label, "seed": s, **fields})
    (path / "runs.json").write_text(json.dumps(runs))

    rng = np.random.default_rng(0)
    n, p_, t = len(runs), periods, TRACES
    p_idx = np.arange(p_)
    point = (p_idx[:, None] * t + np.arange(t)[None, :]).astype(np.float64)  # [P, T] trace index
    m: dict[str, np.ndarray] = {
        "env_steps": np.tile((p_idx + 1) * EVAL_EVERY, (n, 1)).astype(np.int64),
        "eval_return": np.zeros((n, p_)),
        "train_return": np.full((n, p_), np.nan),
        "demos_trace": np.zeros((n, p_, t), np.int64),
        "uncertainty_trace": np.zeros((n, p_, t)),
        "visited_obs": rng.normal(size=(n, K, OBS_DIM)) * np.array([3.0, 1.0, 0.3, 0.1]),
        "visited_valid": np.ones((n, K), bool),
        "queried_obs": rng.normal(size=(n, K, OBS_DIM)) + 2.0,
        "queried_valid": np.zeros((n, K), bool),
        "visited_env_step": np.tile(np.arange(K) * 100, (n, 1)),
        "queried_env_step": np.tile(np.arange(K) * 100, (n, 1)),
    }
    for name in ("critic_loss", "actor_loss", "entropy", "sigma", "uncertainty", "queries"):
        m[name] = rng.random((n, p_))
    m["alpha"] = np.full((n, p_), 0.2)
    for r, entry in enumerate(runs):
        c, s = entry["cell"], entry["seed"]
        m["eval_return"][r] = 100.0 * (c + 1) * (p_idx + 1) + 10.0 * s
        m["uncertainty_trace"][r] = np.exp(-point / 10.0) + 0.05 * s + 0.02 * rng.random((p_, t))
        if entry["strategy"] != "none":
            m["demos_trace"][r] = np.minimum(BUDGET, (point + 1) * DEMO_RATE[s % len(SEEDS)])
            m["queried_valid"][r, :6] = True
    m["demos_used"] = m["demos_trace"][:, :, -1].copy()
    np.savez(path / "metrics.npz", **m)
    (path / "timing.json").write_text(
        json.dumps({"wall_seconds": 12.0, "env_steps_per_second": 1500.0, "compile_seconds": 3.0})
    )
    return path


NONE_AND_BERNOULLI = [{"strategy": "none"}, {"strategy": "bernoulli"}]


@pytest.fixture
def run_dir(tmp_path: Path) -> Path:
    """2 cells (SAC, BQSAC b=0.2) x 3 seeds, 4 periods of 1000 env steps, all present."""
    sweep = {"strategy": ["none", "bernoulli"]}
    return write_run_dir(tmp_path / "sweep", NONE_AND_BERNOULLI, sweep)


# t(0.975, 2) = 4.302653; with sd 10 over 3 seeds: 4.302653 * 10 / sqrt(3) = 24.8414
HALF_SD10_N3 = 24.8414


def test_mean_ci95_hand_computed() -> None:
    # values [1, 2, 3, 4]: mean 2.5; sd (ddof=1) = sqrt((2.25 + 0.25 + 0.25 + 2.25) / 3) = 1.2910;
    # t(0.975, 3) = 3.1824; half-width = 3.1824 * 1.2910 / sqrt(4) = 2.0543
    mean, half = stats.mean_ci95(np.array([1.0, 2.0, 3.0, 4.0]))
    assert mean == pytest.approx(2.5)
    assert half == pytest.approx(2.0543, abs=1e-4)
    # NaNs are dropped before anything else
    assert stats.mean_ci95(np.array([1.0, np.nan, 2.0, 3.0, 4.0])) == (mean, half)
    one_mean, one_half = stats.mean_ci95(np.array([5.0]))
    assert one_mean == 5.0 and math.isnan(one_half)
    assert all(math.isnan(v) for v in stats.mean_ci95(np.array([np.nan])))


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-1e4, 1e4), min_size=2, max_size=12))
def test_mean_ci95_matches_scipy_interval(values: list[float]) -> None:
    x = np.array(values)
    mean, half = stats.mean_ci95(x)
    sem = scipy_stats.sem(x)
    if sem == 0:
        assert half == pytest.approx(0.0, abs=1e-9)
        return
    lo, hi = scipy_stats.t.interval(0.95, x.size - 1, loc=x.mean(), scale=sem)
    assert mean == pytest.approx(x.mean(), abs=1e-9)
    assert half == pytest.approx((hi - lo) / 2, rel=1e-6, abs=1e-9)


def test_mean_ci95_columns_matches_scalar() -> None:
    values = np.array([[1.0, 5.0, np.nan], [2.0, 5.0, 7.0], [3.0, np.nan, np.nan], [4.0, 8.0, 1.0]])
    mean, half = stats.mean_ci95_columns(values)
    for col in range(values.shape[1]):
        m, h = stats.mean_ci95(values[:, col])
        assert mean[col] == pytest.approx(m)
        assert half[col] == pytest.approx(h)
    assert half[0] == pytest.approx(2.0543, abs=1e-4)  # the [1, 2, 3, 4] example again


def test_area_under_curve_is_mean_of_evaluations() -> None:
    ret = np.array([[1.0, 2.0, 3.0, 6.0], [0.0, 0.0, 0.0, 4.0]])
    auc = stats.area_under_curve(ret, np.array([1000, 2000, 3000, 4000]))
    np.testing.assert_allclose(auc, [3.0, 1.0])  # (1 + 2 + 3 + 6) / 4, 4 / 4
    with pytest.raises(ValueError, match="evaluation points"):
        stats.area_under_curve(ret, np.array([1000, 2000]))


def test_summarize_hand_computed(run_dir: Path) -> None:
    rows = summary.summarize(run_dir)
    assert [r["cell"] for r in rows] == [0, 1]
    assert [r["strategy"] for r in rows] == ["none", "bernoulli"]
    assert rows[1]["cell_label"] == "strategy=bernoulli"
    sac, bq = rows
    assert sac["n_seeds"] == bq["n_seeds"] == 3
    # final return: 100 * (cell + 1) * 4 + 10 * seed -> [400, 410, 420] and [800, 810, 820]
    assert sac["final_return_mean"] == pytest.approx(410.0)
    assert bq["final_return_mean"] == pytest.approx(810.0)
    assert sac["final_return_ci95"] == pytest.approx(HALF_SD10_N3, abs=1e-3)
    # IQM of 3 runs cuts none (int(0.25 * 3) = 0): the mean, its bootstrap interval within the
    # runs' range and about the mean (the seeds' offsets are symmetric).
    assert sac["final_return_iqm"] == pytest.approx(410.0)
    assert 400.0 <= sac["final_return_iqm_lo"] < 410.0 < sac["final_return_iqm_hi"] <= 420.0
    assert sac["final_return_iqm_lo"] + sac["final_return_iqm_hi"] == pytest.approx(820.0, abs=1.0)
    # AUC: mean over p of 100 * (c + 1) * (p + 1) + 10 s = 250 (c + 1) + 10 s -> 260 and 510
    assert sac["auc_mean"] == pytest.approx(260.0)
    assert bq["auc_mean"] == pytest.approx(510.0)
    assert bq["auc_ci95"] == pytest.approx(HALF_SD10_N3, abs=1e-3)
    # final demos: SAC 0; BQSAC seeds [80, 100, 100]: mean 93.333, sd sqrt(266.67 / 2) = 11.547,
    # half-width 4.302653 * 11.547 / sqrt(3) = 28.684
    assert sac["demos_used_mean"] == 0.0 and sac["demos_used_ci95"] == 0.0
    assert bq["demos_used_mean"] == pytest.approx(93.3333, abs=1e-3)
    assert bq["demos_used_ci95"] == pytest.approx(28.684, abs=1e-3)
    assert bq["expert_return"] == 3000.0
    assert sac["above_expert"] == bq["above_expert"] == 0  # finals 400-820, expert 3,000
    assert bq["env_steps_per_second"] == 1500.0
    assert bq["periods"] == 4 and bq["env_steps"] == 4000


def test_write_summary_csv_schema_and_markdown(run_dir: Path) -> None:
    csv_path, md_path = summary.write_summary(run_dir)
    assert csv_path == run_dir / "summary.csv" and md_path == run_dir / "summary.md"
    with csv_path.open() as handle:
        reader = csv.DictReader(handle)
        table = list(reader)
    assert reader.fieldnames == [
        "cell",
        "cell_label",
        "name",
        "strategy",
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
    ]
    assert len(table) == 2
    assert float(table[1]["final_return_mean"]) == pytest.approx(810.0)
    assert float(table[0]["auc_mean"]) == pytest.approx(260.0)
    md = md_path.read_text()
    # two significant digits of the CI: 410 ± 24.84 -> "410 ± 25"; 93.33 ± 28.68 -> "93 ± 29"
    assert "| 410 ± 25 | 410 [" in md
    assert "| 810 ± 25 |" in md
    assert "| 93 ± 29 |" in md
    assert "| 0 ± 0 | 0 of 3 |" in md  # SAC's demos, then its seeds above the expert
    assert "95% confidence interval" in md and "Student's t" in md
    assert "Env steps per run: 4,000" in md and "[0, 1, 2]" in md
    assert "Partial" not in md
    # one header row, one separator, one row per cell
    assert sum(line.startswith("|") for line in md.splitlines()) == 4


def test_seeds_above_the_expert_counted_per_cell(tmp_path: Path) -> None:
    # finals 400 (c + 1) + 10 s: SAC [400, 410, 420], BQSAC [800, 810, 820]; with the expert at
    # 805, no SAC seed and two BQSAC seeds end above it (equal is not above: 410 with 410)
    run_dir = write_run_dir(
        tmp_path / "e", NONE_AND_BERNOULLI, {"strategy": ["none", "bernoulli"]}, expert=805.0
    )
    sac, bq = summary.summarize(run_dir)
    assert (sac["above_expert"], bq["above_expert"]) == (0, 2)
    tie = write_run_dir(
        tmp_path / "t", NONE_AND_BERNOULLI, {"strategy": ["none", "bernoulli"]}, expert=410.0
    )
    assert [r["above_expert"] for r in summary.summarize(tie)] == [1, 3]
    _, md_path = summary.write_summary(run_dir)
    md = md_path.read_text()
    assert "seeds above the expert" in md and "| 2 of 3 |" in md and "| 0 of 3 |" in md


def test_late_return_per_cell_and_seeds_above_the_expert_by_it(tmp_path: Path) -> None:
    """20 evaluations: the late return is each seed's mean over the last 2 (p = 18, 19), i.e.
    100 (c + 1) 19.5 + 10 s: SAC [1,950, 1,960, 1,970], BQSAC [3,900, 3,910, 3,920], against
    finals 100 (c + 1) 20 + 10 s: SAC [2,000, 2,010, 2,020]. With the expert at 1,955, all three
    SAC seeds end above it, two by the late return. 4 evaluations have none (nan, no column)."""
    run_dir = write_run_dir(
        tmp_path / "l",
        NONE_AND_BERNOULLI,
        {"strategy": ["none", "bernoulli"]},
        periods=20,
        total_periods=20,
        expert=1955.0,
    )
    sac, bq = summary.summarize(run_dir)
    assert sac["late_return_mean"] == pytest.approx(1960.0)
    assert bq["late_return_mean"] == pytest.approx(3910.0)
    assert sac["late_return_ci95"] == pytest.approx(HALF_SD10_N3, abs=1e-3)
    assert (sac["above_expert"], sac["above_expert_late"]) == (3, 2)
    assert (bq["above_expert"], bq["above_expert_late"]) == (3, 3)
    _, md_path = summary.write_summary(run_dir)
    md = md_path.read_text()
    assert "last 2 evaluations (from 19,000 env steps" in md
    assert "| late return |" in md
    assert "| 1,960 ± 25 |" in md and "| 3 of 3 (late: 2) |" in md
    short = write_run_dir(tmp_path / "s", NONE_AND_BERNOULLI, {"strategy": ["none", "bernoulli"]})
    rows = summary.summarize(short)
    assert all(
        math.isnan(r["late_return_mean"]) and math.isnan(r["above_expert_late"]) for r in rows
    )
    _, md_path = summary.write_summary(short)
    assert "late return" not in md_path.read_text().lower()


def test_partial_run_is_summarised_over_periods_present(tmp_path: Path) -> None:
    run_dir = write_run_dir(
        tmp_path / "partial",
        NONE_AND_BERNOULLI,
        {"strategy": ["none", "bernoulli"]},
        periods=2,
        total_periods=4,
        expert=None,
    )
    run = rundir.load_run(run_dir)
    assert run.partial and run.periods == 2 and run.expected_periods == 4
    sac, bq = summary.summarize(run_dir)
    # final = period 1: 200 (c + 1) + 10 s; AUC = mean(100, 200) (c + 1) + 10 s
    assert sac["final_return_mean"] == pytest.approx(210.0)
    assert bq["final_return_mean"] == pytest.approx(410.0)
    assert sac["auc_mean"] == pytest.approx(160.0)
    assert bq["auc_mean"] == pytest.approx(310.0)
    # demos after 10 trace points: [40, 60, 80] -> 60 ± 4.302653 * 20 / sqrt(3) = 49.683
    assert bq["demos_used_mean"] == pytest.approx(60.0)
    assert bq["demos_used_ci95"] == pytest.approx(49.683, abs=1e-3)
    assert bq["periods"] == 2 and bq["env_steps"] == 2000
    assert math.isnan(bq["expert_return"]) and math.isnan(bq["above_expert"])
    _, md_path = summary.write_summary(run_dir)
    md = md_path.read_text()
    assert "Partial run directory" in md and "2 of 4 evaluation periods" in md
    assert "2,000 of 4,000 env steps" in md


def test_missing_files_raise_helpful_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="does not exist"):
        rundir.load_run(tmp_path / "nowhere")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(FileNotFoundError, match="config.json") as info:
        summary.summarize(empty)
    assert "first chunk" in str(info.value)
    run_dir = write_run_dir(tmp_path / "started", NONE_AND_BERNOULLI, {"strategy": ["none"]})
    (run_dir / "metrics.npz").unlink()
    with pytest.raises(FileNotFoundError, match=r"no metrics\.npz.*first chunk"):
        summary.write_summary(run_dir)
    with pytest.raises(FileNotFoundError, match="metrics.npz"):
        plots.plot_all(run_dir)


def test_upside_down_late_from_period_metric(tmp_path: Path) -> None:
    """10 periods: the last 30% are the last 3. Run r has upside_down[r, p] = p / 10 + r / 100, so
    its late mean is (0.7 + 0.8 + 0.9) / 3 + r / 100 = 0.8 + r / 100."""
    path = write_run_dir(
        tmp_path / "g",
        NONE_AND_BERNOULLI,
        {"strategy": ["none", "bernoulli"]},
        periods=10,
        total_periods=10,
    )
    m = dict(np.load(path / "metrics.npz"))
    n = m["eval_return"].shape[0]
    m["upside_down"] = np.arange(10)[None, :] / 10 + np.arange(n)[:, None] / 100
    np.savez(path / "metrics.npz", **m)
    # The toy task has no gait rule: no upside-down share, column or figure.
    late, source = summary.upside_down_late(rundir.load_run(path))
    assert source == "n/a" and np.all(np.isnan(late))
    assert plots.fig_gait(rundir.load_run(path)) is None
    assert "upside down" not in summary.write_summary(path)[1].read_text().lower()
    cfg = json.loads((path / "config.json").read_text())
    cfg["config"]["env_name"] = "halfcheetah"
    (path / "config.json").write_text(json.dumps(cfg))
    late, source = summary.upside_down_late(rundir.load_run(path))
    assert source == "periods"
    np.testing.assert_allclose(late, 0.8 + np.arange(n) / 100)
    rows = summary.summarize(path)
    np.testing.assert_allclose(rows[1]["upside_down_late_mean"], 0.8 + 0.04)  # runs 3, 4, 5
    assert (path / "figures" / "gait.png") in plots.plot_all(path)
    assert "upside down (last 30%)" in (summary.write_summary(path)[1]).read_text()


def test_fall_share_and_episode_length_weigh_each_late_period_by_its_episodes(
    tmp_path: Path,
) -> None:
    """10 periods, the last 3 late. Run 0 finished (1, 3, 0) episodes in them, falling in shares
    (1, 1/3, nan) with mean lengths (50, 90, nan): its late fall share is (1 + 1) / 4 = 0.5 and its
    mean length (50 + 3 * 90) / 4 = 80. Columns and the reading show them; a run with no fall does
    not."""
    path = write_run_dir(
        tmp_path / "f", NONE_AND_BERNOULLI, {"strategy": ["none", "bernoulli"]}, periods=10,
        total_periods=10,
    )  # fmt: skip
    m = dict(np.load(path / "metrics.npz"))
    n = m["eval_return"].shape[0]
    m["episodes"] = np.ones((n, 10), np.int32)
    m["fell"] = np.zeros((n, 10))
    m["episode_length"] = np.full((n, 10), 1000.0)
    m["eval_fell"] = np.zeros((n, 10))
    np.savez(path / "metrics.npz", **m)
    assert not summary.has_falls(rundir.load_run(path))
    assert "fell (last 30%)" not in summary.write_summary(path)[1].read_text()
    m["episodes"][0, 7:] = (1, 3, 0)
    m["fell"][0, 7:] = (1.0, 1 / 3, np.nan)
    m["episode_length"][0, 7:] = (50.0, 90.0, np.nan)
    np.savez(path / "metrics.npz", **m)
    run = rundir.load_run(path)
    fell, length = summary.episodes_late(run)
    np.testing.assert_allclose((fell[0], length[0]), (0.5, 80.0))
    np.testing.assert_allclose((fell[1:], length[1:]), (0.0 * fell[1:], 1000.0 + 0 * fell[1:]))
    assert (
        "| fell (last 30%) | episode length (last 30%) |"
        in summary.write_summary(path)[1].read_text()
    )
    assert "Falls (share of the late training episodes" in compare.plain_reading(path)


def test_upside_down_late_from_visited_sample_for_old_halfcheetah_runs(tmp_path: Path) -> None:
    """Without the per-period metric, a HalfCheetah run is judged on its saved sample of visited
    states seen in the last 30% of the env steps; a toy run has no gait (n/a)."""
    path = write_run_dir(tmp_path / "h", NONE_AND_BERNOULLI, {"strategy": ["none", "bernoulli"]})
    late, source = summary.upside_down_late(rundir.load_run(path))
    assert source == "n/a" and np.all(np.isnan(late))  # toy env
    cfg = json.loads((path / "config.json").read_text())
    cfg["config"]["env_name"] = "halfcheetah"
    (path / "config.json").write_text(json.dumps(cfg))
    m = dict(np.load(path / "metrics.npz"))
    n, k = m["visited_valid"].shape
    last = int(m["env_steps"][0, -1])  # 4000: late states are those seen after step 2800
    obs = np.zeros((n, k, 17))
    steps = np.tile(np.linspace(0, last, k).astype(np.int64), (n, 1))
    late_mask = steps > 0.7 * last
    obs[:, :, 1] = np.where(late_mask & (np.arange(k) % 2 == 0), np.pi, 0.0)  # half flipped
    obs[0, :, 1] = np.where(late_mask[0], np.pi, 0.0)  # run 0: every late state flipped
    m.update(visited_obs=obs, visited_env_step=steps, visited_valid=np.ones((n, k), bool))
    np.savez(path / "metrics.npz", **m)
    late, source = summary.upside_down_late(rundir.load_run(path))
    assert source == "sample"
    expected = [np.mean(np.arange(k)[late_mask[r]] % 2 == 0) for r in range(n)]
    expected[0] = 1.0
    np.testing.assert_allclose(late, expected)


def test_upside_down_when_asked_against_the_states_visited_meanwhile(tmp_path: Path) -> None:
    """Per run: the share of sampled query states that are flipped, and of the sampled visited
    states up to the last sampled query; per cell, their difference paired run by run (here the
    same in every run, so a zero-width interval, where Welch's over the two shares would be wide);
    runs without a sampled query, toy runs and earlier readings show n/a."""
    sweep = {"strategy": ["none", "bernoulli"]}
    path = write_run_dir(tmp_path / "h", NONE_AND_BERNOULLI, sweep)
    asked, _ = summary.upside_down_when_asked(rundir.load_run(path))
    assert np.all(np.isnan(asked))  # toy env: no gait rule
    cfg = json.loads((path / "config.json").read_text())
    cfg["config"]["env_name"] = "halfcheetah"
    (path / "config.json").write_text(json.dumps(cfg))
    m = dict(np.load(path / "metrics.npz"))
    n, k = m["visited_valid"].shape
    querying = n // 2  # runs 0..2 are the 'none' cell (no query), 3..5 the 'bernoulli' cell
    asked_valid = np.zeros((n, k), bool)
    asked_valid[querying:, : k // 2] = True  # 8 sampled queries, at env steps 0..70
    visited, asked_obs = np.zeros((n, k, 17)), np.zeros((n, k, 17))
    for r, (asked_flips, visited_flips) in zip(
        range(querying, n), [(4, [0, 4]), (3, [0]), (5, [0, 2, 4])], strict=True
    ):
        asked_obs[r, :asked_flips, 1] = -3.0  # 4, 3, 5 of the 8 query states flipped
        visited[r, visited_flips, 1] = np.pi  # 2, 1, 3 of the 8 visited up to step 70; none after
    m.update(
        visited_obs=visited,
        visited_env_step=np.tile(np.arange(k) * 10, (n, 1)),
        visited_valid=np.ones((n, k), bool),
        queried_obs=asked_obs,
        queried_env_step=np.tile(np.arange(k) * 10, (n, 1)),
        queried_valid=asked_valid,
    )
    np.savez(path / "metrics.npz", **m)
    run = rundir.load_run(path)
    asked, meanwhile = summary.upside_down_when_asked(run)
    assert np.all(np.isnan(asked[:querying])) and np.all(np.isnan(meanwhile[:querying]))
    np.testing.assert_allclose(asked[querying:], [4 / 8, 3 / 8, 5 / 8])
    np.testing.assert_allclose(meanwhile[querying:], [2 / 8, 1 / 8, 3 / 8])  # not / 16: the span
    rows = summary.summarize(run)
    assert np.isnan(rows[0]["asked_upside_down_mean"])
    assert rows[1]["asked_minus_visited_upside_down_mean"] == pytest.approx(0.25)
    assert rows[1]["asked_minus_visited_upside_down_ci95"] == pytest.approx(0.0, abs=1e-12)
    text = summary.summary_markdown(run)
    assert "upside down when asked (visited meanwhile), difference" in text
    assert "| 50 % (25 %), +25 [25, 25] |" in text
    reading = rundir.read_at(run, 2 * EVAL_EVERY)  # drops the state samples: no column
    assert "when asked" not in summary.summary_markdown(reading)
    m["visited_env_step"] = m["visited_env_step"] + 1_000  # no state visited before the queries
    np.savez(path / "metrics.npz", **m)
    assert "| 50 % (n/a) |" in summary.summary_markdown(rundir.load_run(path))


@settings(max_examples=25, deadline=None)
@given(
    st.lists(st.integers(-5, 5), min_size=1, max_size=6),
    st.lists(st.integers(-5, 5), min_size=1, max_size=6),
)
def test_probability_of_improvement_equals_rliables(xs: list[int], ys: list[int]) -> None:
    """Ours (vectorised, ties count half) against rliable's Mann-Whitney-based metric."""
    from rliable import metrics as rly_metrics

    x, y = np.asarray(xs, float), np.asarray(ys, float)
    want = rly_metrics.probability_of_improvement(x[:, None], y[:, None])
    assert stats.probability_of_improvement(x, y) == pytest.approx(float(want))


@settings(max_examples=25, deadline=None)
@given(st.lists(st.integers(-50, 50), min_size=1, max_size=12))
def test_iqm_equals_rliables(xs: list[int]) -> None:
    """The interquartile mean of one task's runs is rliable's `aggregate_iqm`."""
    from rliable import metrics as rly_metrics

    x = np.asarray(xs, float)
    assert stats.iqm(x) == pytest.approx(float(rly_metrics.aggregate_iqm(x[:, None])))


def test_iqm_interval_agrees_with_rliables_bootstrap() -> None:
    """The vectorised percentile bootstrap of the IQM gives rliable's interval (its
    `get_interval_estimates`, stratified over one task) to within the resampling noise, for 5
    and 10 runs; one run has no interval; a seed reproduces it."""
    from rliable import library as rly
    from rliable import metrics as rly_metrics

    rng = np.random.default_rng(0)
    for n in (5, 10):
        x = rng.normal(1_000.0, 400.0, n)
        np.random.seed(1)  # rliable 1.2 draws from numpy's global RNG
        _, want = rly.get_interval_estimates(
            {"x": x[:, None]}, lambda s: np.array([rly_metrics.aggregate_iqm(s)]), reps=20_000
        )
        point, lo, hi = stats.iqm_ci95(x)
        assert point == pytest.approx(stats.iqm(x))
        spread = np.ptp(x)
        assert lo == pytest.approx(float(want["x"][0, 0]), abs=0.02 * spread)
        assert hi == pytest.approx(float(want["x"][1, 0]), abs=0.02 * spread)
        assert lo < point < hi
    assert stats.iqm_ci95(np.array([3.0]))[1:] == (pytest.approx(math.nan, nan_ok=True),) * 2
    assert stats.iqm_ci95(x, seed=4) == stats.iqm_ci95(x, seed=4)


def test_pairwise_comparison_with_bootstrap_cis(tmp_path: Path) -> None:
    """SAC, BQSAC and AQSAC cells (intrinsic) with eval_return = 100 (cell + 1)(p + 1) + 10 seed:
    final returns are 400/800/1200 + {0, 10, 20}. AQSAC - BQSAC = 400 exactly in every resample's
    mean (same seed offsets), and every AQSAC run beats every BQSAC run: P = 1 with CI [1, 1]."""
    cells = [{"strategy": "none"}, {"strategy": "bernoulli"}, {"strategy": "active"}]
    path = write_run_dir(tmp_path / "c", cells, {"strategy": ["none", "bernoulli", "active"]})
    run = rundir.load_run(path)
    names = [name for name, _, _ in compare.comparison_pairs(run)]
    assert names == ["AQSAC - BQSAC", "AQSAC - SAC"]  # one uncertainty: no intrinsic-extrinsic
    rows = {(r["pair"], r["metric"]): r for r in compare.compare(run, reps=2_000)}
    final = rows[("AQSAC - BQSAC", "final return")]
    assert final["diff"] == pytest.approx(400.0)
    # Resampling the 3 seeds of each cell independently: the mean offsets range over [0, 20].
    assert 380.0 - 1e-9 <= final["diff_lo"] <= 400.0 <= final["diff_hi"] <= 420.0 + 1e-9
    assert final["p_improve"] == 1.0 and final["p_lo"] == 1.0 and final["p_hi"] == 1.0
    auc = rows[("AQSAC - SAC", "AUC")]
    assert auc["diff"] == pytest.approx(2 * 250.0)  # AUC = 100 (cell + 1) * 2.5 + 10 seed
    md = compare.write_comparison(path).read_text()
    assert "| AQSAC - BQSAC | final return | 3 / 3 | 400 [" in md
    # A run without pairs (no active cell) writes nothing.
    other = write_run_dir(tmp_path / "n", NONE_AND_BERNOULLI, {"strategy": ["none", "bernoulli"]})
    assert compare.write_comparison(other) is None


def test_bootstrap_difference_agrees_with_rliables_stratified_bootstrap() -> None:
    """The vectorised bootstrap gives rliable's intervals (`get_interval_estimates` of the
    difference of means and of the probability of improvement, x and y resampled apart) to within
    the resampling noise, for 5 against 10 runs. Resampling the pooled runs, or a normal interval
    instead of the percentiles, would miss by more on these skewed samples."""
    from rliable import library as rly
    from rliable import metrics as rly_metrics

    def rliable_stats(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.array([np.mean(a) - np.mean(b), rly_metrics.probability_of_improvement(a, b)])

    rng = np.random.default_rng(2)
    n, m = 5, 10
    x, y = rng.lognormal(7.0, 0.6, n), rng.lognormal(6.8, 0.6, m)
    np.random.seed(1)  # rliable 1.2 draws from numpy's global RNG
    point, interval = rly.get_interval_estimates(
        {"d": (x[:, None], y[:, None])}, rliable_stats, reps=20_000
    )
    got = stats.bootstrap_difference(x, y, reps=20_000, seed=0)
    assert got["diff"] == pytest.approx(point["d"][0]) and (got["n_a"], got["n_b"]) == (n, m)
    assert got["p_improve"] == pytest.approx(point["d"][1])
    spread = np.ptp(np.concatenate([x, y]))
    assert got["diff_lo"] == pytest.approx(interval["d"][0, 0], abs=0.02 * spread)
    assert got["diff_hi"] == pytest.approx(interval["d"][1, 0], abs=0.02 * spread)
    step = 1 / (n * m)  # P moves in steps of one pair of runs
    assert got["p_lo"] == pytest.approx(interval["d"][0, 1], abs=step + 0.01)
    assert got["p_hi"] == pytest.approx(interval["d"][1, 1], abs=step + 0.01)


def test_bootstrap_difference_is_reproducible_and_leaves_global_rng_alone() -> None:
    """The same seed gives the same interval, another seed another one, and the caller's global
    numpy RNG stream is as if the call had not happened (the bootstrap has its own generator)."""
    x, y = np.array([1.0, 5, 3, 8, 2]), np.array([0.0, 4, 1, 2, 6])
    np.random.seed(123)
    want_next = np.random.random_sample()
    np.random.seed(123)
    a = stats.bootstrap_difference(x, y, reps=500, seed=0)
    assert np.random.random_sample() == want_next
    b = stats.bootstrap_difference(x, y, reps=500, seed=0)
    c = stats.bootstrap_difference(x, y, reps=500, seed=1)
    assert (a["diff_lo"], a["diff_hi"]) == (b["diff_lo"], b["diff_hi"])
    assert (a["diff_lo"], a["diff_hi"], a["p_lo"]) != (c["diff_lo"], c["diff_hi"], c["p_lo"])


def test_welch_interval_matches_scipy_and_a_hand_computation() -> None:
    """`welch_ci95` is scipy's Welch t-test interval; by hand for x = (1, 3), y = (0, 0, 3):
    mean(x) - mean(y) = 2 - 1 = 1, se^2 = 2/2 + 3/3 = 2, df = 2^2 / (1^2/1 + 1^2/2) = 8/3. One
    value on a side has no interval; constant samples give the point."""
    x, y = np.array([1.0, 3.0]), np.array([0.0, 0.0, 3.0])
    lo, hi = stats.welch_ci95(x, y)
    half = scipy_stats.t.ppf(0.975, 8 / 3) * math.sqrt(2.0)
    assert (lo, hi) == pytest.approx((1.0 - half, 1.0 + half), rel=1e-12)
    rng = np.random.default_rng(3)
    for n, m in ((5, 5), (5, 10), (3, 7)):
        a, b = rng.normal(2.0, 1.0, n), rng.normal(0.0, 3.0, m)
        want = scipy_stats.ttest_ind(a, b, equal_var=False).confidence_interval(0.95)
        assert stats.welch_ci95(a, b) == pytest.approx((want.low, want.high), rel=1e-10)
    assert all(math.isnan(v) for v in stats.welch_ci95(np.array([1.0]), y))
    assert stats.welch_ci95(np.full(3, 2.0), np.full(4, 5.0)) == (-3.0, -3.0)


def test_bootstrap_rows_carry_the_welch_interval_and_the_table_shows_it() -> None:
    """`bootstrap_difference` rows hold `welch_ci95` of the same samples, and `format_comparison`
    prints it in its own column beside the bootstrap interval."""
    x, y = np.array([1.0, 5, 3, 8, 2]), np.array([0.0, 4, 1, 2, 6])
    row = stats.bootstrap_difference(x, y, reps=500, seed=0)
    assert (row["welch_lo"], row["welch_hi"]) == stats.welch_ci95(x, y)
    # With 5 values a side the bootstrap interval is the narrower one (interval_coverage.md).
    assert row["welch_hi"] - row["welch_lo"] > row["diff_hi"] - row["diff_lo"]
    table = compare.format_comparison([dict(row, pair="a − b", metric="final return")])
    lo, hi = stats.welch_ci95(x, y)
    assert f"| [{lo:,.0f}, {hi:,.0f}] |" in table and "Welch t 95% CI" in table


def test_pooled_directories_compare_as_one_with_every_seed(tmp_path: Path) -> None:
    """Seeds 0-2 and 3-5 of one experiment, written to two directories (the second one evaluation
    short), pool into one run of 6 seeds over the 3 evaluations both have: compared with a third
    directory, a - b is worked out by hand from eval_return = 100 (cell + 1) (p + 1) + 10 seed."""
    cells, sweep = NONE_AND_BERNOULLI, {"strategy": ["none", "bernoulli"]}
    first = write_run_dir(tmp_path / "s0-2", cells, sweep)
    second = write_run_dir(tmp_path / "s3-5", cells, sweep, periods=3, seeds=(3, 4, 5))
    other = write_run_dir(tmp_path / "other", cells, sweep)
    pooled = rundir.pool_runs([first, second])
    assert pooled.name == "s0-2+s3-5" and pooled.periods == 3 and pooled.partial
    assert [c.seeds for c in rundir.group_cells(pooled)] == [[0, 1, 2, 3, 4, 5]] * 2
    rows = compare.compare_runs(pooled, other, reps=500)
    final = next(r for r in rows if r["metric"] == "final return" and "bernoulli" in r["pair"])
    # at the 3rd evaluation: cell 1 gives 600 + 10 seed; mean seed 2.5 pooled against 1 in other
    assert final["diff"] == pytest.approx(10 * 2.5 - 10 * 1.0)
    assert (final["n_a"], final["n_b"], final["env_steps"]) == (6, 3, 3 * EVAL_EVERY)
    assert final["pair"] == "s0-2+s3-5:strategy=bernoulli − other:strategy=bernoulli"
    alone = rundir.pool_runs([first])  # one directory: as loaded
    assert (alone.path, alone.sources, alone.periods, len(alone.runs)) == (first, (), 4, 6)


def test_a_pooled_summary_names_each_directory_command_and_separates_thousands(
    tmp_path: Path,
) -> None:
    """A pool has no one command: its summary names the command of every directory pooled, not
    the first one's as if it had made them all. Means and intervals carry thousands separators,
    as the IQM beside them does."""
    cells, sweep = NONE_AND_BERNOULLI, {"strategy": ["none", "bernoulli"]}
    first = write_run_dir(tmp_path / "s0-2", cells, sweep)
    second = write_run_dir(tmp_path / "s3-4", cells, sweep, seeds=(3, 4))
    config = json.loads((second / "config.json").read_text())
    config["command"] = "python -m arld_jax.run --synthetic --seeds 3,4"
    (second / "config.json").write_text(json.dumps(config))
    md = summary.summary_markdown(rundir.pool_runs([first, second]))
    assert "Command: `" not in md
    assert (
        "Pooled from runs made by: `python -m arld_jax.run --synthetic`; "
        "`python -m arld_jax.run --synthetic --seeds 3,4`"
    ) in md
    assert "Command: `python -m arld_jax.run --synthetic`" in summary.summary_markdown(first)
    assert summary.format_mean_ci(2719.2, 828.4) == "2,719 ± 828"
    assert summary.format_mean_ci(12345.6, 1234.4) == "12,346 ± 1,234"
    assert summary.format_mean_ci(0.1234, 0.05) == "0.123 ± 0.050"


def test_pooling_refuses_shared_seeds_and_other_configs(tmp_path: Path) -> None:
    """A seed in two of the directories, a config field that differs (naming it and both
    values), or another sweep is a clear error; a different run length is allowed."""
    cells, sweep = NONE_AND_BERNOULLI, {"strategy": ["none", "bernoulli"]}
    first = write_run_dir(tmp_path / "a", cells, sweep)
    with pytest.raises(ValueError, match="seed 0 of cell 'strategy=none' is in both"):
        rundir.pool_runs([first, write_run_dir(tmp_path / "b", cells, sweep)])
    other_gamma = write_run_dir(tmp_path / "g", cells, sweep, seeds=(7,))
    config = json.loads((other_gamma / "config.json").read_text())
    config["config"]["gamma"] = 0.9
    (other_gamma / "config.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match="differ in gamma 0.99 against 0.9"):
        rundir.pool_runs([first, other_gamma])
    with pytest.raises(ValueError, match="differ in sweep"):
        rundir.pool_runs([first, write_run_dir(tmp_path / "s", cells[:1], {}, seeds=(8,))])
    longer = write_run_dir(tmp_path / "l", cells, sweep, periods=6, total_periods=6, seeds=(9,))
    assert rundir.pool_runs([first, longer]).periods == PERIODS


def test_pooling_reads_a_field_added_later_as_its_default(tmp_path: Path) -> None:
    """A directory written before a Config field existed pools with one that records the field at
    its default (that is what the older run had), and not with one that sets it otherwise."""
    cells, sweep = NONE_AND_BERNOULLI, {"strategy": ["none", "bernoulli"]}
    older = write_run_dir(tmp_path / "old", cells, sweep)
    assert "integrator" not in json.loads((older / "config.json").read_text())["config"]

    def recording(name: str, seed: int, integrator: str) -> Path:
        path = write_run_dir(tmp_path / name, cells, sweep, seeds=(seed,))
        config = json.loads((path / "config.json").read_text())
        config["config"]["integrator"] = integrator
        (path / "config.json").write_text(json.dumps(config))
        return path

    pooled = rundir.pool_runs([older, recording("new", 7, "task")])
    assert len(pooled.runs) == len(cells) * (len(SEEDS) + 1)
    rk4 = recording("rk4", 8, "rk4")
    with pytest.raises(ValueError, match="differ in integrator 'task' against 'rk4'"):
        rundir.pool_runs([older, rk4])


def test_compare_command_pools_comma_separated_directories(tmp_path: Path, capsys) -> None:
    """`compare A1,A2 B` pools A1 and A2; the text says at which env steps B, longer, is read for
    the final return; a pooling error is a clean exit naming the problem."""
    from arld_jax import run  # the CLI (imports JAX, unlike the rest of this file)

    cells, sweep = NONE_AND_BERNOULLI, {"strategy": ["none", "bernoulli"]}
    a1 = write_run_dir(tmp_path / "a1", cells, sweep)
    a2 = write_run_dir(tmp_path / "a2", cells, sweep, seeds=(3, 4))
    b = write_run_dir(tmp_path / "b", cells, sweep, periods=PERIODS + 2, total_periods=PERIODS + 2)
    run.main(["compare", f"{a1},{a2}", str(b), "--out", str(tmp_path / "c.md")])
    out = capsys.readouterr().out
    assert "| a1+a2:strategy=none − b:strategy=none | final return | 5 / 3 |" in out
    assert f"at and up to {PERIODS * EVAL_EVERY:,} env steps, the last evaluation both have" in out
    none = [r for r in compare.compare_runs(rundir.pool_runs([a1, a2]), b) if "none" in r["pair"]]
    final = next(r for r in none if r["metric"] == "final return")
    assert final["diff"] == pytest.approx(10 * (0 + 1 + 2 + 3 + 4) / 5 - 10 * (0 + 1 + 2) / 3)
    assert "Welch" in (tmp_path / "c.md").read_text()
    with pytest.raises(SystemExit, match="seed 0 of cell"):
        run.main(["compare", f"{a1},{a1}", str(b)])
    with pytest.raises(SystemExit, match="not a run directory"):
        run.main(["compare", f"{a1},{tmp_path}", str(b)])


def test_plot_pools_directories_into_one_run_directory_of_every_seed(tmp_path: Path) -> None:
    """`plot A1,A2 --out P`: seeds 0-2 and 3-4 of one experiment (A2 one evaluation short) written
    as one run directory of 5 seeds per cell over the 3 evaluations both have, which the summary
    and the comparison read like any run. eval_return = 100 (cell + 1)(p + 1) + 10 seed: at p = 2
    cell c's mean is 300 (c + 1) + 20, and AQSAC (cell 2) - SAC (cell 0) is 600 with Welch's
    interval of the hand-built samples. The state samples, drawn over whole runs, are dropped
    when the lengths differ. --out on a run directory, or on one of the sources, is refused
    with nothing written."""
    from arld_jax import run  # the CLI (imports JAX, unlike the rest of this file)

    strategies = ["none", "bernoulli", "active"]
    cells, sweep = [{"strategy": s} for s in strategies], {"strategy": strategies}
    a1 = write_run_dir(tmp_path / "a1", cells, sweep)
    a2 = write_run_dir(tmp_path / "a2", cells, sweep, periods=3, seeds=(3, 4))
    out = tmp_path / "pooled"
    run.main(["plot", f"{a1},{a2}", "--out", str(out)])
    pooled = rundir.load_run(out)
    assert (pooled.periods, pooled.partial, pooled.config["seeds"]) == (3, True, [0, 1, 2, 3, 4])
    assert pooled.config["pooled_from"] == [str(a1), str(a2)]
    assert "visited_obs" not in pooled.metrics and pooled.metrics["demos_used"].shape == (15, 3)
    as_long = write_run_dir(tmp_path / "a3", cells, sweep, seeds=(5, 6))
    kept = rundir.pool_runs([a1, as_long]).metrics  # equally long: the state samples stay
    assert kept["visited_obs"].shape[0] == kept["eval_return"].shape[0] == 15
    rows = summary.summarize(pooled)
    assert [r["n_seeds"] for r in rows] == [5, 5, 5]
    assert [r["final_return_mean"] for r in rows] == pytest.approx([320, 620, 920])
    final = next(
        r
        for r in compare.compare(pooled)
        if r["pair"] == "AQSAC - SAC" and r["metric"] == "final return"
    )
    seeds = np.arange(5.0)
    assert final["diff"] == pytest.approx(600)
    assert (final["welch_lo"], final["welch_hi"]) == pytest.approx(
        stats.welch_ci95(900 + 10 * seeds, 300 + 10 * seeds)
    )
    for name in ("summary.md", "comparison.md", "figures/fig4_5_returns.png"):
        assert (out / name).is_file(), name
    assert f"plot {a1},{a2} --out {out}" in (out / "summary.md").read_text()
    before = (a1 / "config.json").read_text()
    with pytest.raises(SystemExit, match="one of the directories pooled"):
        run.main(["plot", f"{a1},{a2}", "--out", str(a1)])
    other = write_run_dir(tmp_path / "other", cells, sweep, seeds=(7,))
    with pytest.raises(SystemExit, match="holds a run directory, not a pool"):
        run.main(["plot", f"{a1},{a2}", "--out", str(other)])
    assert (a1 / "config.json").read_text() == before
    assert rundir.load_run(other).config["seeds"] == [7]
    with pytest.raises(SystemExit, match="comma-separated, at least two"):
        run.main(["plot", str(a1), "--out", str(out)])


def test_comparison_pairs_include_active_against_greedy(tmp_path: Path) -> None:
    """With a greedy cell, active is also compared with greedy (the paper's Fig. 1 names greedy
    among the passive strategies ARLD can fall behind), and the pair holds the right cells."""
    strategies = ["none", "greedy", "bernoulli", "active"]
    path = write_run_dir(tmp_path / "g", [{"strategy": s} for s in strategies],
                         {"strategy": strategies})  # fmt: skip
    run = rundir.load_run(path)
    pairs = {name: (a, b) for name, a, b in compare.comparison_pairs(run)}
    assert list(pairs) == ["AQSAC - BQSAC", "AQSAC - GQSAC", "AQSAC - SAC"]
    a, b = pairs["AQSAC - GQSAC"]
    field = lambda cell: rundir.run_field(run, cell.runs[0], "strategy", None)  # noqa: E731
    assert (field(a), field(b)) == ("active", "greedy")


def test_every_bernoulli_cell_is_paired_and_pairs_are_read_at_quarters_of_the_run(
    tmp_path: Path,
) -> None:
    """arld_400k's shape: BQSAC with b = 0.1 and b = 0.2 beside one AQSAC and one SAC. Active is
    compared with each Bernoulli cell, named by its b; the unique cells keep their plain names.
    8 periods of 1,000 steps: every pair is also read at 2,000, 4,000 and 6,000 env steps (a
    quarter, half and three quarters of the run), where eval_return = 100 (cell + 1)(p + 1) + 10
    seed gives AQSAC (cell 3) - BQSAC b=0.1 (cell 1) = 200 (p + 1): 400 at 2,000 (p = 1), 800 at
    4,000 (p = 3), 1,200 at 6,000, 1,600 at the end. With 8 evaluations the late return would be
    the last one alone, so there is none."""
    cells = [
        {"strategy": "none"},
        {"strategy": "bernoulli", "query_prob": 0.1},
        {"strategy": "bernoulli", "query_prob": 0.2},
        {"strategy": "active"},
    ]
    sweep = {"strategy": ["none", "bernoulli", "active"], "query_prob": [0.1, 0.2]}
    path = write_run_dir(tmp_path / "b", cells, sweep, periods=8, total_periods=8)
    run = rundir.load_run(path)
    pairs = {name: (a, b) for name, a, b in compare.comparison_pairs(run)}
    assert list(pairs) == ["AQSAC - BQSAC b=0.1", "AQSAC - BQSAC b=0.2", "AQSAC - SAC"]
    assert [c.cell for c in pairs["AQSAC - BQSAC b=0.2"]] == [3, 2]
    assert compare.reading_steps(run) == [2_000, 4_000, 6_000]
    rows = {(r["pair"], r["metric"]): r for r in compare.compare(run, reps=500)}
    for metric, want in (
        ("return at 2,000", 400),
        ("return at 4,000", 800),
        ("return at 6,000", 1200),
        ("final return", 1600),
    ):
        assert rows[("AQSAC - BQSAC b=0.1", metric)]["diff"] == pytest.approx(want)
    assert compare.late_evaluations(run) == 0
    assert not any(metric.startswith("late") for _, metric in rows)
    md = compare.write_comparison(path).read_text()
    assert "also at 2,000; also at 4,000; also at 6,000." in md
    assert "Late return" not in md
    assert "| AQSAC - BQSAC b=0.2 | return at 4,000 | 3 / 3 | 400 [" in md
    # A partial run reads only the steps it has reached, and not its last one.
    partial = write_run_dir(tmp_path / "p", cells, sweep, periods=3, total_periods=8)
    assert compare.reading_steps(rundir.load_run(partial)) == [2_000]


def test_late_return_is_the_mean_of_each_runs_last_tenth_of_evaluations(tmp_path: Path) -> None:
    """20 periods of 1,000 steps: the late return averages each run's last 2 evaluations
    (19,000 and 20,000). eval_return = 100 (cell + 1)(p + 1) + 10 seed, so AQSAC (cell 1) - SAC
    (cell 0) = 100 (p + 1): 1,950 over p = 18, 19, against 2,000 at the end; resampling the
    seeds moves either side's mean by at most 20 (the seed offsets 0, 10, 20), so the bootstrap
    interval is within 40 of it. A partial directory of 15 periods averages its own last 2
    (14,000 and 15,000): 1,450."""
    cells = [{"strategy": "none"}, {"strategy": "active"}]
    sweep = {"strategy": ["none", "active"]}
    path = write_run_dir(tmp_path / "late", cells, sweep, periods=20, total_periods=20)
    run = rundir.load_run(path)
    assert compare.late_evaluations(run) == 2
    label = compare.late_return_label(run)
    assert label == "late return (19,000 to 20,000)"
    rows = {(r["pair"], r["metric"]): r for r in compare.compare(run, reps=500)}
    late = rows[("AQSAC - SAC", label)]
    assert late["diff"] == pytest.approx(1950.0)
    assert 1930.0 <= late["diff_lo"] <= 1950.0 <= late["diff_hi"] <= 1970.0
    assert rows[("AQSAC - SAC", "final return")]["diff"] == pytest.approx(2000.0)
    assert [m for p, m in rows if p == "AQSAC - SAC"] == [
        "return at 5,000",
        "return at 10,000",
        "return at 15,000",
        "final return",
        label,
        "AUC",
    ]
    md = compare.write_comparison(path).read_text()
    assert "Late return: each run's mean return over its last 2 evaluations" in md
    assert f"| AQSAC - SAC | {label} | 3 / 3 | 1,950 [" in md
    partial = rundir.load_run(
        write_run_dir(tmp_path / "partial", cells, sweep, periods=15, total_periods=20)
    )
    rows = {(r["pair"], r["metric"]): r for r in compare.compare(partial, reps=500)}
    assert rows[("AQSAC - SAC", "late return (14,000 to 15,000)")]["diff"] == pytest.approx(1450.0)


def test_comparison_pairs_are_named_after_the_agent_family(tmp_path: Path) -> None:
    """A TD3 run (Fig. 1) with both uncertainties: pairs are AQTD3 - BQTD3, ..., AQNoisyTD3 -
    BQNoisyTD3, ..., and the intrinsic - extrinsic pair per strategy (AQTD3 - AQNoisyTD3); the
    cells paired are the right ones."""
    cells = [
        {"strategy": s, "uncertainty": u}
        for s in ("none", "bernoulli", "active")
        for u in ("intrinsic", "extrinsic")
    ]
    sweep = {"strategy": ["none", "bernoulli", "active"], "uncertainty": ["intrinsic", "extrinsic"]}
    path = write_run_dir(tmp_path / "td3", cells, sweep)
    cfg = json.loads((path / "config.json").read_text())
    cfg["config"]["agent"] = "td3"
    (path / "config.json").write_text(json.dumps(cfg))
    run = rundir.load_run(path)
    pairs = {name: (a, b) for name, a, b in compare.comparison_pairs(run)}
    assert list(pairs) == [
        "AQTD3 - BQTD3",
        "AQTD3 - TD3",
        "AQNoisyTD3 - BQNoisyTD3",
        "AQNoisyTD3 - NoisyTD3",
        "AQTD3 - AQNoisyTD3",
        "BQTD3 - BQNoisyTD3",
        "TD3 - NoisyTD3",
    ]
    field = lambda cell, name: rundir.run_field(run, cell.runs[0], name, None)  # noqa: E731
    a, b = pairs["AQNoisyTD3 - BQNoisyTD3"]
    assert (field(a, "strategy"), field(a, "uncertainty")) == ("active", "extrinsic")
    assert (field(b, "strategy"), field(b, "uncertainty")) == ("bernoulli", "extrinsic")
    a, b = pairs["TD3 - NoisyTD3"]
    assert (field(a, "strategy"), field(a, "uncertainty")) == ("none", "intrinsic")
    assert (field(b, "strategy"), field(b, "uncertainty")) == ("none", "extrinsic")


def test_plain_reading_names_which_cells_differ(tmp_path: Path) -> None:
    """Final returns SAC 400/410/420, BQSAC 800/810/820, AQSAC 1,200/1,210/1,220 (seeds 0, 1, 2).
    BQSAC - SAC = +400; each side's variance of the mean is 100 / 3, so the standard error is
    sqrt(200 / 3) = 8.165 and Welch's df = (200/3)^2 / (2 (100/3)^2 / 2) = 4, t(0.975, 4) = 2.776:
    [400 - 22.67, 400 + 22.67] = [377, 423], which excludes 0. With AQSAC's seeds at 0/2,000/4,000
    (sd 2,000) its difference +1,590 has df ~ 2 and t = 4.303: [-3,378, 6,558], not separated."""
    cells = [{"strategy": "none"}, {"strategy": "bernoulli"}, {"strategy": "active"}]
    path = write_run_dir(tmp_path / "r", cells, {"strategy": ["none", "bernoulli", "active"]})
    text = compare.plain_reading(path)
    assert "- BQSAC b=0.2: 810 [785, 835]; above SAC (+400, Welch [377, 423])." in text
    assert "- AQSAC t_query=0.1: 1,210 [1,185, 1,235]; above SAC" in text
    assert "Best querying cell: AQSAC t_query=0.1." in text
    assert "Asking for demonstrations beat not asking: BQSAC b=0.2, AQSAC t_query=0.1" in text
    assert "The expert's return is 3,000; no cell's interval is above it." in text
    m = dict(np.load(path / "metrics.npz"))
    m["eval_return"][6:9, -1] = [0.0, 2000.0, 4000.0]  # AQSAC's seeds far apart
    np.savez(path / "metrics.npz", **m)
    text = compare.plain_reading(path)
    assert "- AQSAC t_query=0.1: 2,000 [" in text
    assert "not separated from SAC (+1,590, Welch [-3,378, 6,558])." in text
    assert "beat not asking: BQSAC b=0.2 ended above" in text
    # Without a separated cell the reading says so.
    m["eval_return"][3:6, -1] = [0.0, 1000.0, 2000.0]  # BQSAC's seeds far apart too
    np.savez(path / "metrics.npz", **m)
    assert "did not beat not asking here" in compare.plain_reading(path)


def test_read_at_reads_a_run_as_if_it_had_stopped_there(run_dir: Path) -> None:
    run = rundir.load_run(run_dir)
    at2k = rundir.read_at(run, 2000)
    assert at2k.periods == 2 and not at2k.partial
    assert list(rundir.env_steps_axis(at2k)) == [1000, 2000]
    assert "visited_obs" not in at2k.metrics  # drawn over the whole run: not a 2k reading
    sac, bq = summary.summarize(at2k)
    # final = evaluation 2: 200 (c + 1) + 10 s; AUC = mean(100, 200) (c + 1) + 10 s
    assert (sac["final_return_mean"], bq["final_return_mean"]) == pytest.approx((210.0, 410.0))
    assert (sac["auc_mean"], bq["auc_mean"]) == pytest.approx((160.0, 310.0))
    # demos at the 2k evaluation: 10 trace points x rate [4, 6, 8] -> [40, 60, 80]
    assert bq["demos_used_mean"] == pytest.approx(60.0) and bq["env_steps"] == 2000
    assert rundir.read_at(run, 4000) is run  # the last evaluation: the run as loaded
    with pytest.raises(ValueError, match=r"no evaluation at 2,500 env steps.*1,000, 2,000"):
        rundir.read_at(run, 2500)


def test_summary_command_prints_each_reading_and_refuses_bad_steps(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from arld_jax import run  # the CLI (imports JAX, unlike the rest of this file)

    cells = [{"strategy": "none"}, {"strategy": "bernoulli"}, {"strategy": "active"}]
    run_dir = write_run_dir(
        tmp_path / "sweep", cells, {"strategy": ["none", "bernoulli", "active"]}
    )
    out = tmp_path / "r.md"
    run.main(["summary", str(run_dir), "--at", "2000,3000", "--out", str(out)])
    text = capsys.readouterr().out
    assert out.read_text() == text
    first, second = text.split("# sweep, read at 3,000 env steps")
    assert "# sweep, read at 2,000 env steps" in first and "--at 2000,3000" in first
    # SAC's finals [200, 210, 220] and [300, 310, 320]: 210 ± 25 at 2k, 310 ± 25 at 3k
    assert "| 210 ± 25 |" in first and "| 310 ± 25 |" in second
    # its comparison, AQSAC - SAC at 2k and 3k
    assert "At the last evaluation present: 2,000 env steps" in first
    # (finals 600 + 10 s against 200 + 10 s; AUCs 450 + 10 s against 150 + 10 s)
    assert "| AQSAC - SAC | final return | 3 / 3 | 400 [" in first
    assert "| AQSAC - SAC | AUC | 3 / 3 | 300 [" in first
    assert "| AQSAC - SAC | final return | 3 / 3 | 600 [" in second  # 900 + 10 s against 300 + 10 s
    assert "Partial" not in text
    summary.write_summary(run_dir)
    before = {p.name: p.read_bytes() for p in run_dir.iterdir() if p.is_file()}
    for bad, why in (("2500", "no evaluation at 2,500"), ("1e5", "a comma list of env steps")):
        with pytest.raises(SystemExit, match=why):
            run.main(["summary", str(run_dir), "--at", bad])
    for command in (["summary", str(run_dir)], ["compare", str(run_dir), str(run_dir)]):
        with pytest.raises(SystemExit, match="would replace the run directory's own summary.md"):
            run.main([*command, "--at", "2000", "--out", str(run_dir / "summary.md")])
    after = {p.name: p.read_bytes() for p in run_dir.iterdir() if p.is_file()}
    assert after == before  # nothing written, nothing lost
