"""Tests of reading our runs against sbx's (benchmarks/peers/vs_sbx.py) on hand-written run
directories (tests/test_results.py's `write_run_dir`) and sbx JSONs, with numbers worked out on
paper and Welch's interval from scipy's own t-test."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import stats as scipy_stats
from test_results import EVAL_EVERY, write_run_dir

from arld_jax import stats
from benchmarks.peers import vs_sbx

PERIODS = 20  # 20 evaluations: a late window of 2 (stats.late_window)
SEEDS = (0, 1, 2)
SBX_FINAL = {0: 1500.0, 1: 1900.0, 2: 2600.0, 3: 2100.0}


def sbx_curve(seed: int, steps: list[int]) -> list[float]:
    """A seed's evaluation means: a straight line from 100 to SBX_FINAL[seed] at the last step."""
    return list(np.linspace(100.0, SBX_FINAL[seed], len(steps)))


def write_sbx(
    path: Path, seed: int, steps: list[int], env: str = "Walker2d-v5", complete: bool = True
) -> Path:
    """An sbx_sac.py JSON; each evaluation's two episodes are its mean ∓ 7."""
    curve = sbx_curve(seed, steps)
    report = {
        "peer": "sbx SAC",
        "env": env,
        "seed": seed,
        "steps": steps[-1],
        "complete": complete,
        "eval_env_steps": steps,
        "eval_returns": [[v - 7.0, v + 7.0] for v in curve],
        "eval_lengths": [[1000, 1000] for _ in curve],
    }
    path.write_text(json.dumps(report))
    return path


@pytest.fixture()
def ours(tmp_path: Path) -> Path:
    """One cell (plain SAC), seeds 0-2: eval_return[seed, p] = 100 (p + 1) + 10 seed."""
    return write_run_dir(
        tmp_path / "ours",
        [{"strategy": "none"}],
        {},
        periods=PERIODS,
        total_periods=PERIODS,
        seeds=SEEDS,
    )


ALL_STEPS = [(p + 1) * EVAL_EVERY for p in range(PERIODS)]
EVEN_STEPS = ALL_STEPS[1::2]  # sbx evaluating every other of our evaluations


def test_readings_match_hand_values_and_scipy_welch(ours: Path, tmp_path: Path) -> None:
    files = [write_sbx(tmp_path / f"s{s}.json", s, EVEN_STEPS) for s in (0, 1, 2, 3)]
    rows = vs_sbx.readings(
        vs_sbx.load_ours([ours]), vs_sbx.load_sbx(files), [2 * EVAL_EVERY, PERIODS * EVAL_EVERY]
    )
    by = {r["reading"]: r for r in rows}

    final_ours = np.array([2000.0, 2010.0, 2020.0])
    final_sbx = np.array([SBX_FINAL[s] for s in (0, 1, 2, 3)])
    row = by[f"return at {PERIODS * EVAL_EVERY:,}"]
    assert row["ours_mean"] == pytest.approx(2010.0)
    assert row["peer_mean"] == pytest.approx(2025.0)
    assert row["difference"] == pytest.approx(-15.0)
    ci = scipy_stats.ttest_ind(final_ours, final_sbx, equal_var=False).confidence_interval(0.95)
    assert (row["welch_lo"], row["welch_hi"]) == pytest.approx((ci.low, ci.high))
    assert row["separated"] is False
    assert row["peer_ci95"] == pytest.approx(stats.mean_ci95(final_sbx)[1])

    # at 2k: ours 200 + 10 seed; every sbx seed at its line's start, 100: separated
    row = by[f"return at {2 * EVAL_EVERY:,}"]
    assert (row["ours_mean"], row["peer_mean"]) == pytest.approx((210.0, 100.0))
    assert row["separated"] is True and row["welch_lo"] > 0

    # late: of the 10 evaluations both have, the last tenth is one evaluation, too few for a
    # late return: no row, not a reading of different stretches nor a row of nan
    assert not [r for r in rows if r["reading"].startswith("late return")]
    assert all(np.isfinite(r["ours_mean"]) and np.isfinite(r["peer_mean"]) for r in rows)

    # AUC over the 10 evaluations both have: ours' even-numbered evaluations
    auc = by["AUC over 10 common evaluations"]
    assert auc["ours_mean"] == pytest.approx(
        np.mean([100.0 * (p + 1) for p in range(1, PERIODS, 2)]) + 10.0
    )
    assert auc["peer_mean"] == pytest.approx(
        np.mean([np.mean(sbx_curve(s, EVEN_STEPS)) for s in (0, 1, 2, 3)])
    )


