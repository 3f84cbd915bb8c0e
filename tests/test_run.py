"""The CLI and the resumable, sharded sweep driver (toy env)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

from arld_jax import cli, compare, driver, plots, run, rundir, summary
from arld_jax import config as config_mod
from arld_jax.config import Config
from arld_jax.sweep import SHIPPED_EXPERT, Sweep, SweepGroup, expert_path_for, preset_tiny

REPO = Path(__file__).resolve().parents[1]


def _quiet(**options) -> driver.RunOptions:  # noqa: ANN003
    """Run options for tests: no figures, nothing printed."""
    return driver.RunOptions(plots=False, log=lambda *a: None, **options)


def _sweep(**overrides: str) -> Sweep:
    args, sweep = run.parse_args(
        ["seed_sweep", "--preset", "tiny"] + [f"--{k}={v}" for k, v in overrides.items()]
    )
    return sweep


# ---------------------------------------------------------------- parsing


def test_overrides_and_lists_become_a_vmapped_grid():
    sweep = _sweep(strategy="none,active", t_query="0.1,0.2", seeds="3,4", budget="50")
    assert sweep.cfg.budget == 50
    assert sweep.sweep == {"strategy": ("none", "active"), "t_query": (0.1, 0.2)}
    assert sweep.seeds == (3, 4)
    # Pruned: t_query cannot change a 'none' run, so 'none' is one cell, not two copies.
    runs = sweep.runs()
    assert len(runs) == sweep.num_runs == (1 + 2) * 2
    assert [(r["strategy"], r["t_query"], r["seed"], r["cell"]) for r in runs] == [
        ("none", 0.1, 3, 0),  # t_query left at the base value
        ("none", 0.1, 4, 0),
        ("active", 0.1, 3, 1),
        ("active", 0.1, 4, 1),
        ("active", 0.2, 3, 2),
        ("active", 0.2, 4, 2),
    ]
    assert runs[0]["cell_label"] == "strategy=none"
    assert runs[2]["cell_label"] == "strategy=active t_query=0.1"
    hps, keys = sweep.hparams_and_keys()
    assert hps.strategy.shape == (6,) and keys.shape == (6,)
    assert list(np.asarray(hps.strategy)) == [0, 0, 3, 3, 3, 3]
    np.testing.assert_allclose(np.asarray(hps.t_query), [0.1, 0.1, 0.1, 0.1, 0.2, 0.2])


def test_full_grid_keeps_every_combination():
    args, sweep = run.parse_args(
        ["seed_sweep", "--preset", "tiny", "--strategy=none,active", "--t_query=0.1,0.2"]
        + ["--seeds=3,4", "--full_grid"]
    )
    runs = sweep.runs()
    assert len(runs) == sweep.num_runs == 2 * 2 * 2
    assert [(r["strategy"], r["t_query"], r["seed"]) for r in runs[:4]] == [
        ("none", 0.1, 3),
        ("none", 0.1, 4),
        ("none", 0.2, 3),
        ("none", 0.2, 4),
    ]
    # The two sweeps are different runs: neither may resume the other's directory.
    assert sweep.to_json() != _sweep(strategy="none,active", t_query="0.1,0.2").to_json()


def test_pruning_follows_each_fields_strategies():
    """b only for bernoulli, t_query only for active, C / budget / eps_d for every querying one."""
    sweep = _sweep(
        strategy="none,greedy,bernoulli,active",
        query_prob="0.1,0.3",
        t_query="0.1,0.2,0.4",
        demo_steps="1,5",
    )
    per_strategy = {}
    for cell in sweep.cells():
        per_strategy.setdefault(cell["strategy"], []).append(cell)
    assert [len(per_strategy[s]) for s in ("none", "greedy", "bernoulli", "active")] == [
        1,
        2,
        2 * 2,
        3 * 2,
    ]
    assert set(per_strategy["bernoulli"][0]) == {"strategy", "query_prob", "demo_steps"}
    assert set(per_strategy["active"][0]) == {"strategy", "t_query", "demo_steps"}
    assert sweep.num_runs == 13 * len(sweep.seeds)


def test_arld_400k_preset_is_the_papers_protocol_with_figure_4s_cells():
    """Appendix A.1's protocol (400k steps, 1 env, one update per step, budget 10,000, N_r 5,000,
    eval every 5,000, replay holding the whole run) with Fig. 4's sigma_theta cells."""
    _, sweep = run.parse_args(["seed_sweep", "--preset", "arld_400k"])
    cfg = sweep.cfg
    assert (cfg.total_env_steps, cfg.num_envs, cfg.updates_per_env_step, cfg.batch_size) == (
        400_000,
        1,
        1.0,
        256,
    )
    assert (cfg.budget, cfg.window_size, cfg.eval_every, cfg.replay_capacity) == (
        10_000,
        5_000,
        5_000,
        400_000,
    )
    assert cfg.num_eval_episodes >= 5 and cfg.backend == "mujoco" and cfg.demo_steps == 1
    assert (cfg.init_alpha, cfg.autotune_alpha, cfg.reward_scale) == (0.2, False, 5.0)
    assert cfg.per_alpha > 0 and cfg.eps_demo > 0 and expert_path_for(cfg) == SHIPPED_EXPERT
    cells = [
        (c["strategy"], c.get("query_prob"), sweep.run_configs()[i * 5].t_query)
        for i, c in enumerate(sweep.cells())
    ]
    assert cells == [
        ("none", None, 0.1),
        ("greedy", None, 0.1),
        ("bernoulli", 0.1, 0.1),
        ("bernoulli", 0.2, 0.1),
        ("active", None, 0.1),
    ]
    assert sweep.seeds == (0, 1, 2, 3, 4)
    assert all(c.uncertainty == "intrinsic" for c in sweep.run_configs())