def test_late_return_uses_the_same_window_on_both_sides(ours: Path, tmp_path: Path) -> None:
    files = [write_sbx(tmp_path / f"s{s}.json", s, ALL_STEPS) for s in (0, 1)]
    rows = vs_sbx.readings(vs_sbx.load_ours([ours]), vs_sbx.load_sbx(files), [])
    late = {r["reading"]: r for r in rows}["late return (of 20 common evaluations)"]
    assert late["ours_mean"] == pytest.approx(1960.0)  # 1,900 and 2,000, + 10 seed
    expected = np.mean([np.mean(sbx_curve(s, ALL_STEPS)[-2:]) for s in (0, 1)])
    assert late["peer_mean"] == pytest.approx(expected)


def test_a_longer_peer_is_read_over_the_stretch_both_have(ours: Path, tmp_path: Path) -> None:
    """sbx evaluated to 40k, ours to 20k: the late return and AUC are sbx's at 1k-20k, not its
    own last evaluations (its line keeps rising to 40k)."""
    longer = [(p + 1) * EVAL_EVERY for p in range(2 * PERIODS)]
    files = [write_sbx(tmp_path / f"s{s}.json", s, longer) for s in (0, 1)]
    rows = {
        r["reading"]: r
        for r in vs_sbx.readings(vs_sbx.load_ours([ours]), vs_sbx.load_sbx(files), [])
    }
    first_half = [np.array(sbx_curve(s, longer)[:PERIODS]) for s in (0, 1)]
    late = rows["late return (of 20 common evaluations)"]
    assert late["peer_mean"] == pytest.approx(np.mean([c[-2:].mean() for c in first_half]))
    auc = rows["AUC over 20 common evaluations"]
    assert auc["peer_mean"] == pytest.approx(np.mean([c.mean() for c in first_half]))
    assert auc["ours_mean"] == pytest.approx(1060.0)  # mean of 100 (p + 1) over p < 20, + 10


def test_unfinished_mixed_or_repeated_sbx_runs_are_refused(tmp_path: Path) -> None:
    done = write_sbx(tmp_path / "done.json", 0, ALL_STEPS)
    with pytest.raises(ValueError, match=r"part\.json is unfinished .*20,000 of 20,000"):
        vs_sbx.load_sbx([done, write_sbx(tmp_path / "part.json", 1, ALL_STEPS, complete=False)])
    with pytest.raises(ValueError, match="differ in env .*'Ant-v5' against 'Walker2d-v5'"):
        vs_sbx.load_sbx([done, write_sbx(tmp_path / "ant.json", 1, ALL_STEPS, env="Ant-v5")])
    with pytest.raises(ValueError, match="differ in eval_env_steps"):
        vs_sbx.load_sbx([done, write_sbx(tmp_path / "even.json", 1, EVEN_STEPS)])
    with pytest.raises(ValueError, match="seed 0 is given twice"):
        vs_sbx.load_sbx([done, write_sbx(tmp_path / "again.json", 0, ALL_STEPS)])
    with pytest.raises(FileNotFoundError, match="missing.json does not exist"):
        vs_sbx.load_sbx([done, tmp_path / "missing.json"])


def test_a_sweep_of_several_cells_is_refused(tmp_path: Path) -> None:
    two = write_run_dir(
        tmp_path / "two",
        [{"strategy": "none"}, {"strategy": "greedy"}],
        {"strategy": ["none", "greedy"]},
    )
    with pytest.raises(ValueError, match="holds 2 cells"):
        vs_sbx.load_ours([two])


def test_command_line_writes_the_table_and_names_a_missing_evaluation(
    ours: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    files = [str(write_sbx(tmp_path / f"s{s}.json", s, ALL_STEPS)) for s in (0, 1)]
    out = tmp_path / "vs.md"
    vs_sbx.main([str(ours), *files, "--at", "20000", "--out", str(out)])
    text = out.read_text()
    assert "| return at 20,000 | 2,010 ± " in text
    assert (
        "sbx Walker2d-v5, last evaluation (20,000 env steps) by seed: 0: 1,500, 1: 1,900." in text
    )
    assert "Written by `python -m benchmarks.peers.vs_sbx " in text

    out.unlink()
    with pytest.raises(SystemExit) as exit_info:
        vs_sbx.main([str(ours), *files, "--at", "15500", "--out", str(out)])
    assert exit_info.value.code == 2
    assert "no evaluation at 15,500 env steps" in capsys.readouterr().err
    assert not out.exists()