def test_paper_preset_is_pruned_to_the_counts_its_docstring_gives():
    """142 cells x 10 seeds = 1,420 runs, and 16,000 without pruning (the docstring's counts)."""
    import inspect
    import math

    from arld_jax.sweep import preset_paper

    sweep = preset_paper()
    full = math.prod(len(values) for values in sweep.sweep.values()) * len(sweep.seeds)
    assert (len(sweep.cells()), sweep.num_runs, full) == (142, 1_420, 16_000)
    doc = " ".join(inspect.getdoc(preset_paper).split())
    assert "142 cells x 10 seeds = 1,420 runs instead of the 16,000" in doc


def test_static_field_list_is_refused():
    with pytest.raises(SystemExit, match="num_envs.*cannot be swept"):
        _sweep(num_envs="1,2")


def test_invalid_value_in_a_list_names_the_field():
    with pytest.raises(SystemExit, match="t_query"):
        _sweep(t_query="0.1,1.5")
    with pytest.raises(SystemExit, match="strategy"):
        _sweep(strategy="greedy,smart")
    with pytest.raises(SystemExit, match="budget"):
        _sweep(budget="-1")
    with pytest.raises(SystemExit, match="demo_steps"):
        _sweep(demo_steps="0")
    with pytest.raises(SystemExit, match="window_size"):
        _sweep(window_size="0")
    with pytest.raises(SystemExit, match="not a valid int"):
        _sweep(budget="lots")


@pytest.mark.parametrize(
    ("option", "text"), [("seeds", "a,b"), ("seeds", "0,-1"), ("num_seeds", "three")]
)
def test_bad_seeds_are_a_clear_error_not_a_traceback(option, text):
    with pytest.raises(SystemExit, match=rf"--{option} got .*expected integers >= 0"):
        run.parse_args(["seed_sweep", "--preset", "tiny", f"--{option}", text])


def test_unknown_option_lists_close_matches(capsys):
    with pytest.raises(SystemExit):
        run.parse_args(["seed_sweep", "--t_qury", "0.1"])
    err = capsys.readouterr().err
    assert "unknown option --t_qury" in err and "--t_query" in err


def test_help_documents_every_field(capsys):
    with pytest.raises(SystemExit):
        run.parse_args(["seed_sweep", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for name in cli.FIELDS:
        assert f"--{name}" in text, name
    assert "Proportion threshold of the active strategy" in text
    assert "(Config default: 0.1)" in text


# ---------------------------------------------------------------- resume and results


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    sweep = _sweep(strategy="none,greedy,active")
    out = tmp_path_factory.mktemp("full")
    driver.run_sweep(sweep, out, _quiet(chunk_periods=1))
    return sweep, out


def test_resume_after_a_stop_equals_uninterrupted(uninterrupted, tmp_path):
    sweep, full = uninterrupted
    first = driver.run_sweep(sweep, tmp_path, _quiet(chunk_periods=1, stop_after_chunks=2))
    assert not first["complete"]
    assert np.load(tmp_path / rundir.METRICS_FILE)["eval_return"].shape[1] == 2
    second = driver.run_sweep(sweep, tmp_path, _quiet(chunk_periods=1))
    assert second["complete"]
    a, b = np.load(full / rundir.METRICS_FILE), np.load(tmp_path / rundir.METRICS_FILE)
    assert sorted(a.files) == sorted(b.files)
    for name in a.files:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_resume_with_mujoco_c_physics_equals_uninterrupted(tmp_path):
    """The 'mujoco' backend keeps its whole physics state in the loop's carry (the host callback
    holds none), so a stopped halfcheetah run resumes bit-identically, as MJX and the toy env do."""
    sweep = _sweep(env_name="halfcheetah", backend="mujoco", strategy="none", total_env_steps=600,
                   eval_every=200, learning_starts=100, episode_length=100, num_eval_episodes=1,
                   replay_capacity=600, window_size=100)  # fmt: skip
    driver.run_sweep(sweep, tmp_path / "full", _quiet(chunk_periods=1))
    first = driver.run_sweep(
        sweep, tmp_path / "parts", _quiet(chunk_periods=1, stop_after_chunks=1)
    )
    assert not first["complete"]
    assert driver.run_sweep(sweep, tmp_path / "parts", _quiet(chunk_periods=1))["complete"]
    a = np.load(tmp_path / "full" / rundir.METRICS_FILE)
    b = np.load(tmp_path / "parts" / rundir.METRICS_FILE)
    assert np.all(np.isfinite(a["eval_return"]))
    for name in a.files:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_a_line_per_period_and_the_same_numbers_whatever_the_chunk(uninterrupted, tmp_path):
    """One period is compiled and called period after period, so a run checkpointed every 2
    periods prints a line after each of its 4 periods and equals the run checkpointed after every
    period; the lines name the cells as the figures do, with each cell's seed-mean return."""
    sweep, full = uninterrupted
    lines: list[str] = []
    options = driver.RunOptions(
        chunk_periods=2, plots=False, log=lambda *a: lines.append(" ".join(map(str, a)))
    )
    driver.run_sweep(sweep, tmp_path, options)
    assert lines[0] == "physics: none (toy is pure JAX; --backend does not apply)"
    progress = [line for line in lines if line.startswith("period ")]
    assert [line.split(" | ")[0] for line in progress] == [
        "period 1/4 (warm-up)",
        "period 2/4",
        "period 3/4",
        "period 4/4",
    ]
    tails = [line.split(" | ")[5:] for line in progress]
    assert tails == [[], ["checkpoint 1/2"], [], ["checkpoint 2/2"]]
    assert "ETA after the first learning period" in progress[0]
    assert progress[1].split(" | ")[3].startswith("ETA ") and "ETA 0 s" in progress[3]
    a, b = np.load(full / rundir.METRICS_FILE), np.load(tmp_path / rundir.METRICS_FILE)
    for name in a.files:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    returns = a["eval_return"][:, 2].reshape(3, 2).mean(axis=1)  # 3 cells x seeds 0, 1
    want = ", ".join(
        f"{n} {r:,.0f}" for n, r in zip(["SAC", "GQSAC", "AQSAC t_query=0.1"], returns, strict=True)
    )
    assert progress[2].split(" | ")[4] == f"eval return {want}"


def test_eta_counts_warm_up_and_learning_periods_apart():
    # 10 periods, 2 of warm-up at 3 s each, learning periods at 20 s each.
    assert driver.eta_seconds(0, 2, 10, None, None) is None
    assert driver.eta_seconds(1, 2, 10, 3.0, None) is None  # no learning period timed yet
    assert driver.eta_seconds(2, 2, 10, 3.0, None) is None
    assert driver.eta_seconds(3, 2, 10, 3.0, 20.0) == 7 * 20.0
    assert driver.eta_seconds(10, 2, 10, 3.0, 20.0) == 0.0
    # Resumed in the middle of the warm-up with learning time known: 1 warm + 8 learning left.
    assert driver.eta_seconds(1, 2, 10, 3.0, 20.0) == 3.0 + 8 * 20.0
    # Resumed after the warm-up: no warm-up time needed.
    assert driver.eta_seconds(4, 2, 10, None, 20.0) == 6 * 20.0
    assert driver.eta_seconds(0, 0, 5, None, 20.0) == 100.0
    assert driver.format_eta(None) == "ETA after the first learning period"
    assert driver.format_eta(12.4) == "ETA 12 s" and driver.format_eta(90.0) == "ETA 1.5 min"
    assert driver.format_eta(7200.0) == "ETA 2.0 h"


def test_latest_returns_name_each_cell_with_its_seed_mean():
    names = [f"c{i}" for i in range(12)]
    returns = np.repeat(np.arange(12.0) * 100, 2) + np.tile([0.0, 10.0], 12)  # 2 seeds a cell
    assert driver.latest_returns(names[:2], returns[:4]) == "c0 5, c1 105"
    text = driver.latest_returns(names, returns)  # the 10 best of 12, in cell order
    assert text.startswith("c2 205, c3 305") and text.endswith(
        "c11 1,105 (the best 10 of 12 cells)"
    )


def test_checkpoint_of_another_state_layout_is_refused(uninterrupted, tmp_path):
    """A checkpoint whose TrainState layout differs (written by an older arld_jax) is not restored
    position by position into the new state: a clear error, and the saved metrics are kept."""
    import shutil

    sweep, full = uninterrupted
    saved = json.loads((full / rundir.LAYOUT_FILE).read_text())
    assert int(saved["num_leaves"]) > 0 and len(saved["sha256"]) == 64
    out = tmp_path / "old"
    shutil.copytree(full, out)
    (out / rundir.LAYOUT_FILE).write_text(json.dumps(saved | {"sha256": "0" * 64}))
    metrics_before = (out / rundir.METRICS_FILE).read_bytes()
    with pytest.raises(SystemExit, match=r"another layout .* Nothing was overwritten"):
        driver.run_sweep(sweep, out, _quiet(chunk_periods=1))
    assert (out / rundir.METRICS_FILE).read_bytes() == metrics_before


class _Static:
    """Static pytree data whose repr carries its address, like MJX's `_NumPyArrayHashWrapper`."""


class _Node:
    def __init__(self, x, static):  # noqa: ANN001
        self.x, self.static = x, static


jax.tree_util.register_pytree_node(_Node, lambda n: ((n.x,), n.static), lambda s, c: _Node(c[0], s))


def test_state_layout_is_the_same_in_every_process():
    """The fingerprint must not depend on where objects live: MJX's static pytree data prints as
    "<... object at 0x...>", and with the address in it no MJX run could resume in a new process
    (seen before). Equal structure and shapes -> equal fingerprint; other shapes -> not."""
    a = {"env": _Node(np.zeros((2, 3, 4)), _Static())}
    b = {"env": _Node(np.zeros((2, 3, 4)), _Static())}
    assert str(jax.tree.structure(a)) != str(jax.tree.structure(b))  # the addresses differ
    assert rundir.state_layout(a) == rundir.state_layout(b)
    c = {"env": _Node(np.zeros((2, 3, 5)), _Static())}
    assert rundir.state_layout(c) != rundir.state_layout(a)
    renamed = {"envs": _Node(np.zeros((2, 3, 4)), _Static())}  # same shapes, another leaf path
    assert rundir.state_layout(renamed) != rundir.state_layout(a)


def test_other_config_in_same_directory_is_refused(uninterrupted):
    sweep, full = uninterrupted
    before = (full / "config.json").read_text()
    other = _sweep(strategy="none,greedy,active", budget="7")
    with pytest.raises(SystemExit, match=r"holds a different run \(budget: 200 -> 7\)"):
        driver.run_sweep(other, full, _quiet(chunk_periods=1))
    assert (full / "config.json").read_text() == before


def test_recorded_periods_without_a_checkpoint_are_not_overwritten(uninterrupted, tmp_path):
    """A run directory holding recorded periods but no checkpoint (a clone of a committed run:
    checkpoints are not committed) is refused rather than trained again from step 0 over them."""
    sweep, full = uninterrupted
    for name in ("config.json", rundir.METRICS_FILE):
        shutil.copy(full / name, tmp_path / name)
    before = (tmp_path / rundir.METRICS_FILE).read_bytes()
    with pytest.raises(SystemExit, match=r"holds 4 of 4 evaluation periods .* no checkpoint"):
        driver.run_sweep(sweep, tmp_path, _quiet(chunk_periods=1))
    assert (tmp_path / rundir.METRICS_FILE).read_bytes() == before


def test_field_added_later_at_its_default_does_not_block_resume(tmp_path):
    """A directory written before a Config field existed resumes when the field is at its default
    (new fields keep the old behaviour there), and is refused when it is not."""
    sweep = _sweep(strategy="none,active")
    identity = sweep.to_json() | {"preset": "tiny"}
    old = json.loads(json.dumps(identity))
    del old["config"]["update_before_add"]
    (tmp_path / "config.json").write_text(json.dumps(old))
    assert rundir.check_or_write_identity(tmp_path, identity) is True
    changed = _sweep(strategy="none,active", update_before_add="true").to_json()
    with pytest.raises(SystemExit, match=r"update_before_add: None -> True"):
        rundir.check_or_write_identity(tmp_path, changed | {"preset": "tiny"})


def test_results_files(uninterrupted):
    sweep, full = uninterrupted
    saved = json.loads((full / "config.json").read_text())
    assert saved["sweep"] == {"strategy": ["none", "greedy", "active"]}
    runs = json.loads((full / "runs.json").read_text())
    assert len(runs) == sweep.num_runs
    metrics = np.load(full / rundir.METRICS_FILE)
    assert metrics["eval_return"].shape == (sweep.num_runs, sweep.cfg.num_evals)
    demos = metrics["demos_used"][:, -1]
    assert list(demos[:2]) == [0, 0] and list(demos[2:4]) == [sweep.cfg.budget] * 2
    summary = (full / "summary.csv").read_text().splitlines()
    assert len(summary) == 1 + 3  # header + one row per cell
    assert "±" in (full / "summary.md").read_text()


def test_compare_two_run_directories(uninterrupted, tmp_path, capsys):
    """`compare A B`: cells paired by label; a - b is the difference of the cells' mean returns
    (checked against the metrics), a run against itself by exactly 0 with P(a > b) = 0.5;
    steps that are not evaluated in both and different evaluation schedules are clear errors."""
    _, full = uninterrupted
    other = tmp_path / "other"
    # Other seeds, one cell fewer; the same number of runs, so the same compiled program.
    sweep = _sweep(strategy="none,active", seeds="2,3,4")
    driver.run_sweep(sweep, other, _quiet(chunk_periods=4))
    rows = compare.compare_runs(full, other, at_steps=[1000])
    assert {r["pair"].split(" − ")[0].split(":")[1] for r in rows} == {
        "strategy=none",
        "strategy=active",
    }
    assert [r["metric"] for r in rows[:3]] == ["return at 1,000", "final return", "AUC"]
    a, b = np.load(full / rundir.METRICS_FILE), np.load(other / rundir.METRICS_FILE)
    runs_a = [i for i, r in enumerate(json.loads((full / "runs.json").read_text()))
              if r["cell_label"] == "strategy=active"]  # fmt: skip
    runs_b = [i for i, r in enumerate(json.loads((other / "runs.json").read_text()))
              if r["cell_label"] == "strategy=active"]  # fmt: skip
    final = next(r for r in rows if "active" in r["pair"] and r["metric"] == "final return")
    want = a["eval_return"][runs_a, -1].mean() - b["eval_return"][runs_b, -1].mean()
    assert final["diff"] == pytest.approx(want, abs=1e-5)
    assert final["diff_lo"] <= final["diff"] <= final["diff_hi"]
    at_1000 = next(r for r in rows if "active" in r["pair"] and r["metric"] == "return at 1,000")
    want = a["eval_return"][runs_a, 1].mean() - b["eval_return"][runs_b, 1].mean()
    assert at_1000["diff"] == pytest.approx(want, abs=1e-5)  # eval_every 500: the 2nd evaluation
    for r in compare.compare_runs(full, full):
        assert (r["diff"], r["p_improve"]) == (0.0, 0.5)  # a and b resampled apart: CI spans 0
        assert r["diff_lo"] <= 0.0 <= r["diff_hi"] and r["p_lo"] <= 0.5 <= r["p_hi"]
    with pytest.raises(ValueError, match="no evaluation at 1,234 env steps"):
        compare.compare_runs(full, other, at_steps=[1234])
    run.main(["compare", str(full), str(other), "--at", "1000", "--out", str(tmp_path / "c.md")])
    assert "return at 1,000" in capsys.readouterr().out
    assert "| a − b |" in (tmp_path / "c.md").read_text()
    with pytest.raises(SystemExit, match="comma list of env steps"):
        run.main(["compare", str(full), str(other), "--at", "lots"])
    with pytest.raises(SystemExit, match="not a run directory"):
        run.main(["compare", str(full), str(tmp_path)])
    slower = tmp_path / "slower"  # `other` as if it evaluated every 1,000 steps: no second compile
    shutil.copytree(other, slower)
    config = json.loads((slower / rundir.CONFIG_FILE).read_text())
    config["config"]["eval_every"] = 1000
    (slower / rundir.CONFIG_FILE).write_text(json.dumps(config))
    with pytest.raises(ValueError, match="evaluates every 500 env steps"):
        compare.compare_runs(full, slower)


def test_needs_expert_for_halfcheetah_queries(tmp_path):
    base = preset_tiny()
    cfg = base.cfg.replace(env_name="halfcheetah", expert_path=str(tmp_path / "nothing"))
    sweep = Sweep(cfg=cfg, sweep={"strategy": ("none", "active")}, seeds=(0,))
    with pytest.raises(SystemExit, match="No expert at"):
        driver.run_sweep(sweep, tmp_path / "out", _quiet())
    assert not (tmp_path / "out").exists()  # nothing written before the check


# ---------------------------------------------------------------- multi-device sharding


@pytest.mark.skipif(
    jax.default_backend() != "cpu", reason="two forced host devices against a CPU run"
)
def test_sharded_over_two_devices_equals_one_device(uninterrupted, tmp_path):
    """The run axis sharded over 2 (forced host) devices gives the same numbers as one device.

    Each device then runs a smaller vmapped batch, so XLA may round the batched matmuls differently
    (ulp-level); SAC amplifies such differences chaotically over thousands of updates (seen here:
    equal to 1e-5 over the first 500 env steps, a few % apart after 1,500; an active query decision
    flips on a tiny difference). So the comparison is tight over the first period, and the
    demonstration counts of the strategies that do not depend on floats must match exactly."""
    sweep, full = uninterrupted
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2")
    code = (
        "import jax, sys; assert jax.device_count() == 2, jax.devices();"
        "from arld_jax import run;"
        "run.main(['seed_sweep', '--preset', 'tiny', '--strategy', 'none,greedy,active',"
        f" '--chunk_periods', '1', '--no_plots', '--out', {str(tmp_path)!r}])"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code], env=env, cwd=REPO, capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "2 device(s)" in proc.stdout
    a, b = np.load(full / rundir.METRICS_FILE), np.load(tmp_path / rundir.METRICS_FILE)
    for name in ("eval_return", "critic_loss", "uncertainty_trace"):
        np.testing.assert_allclose(
            a[name][:, :1], b[name][:, :1], rtol=1e-4, atol=1e-4, err_msg=name
        )
    runs = json.loads((tmp_path / "runs.json").read_text())
    not_active = [r["run"] for r in runs if r["strategy"] != "active"]
    np.testing.assert_array_equal(a["demos_used"][not_active], b["demos_used"][not_active])


def test_evaluate_expert_rolls_out_fresh_episodes(uninterrupted, tmp_path, capsys):
    """`evaluate_expert` reports the exported actor's deterministic return on fresh episodes (a
    trained toy policy earns close to 1 per step, an untrained one far less) and no gait; its
    printed line names neither a gait nor falls, which the toy task has not."""
    _, full = uninterrupted
    driver.export_expert(full, tmp_path / "expert")
    report = driver.evaluate_expert(tmp_path / "expert", episodes=4, seed=3)
    assert len(report["returns"]) == 4 and report["episodes"] == 4
    assert report["return_mean"] == pytest.approx(np.mean(report["returns"]), abs=0.1)
    assert report["return_mean"] > 0.85 * 1000  # Config's default 1,000-step episodes
    assert report["upside_down"] == 0.0  # the toy env has no body
    run.main(["evaluate_expert", str(tmp_path / "expert"), "--episodes", "2"])
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert "(toy, " in line and "upside down" not in line and "fell" not in line
    with pytest.raises(SystemExit, match="at least 2"):
        run.main(["evaluate_expert", str(tmp_path / "expert"), "--episodes", "1"])


def test_an_expert_plays_in_the_physics_it_was_trained_in():
    """`evaluate_expert` rebuilds the expert's physics from its metadata: its backend, and
    MuJoCo's solver options and contacts where its run set them (an exported expert records them
    only then); `--backend` changes the engine, not the solver or the contacts."""
    meta = {"env_name": "ant", "backend": "mujoco"}
    cfg = driver.expert_config(meta)
    assert (cfg.backend, cfg.solver_iterations, cfg.solver_ls_iterations) == ("mujoco", 0, 0)
    assert cfg.contacts == "task" and config_mod.physics_settings(cfg) == {}
    solver = meta | {"solver_iterations": 100, "solver_ls_iterations": 50, "contacts": "all"}
    cfg = driver.expert_config(solver, backend="mjx")
    assert (cfg.backend, cfg.solver_iterations, cfg.solver_ls_iterations) == ("mjx", 100, 50)
    assert cfg.contacts == "all"
    assert config_mod.physics_settings(cfg) == {
        k: v for k, v in solver.items() if k not in ("env_name", "backend")
    }
    with pytest.raises(ValueError, match="solver_iterations = 100 is invalid"):
        driver.expert_config(solver, backend="spring")


def test_a_run_notes_an_expert_trained_in_other_physics():
    """An expert asked in physics other than its own is allowed but named in the run's log: the
    options that differ on each side; nothing where they agree (an expert that records no physics
    was trained in Brax's own model) or where the expert records no task (the toy expert)."""
    gym = {"env_name": "ant_contact", "backend": "mujoco", "integrator": "rk4", "contacts": "all"}
    brax = Config(env_name="ant_contact", backend="mujoco")
    note = driver.expert_physics_note(gym, brax)
    assert note is not None
    assert "trained with --contacts all --integrator rk4" in note
    assert "this run has Brax's own model" in note
    same = brax.replace(integrator="rk4", contacts="all", backend="mjx")  # the engine may differ
    assert driver.expert_physics_note(gym, same) is None
    rk4_only = brax.replace(integrator="rk4")
    assert "this run has --integrator rk4:" in driver.expert_physics_note(gym, rk4_only)
    assert driver.expert_physics_note({"env_name": "ant_contact"}, brax) is None
    assert "Brax's own model, this run has --integrator rk4" in driver.expert_physics_note(
        {"env_name": "ant_contact"}, rk4_only
    )
    assert driver.expert_physics_note({"obs_dim": 3}, rk4_only) is None


def test_shipped_expert_runs_as_well_in_mujoco_c_physics(capsys):
    """`evaluate_expert --backend mujoco`: the shipped expert, trained in MJX, keeps its upright
    running gait when MuJoCo's C engine steps the same model (it is the same task), and the report
    names the physics it ran in."""
    run.main(["evaluate_expert", str(run.SHIPPED_EXPERT), "--episodes", "2", "--backend", "mujoco"])
    out = capsys.readouterr().out
    report = json.loads(out[: out.rindex("}") + 1])
    assert report["backend"] == "mujoco" and len(report["returns"]) == 2
    assert min(report["returns"]) > 5_000 and report["upside_down"] == 0.0
    assert "(halfcheetah, mujoco): deterministic return" in out and "upside down" in out


def test_export_expert_from_a_run_acts_like_its_best_actor(uninterrupted, tmp_path, monkeypatch):
    import jax

    from arld_jax.envs import make_env
    from arld_jax.evaluate import evaluate_policy
    from arld_jax.expert import load_expert

    sweep, full = uninterrupted
    driver.export_expert(full, tmp_path / "expert")
    meta = json.loads((tmp_path / "expert" / "expert.json").read_text())
    final = np.load(full / rundir.METRICS_FILE)["eval_return"][:, -1]
    assert meta["eval_return"] == pytest.approx(float(final.max()))
    assert meta["train_env_steps"] == sweep.cfg.total_env_steps
    assert "solver_iterations" not in meta  # recorded only where the run set MuJoCo's solver
    assert meta["training_run"] == str(full)  # outside the working directory: as given
    monkeypatch.chdir(full.parent)  # inside it: relative, as a shipped expert names its run
    driver.export_expert(full, tmp_path / "again")
    assert json.loads((tmp_path / "again" / "expert.json").read_text())["training_run"] == full.name
    env = make_env(sweep.cfg)
    expert = load_expert(tmp_path / "expert", env.obs_dim, env.action_dim)
    ret = evaluate_policy(
        env,
        lambda obs: expert.act(expert.params, obs, jax.random.key(0)),
        jax.random.key(11),
        20,
        sweep.cfg.episode_length,
    ).episode_return
    # The exported actor is the trained one: far above an untrained policy (~20 on this toy env).
    assert float(ret) > 0.85 * sweep.cfg.episode_length


# ---------------------------------------------------------------- groups (one program per agent)


def test_agent_list_is_a_group_of_programs_with_one_summary(tmp_path, capsys):
    """`--agent sac,td3` trains one compiled program per agent family into agent-<name>/, then
    one summary of both; a rerun skips finished members; another group there is refused."""
    argv = ["seed_sweep", "--preset", "tiny", "--agent", "sac,td3", "--seeds", "0"]
    argv += ["--strategy", "none,greedy", "--total_env_steps", "1000", "--no_plots"]
    args, group = run.parse_args(argv)
    assert isinstance(group, SweepGroup)
    assert [(name, s.cfg.agent) for name, s in group.members] == [
        ("agent-sac", "sac"),
        ("agent-td3", "td3"),
    ]
    assert all(s.sweep == {"strategy": ("none", "greedy")} for _, s in group.members)
    out = tmp_path / "group"
    options = driver.RunOptions(plots=False, command="python -m arld_jax.run " + " ".join(argv))
    assert driver.run_group(group, out, options)
    rows = summary.summarize_group(out)
    assert [(r["agent"], r["cell_label"], r["name"]) for r in rows] == [
        ("sac", "strategy=none", "SAC"),
        ("sac", "strategy=greedy", "GQSAC"),
        ("td3", "strategy=none", "TD3"),
        ("td3", "strategy=greedy", "GQTD3"),
    ]
    assert all(r["env_steps"] == 1000 for r in rows)
    assert [r["demos_used_mean"] for r in rows] == [0, group.members[0][1].cfg.budget] * 2
    md = (out / "summary.md").read_text()
    assert "| td3 | GQTD3 |" in md  # the paper's names of the family that ran
    capsys.readouterr()
    assert driver.run_group(group, out, options)  # nothing left to train
    assert capsys.readouterr().out.count(": complete") == 2
    _, other = run.parse_args(argv[:4] + ["sac,boot_td3"] + argv[5:])
    with pytest.raises(SystemExit, match="another group"):
        driver.run_group(other, out, options)
    assert plots.plot_group(out).exists()


def test_uncertainty_is_pruned_for_bootstrapped_td3():
    """Bootstrapped TD3's uncertainty is its heads' disagreement: sweeping intrinsic/extrinsic
    would train the same runs twice, so its cells drop the field (TD3's keep it: Noisy TD3)."""
    boot = _sweep(agent="boot_td3", strategy="none,active", uncertainty="intrinsic,extrinsic")
    assert [c for c in boot.cells()] == [{"strategy": "none"}, {"strategy": "active"}]
    td3 = _sweep(agent="td3", strategy="none,active", uncertainty="intrinsic,extrinsic")
    assert len(td3.cells()) == 4
