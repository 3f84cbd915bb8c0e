"""The run-directory and checkpoint format: what `arld_jax.driver` writes and reads back.

A run directory holds config.json (the run's identity, compared on resume), runs.json, metrics.npz
(per-run arrays `[num_runs, num_periods, ...]`, rewritten after every chunk), state_layout.json (a
fingerprint of the checkpointed state's leaves), checkpoints/ (orbax, the complete training state
after each chunk), and when complete timing.json, summary.md/csv, comparison.md/csv and figures/
(`arld_jax.summary`, `arld_jax.compare`, `arld_jax.plots`). A group of runs (one per agent family)
has group.json and one such directory per member. Every file name is written here once.

`load_run` is the one reader: a typed `RunDir`. A sweep that is still running leaves a *partial*
directory whose metrics hold fewer periods than `total_env_steps // eval_every`; everything that
reads it then summarises the periods present and says so.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from arld_jax.config import FIELDS

CHECKPOINT_DIR = "checkpoints"
METRICS_FILE = "metrics.npz"
LAYOUT_FILE = "state_layout.json"  # fingerprint of the checkpointed TrainState's tree and shapes
GROUP_FILE = "group.json"
"""In the output directory of a `SweepGroup`: its members' subdirectory names and the command."""
CONFIG_FILE = "config.json"
"""The run's identity: resolved config, swept fields, seeds (compared on resume), command, expert."""
RUNS_FILE = "runs.json"
"""One record per run, in run order: run, cell, cell_label, seed and every sweepable field."""
TIMING_FILE = "timing.json"
"""Written when a sweep completes: wall, train and compile seconds, env steps per second."""
SUMMARY_CSV, SUMMARY_MD = "summary.csv", "summary.md"
"""The summary table of a run directory (or of a group's members together)."""
COMPARISON_CSV, COMPARISON_MD = "comparison.csv", "comparison.md"
"""The pairwise comparisons of the paper's strategies."""
FIGURES_DIR = "figures"
"""The paper's figures, redrawn by `python -m arld_jax.run plot DIR`."""
WRITTEN_FILES: tuple[str, ...] = (
    METRICS_FILE, LAYOUT_FILE, GROUP_FILE, CONFIG_FILE, RUNS_FILE, TIMING_FILE,
    SUMMARY_CSV, SUMMARY_MD, COMPARISON_CSV, COMPARISON_MD,
)  # fmt: skip
"""The files a run directory's own writers (the sweep, `plot`) own: no --out may replace one."""


def recorded_field(config: dict[str, Any], name: str) -> Any:
    """Config field `name` as the config a run directory saved (`config.json`'s "config") records
    it. A field added to Config after the directory was written reads as its default: new fields
    keep the old behaviour at their default, so that is what the run had."""
    if name in config or name not in FIELDS:
        return config.get(name)
    return json.loads(json.dumps(FIELDS[name].default))


def check_or_write_identity(out: Path, identity: dict[str, Any]) -> bool:
    """Write config.json, or check it matches. Returns True if the directory already held this run."""
    path = out / CONFIG_FILE
    if path.exists():
        saved = json.loads(path.read_text())
        keys = ("config", "sweep", "seeds")
        old = {k: saved.get(k) for k in keys}
        new = json.loads(json.dumps({k: identity[k] for k in keys}))
        # A Config field added after the run was saved, at its default, is what the run had
        # (`recorded_field`), so it does not block resuming.
        for f in set(new["config"]) - set(old["config"] or {}):
            if f in FIELDS and new["config"][f] == recorded_field(old["config"] or {}, f):
                del new["config"][f]
        if old != new:
            diffs = []
            for k in keys:
                if k == "config":
                    diffs += [
                        f"{f}: {old[k].get(f)!r} -> {new[k].get(f)!r}"
                        for f in sorted(set(old[k]) | set(new[k]))
                        if old[k].get(f) != new[k].get(f)
                    ]
                elif old[k] != new[k]:
                    diffs.append(f"{k}: {old[k]!r} -> {new[k]!r}")
            raise SystemExit(
                f"error: {out} holds a different run ({'; '.join(diffs)}). Nothing was overwritten: "
                "use another --out, or the same settings to resume."
            )
        return True
    out.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(identity, indent=2) + "\n")
    os.replace(tmp, path)
    return False


def save_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, path)


def is_key(x: Any) -> bool:
    import jax

    return hasattr(x, "dtype") and jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key)


def checkpoint_key(index: int) -> str:
    """The orbax key of the state's leaf number `index` (leaves in `jax.tree.leaves` order)."""
    return f"{index:05d}"


def to_checkpoint(state: Any) -> dict[str, Any]:
    """The state's leaves as a flat {index: array} dict for orbax: typed PRNG keys become their raw
    uint32 data, and zero-size leaves (orbax refuses them; e.g. MJX's empty actuator arrays) are
    left out: `from_checkpoint` takes them from a template state."""
    import jax

    leaves = jax.tree.leaves(state)
    return {
        checkpoint_key(i): jax.random.key_data(x) if is_key(x) else x
        for i, x in enumerate(leaves)
        if x.size > 0
    }


def from_checkpoint(saved: dict[str, Any], template: Any) -> Any:
    """Inverse of `to_checkpoint`, with structure, key types and empty leaves from `template`."""
    import jax

    leaves, treedef = jax.tree.flatten(template)
    out = []
    for i, x in enumerate(leaves):
        if x.size == 0:
            out.append(x)
        else:
            data = saved[checkpoint_key(i)]
            out.append(jax.random.wrap_key_data(data) if is_key(x) else data)
    return jax.tree.unflatten(treedef, out)


def state_layout(state: Any) -> dict[str, Any]:
    """A fingerprint of the state's leaves: each leaf's path (field and parameter names), shape and
    dtype, in order. The checkpoint stores leaves by position, so a run saved by code with another
    state layout (e.g. before the twin critics became `q0`/`q1`) must not be restored into this one.
    Class names and static pytree data are not part of it (MJX's print with object addresses that
    change from process to process), so code that keeps the leaves keeps its runs resumable.
    The leading (runs) axis is left out: its padding depends on the device count, not the code."""
    import hashlib

    import jax

    flat, _ = jax.tree_util.tree_flatten_with_path(state)
    text = "".join(f"{jax.tree_util.keystr(path)}{x.shape[1:]}{x.dtype};" for path, x in flat)
    return {"sha256": hashlib.sha256(text.encode()).hexdigest(), "num_leaves": len(flat)}


def layout_error(out: Path, done: int, why: str) -> str:
    return (
        f"error: {out} holds a checkpoint (chunk {done}) of a training state with another layout "
        f"than this version of arld_jax builds ({why}); it was probably written by an older version "
        "(or, if only the number of runs differs, on a different number of devices). "
        f"Nothing was overwritten: its metrics up to chunk {done} stay in {out / METRICS_FILE}. "
        "Use another --out to start afresh, or the arld_jax version that wrote it to resume."
    )


def check_layout(out: Path, layout: dict[str, Any], done: int) -> None:
    path = out / LAYOUT_FILE
    if path.exists():
        saved = json.loads(path.read_text())
        if saved != layout:
            raise SystemExit(layout_error(out, done, f"saved {saved}, now {layout}"))


STATE_SAMPLES: tuple[str, ...] = ("visited", "queried")
"""The state samples of metrics.npz (`<name>_obs`, `_env_step`, `_valid`: [runs, K, ...], drawn
over the whole run, no period axis)."""


def state_samples(state, num_runs: int) -> dict[str, np.ndarray]:  # noqa: ANN001
    out = {}
    for name in STATE_SAMPLES:
        s = getattr(state, name)
        out[f"{name}_obs"] = np.asarray(s.obs)[:num_runs]
        out[f"{name}_env_step"] = np.asarray(s.env_step)[:num_runs]
        out[f"{name}_valid"] = np.asarray(s.key)[:num_runs] >= 0
    return out


# ---------------------------------------------------------------- reading a run directory back


REQUIRED_FILES: tuple[str, ...] = (CONFIG_FILE, RUNS_FILE, METRICS_FILE)
"""Files a run directory must have before it can be summarised or plotted."""


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
    config = json.loads((path / CONFIG_FILE).read_text())
    runs = json.loads((path / RUNS_FILE).read_text())
    try:
        with np.load(path / METRICS_FILE, allow_pickle=False) as npz:
            metrics = {key: np.asarray(npz[key]) for key in npz.files}
    except (OSError, ValueError, EOFError) as err:
        raise ValueError(
            f"cannot read {path / 'metrics.npz'} ({err}); the sweep may be writing it right now, "
            "try again in a moment"
        ) from err
    timing_path = path / TIMING_FILE
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


POOL_SAME_ENTRIES: tuple[str, ...] = ("sweep", "expert")
"""The entries of config.json besides the config that pooled directories share (sweep: but seeds)."""


def _pool_identity(run: RunDir) -> dict[str, Any]:
    """What `pool_runs` requires pooled directories to share: every Config field but
    `POOL_MAY_DIFFER` as the directory records it (`recorded_field`), and `POOL_SAME_ENTRIES`."""
    identity = {f: recorded_field(run.cfg, f) for f in set(run.cfg) | set(FIELDS)}
    identity.update({what: run.config.get(what) for what in POOL_SAME_ENTRIES})
    identity["sweep"] = {k: v for k, v in (identity["sweep"] or {}).items() if k != "seed"}
    return {k: v for k, v in identity.items() if k not in POOL_MAY_DIFFER}


def pool_runs(run_dirs: Sequence[str | Path | RunDir]) -> RunDir:
    """Run directories of one experiment run with different seeds (seeds 0-4, later 5-9 with the
    same command and another --out), read as one: their runs side by side, in the order given,
    over the evaluations all of them have (`pool_metrics`); one directory is returned as loaded.
    The config is the first directory's with every seed, and each directory's command in
    `pooled_commands` in place of one `command`.

    Raises ValueError naming the directories and the difference when their configs differ in a
    field other than `POOL_MAY_DIFFER`, when their sweeps or experts differ, or when a cell has the
    same seed in two of them (its runs would be counted twice)."""
    runs = [as_run(d) for d in run_dirs]
    if not runs:
        raise ValueError("pool_runs needs at least one run directory")
    if len(runs) == 1:
        return runs[0]
    first = runs[0]
    want = _pool_identity(first)
    for other in runs[1:]:
        have = _pool_identity(other)
        differ = [f for f in sorted(set(want) | set(have)) if want.get(f) != have.get(f)]
        if differ:
            shown = ", ".join(f"{f} {want.get(f)!r} against {have.get(f)!r}" for f in differ)
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
    entries = [dict(e, run=i) for i, e in enumerate(e for r in runs for e in r.runs)]
    seeds = [s for r in runs for s in r.config.get("seeds", [])]
    commands = [r.config.get("command") for r in runs]  # the pool has no one command of its own
    return RunDir(
        path=first.path,
        config=dict(first.config, seeds=seeds, command=None, pooled_commands=commands),
        runs=entries,
        metrics=pool_metrics(runs, periods),
        timing={},
        periods=periods,
        expected_periods=max(r.expected_periods for r in runs),
        partial=any(r.partial or r.periods > periods for r in runs),
        missing_runs=sum(r.missing_runs for r in runs),
        sources=tuple(r.path for r in runs),
    )


def pool_metrics(runs: Sequence[RunDir], periods: int) -> dict[str, np.ndarray]:
    """The metrics every one of `runs` has, their runs side by side: period metrics over the first
    `periods` evaluations; the state samples (`STATE_SAMPLES`, drawn over a whole run) only when
    every run has exactly `periods` evaluations, since a longer run's would cover later states."""
    samples = tuple(f"{name}_" for name in STATE_SAMPLES)
    same_length = all(r.periods == periods for r in runs)
    out = {}
    for key in sorted(set.intersection(*(set(r.metrics) for r in runs))):
        arrays = [np.asarray(r.metrics[key]) for r in runs]
        if key.startswith(samples):
            if same_length:
                out[key] = np.concatenate(arrays)
        elif all(a.ndim >= 2 for a in arrays):
            out[key] = np.concatenate([a[:, :periods] for a in arrays])
    if "env_steps" not in out:  # directories written before env_steps was recorded
        steps = env_steps_axis(runs[0])[:periods]
        out["env_steps"] = np.tile(steps, (len(out["eval_return"]), 1))
    return out


def write_pooled(run_dirs: Sequence[str | Path], out: Path, command: str) -> RunDir:
    """Write `pool_runs(run_dirs)` as a run directory `out` (config.json, runs.json, metrics.npz),
    which `plot` then summarises, compares and draws like any other: seeds 0-4 and 5-9 run in two
    goes, read as one experiment of 10 seeds. config.json records `command` and the directories
    pooled. Raises ValueError (nothing written) when `out` holds a run directory that is not such
    a pool, or is one of `run_dirs`."""
    sources = [Path(d) for d in run_dirs]
    if any(out.resolve() == d.resolve() for d in sources):
        raise ValueError(f"--out {out} is one of the directories pooled; choose another")
    if (out / CONFIG_FILE).exists():
        if "pooled_from" not in json.loads((out / CONFIG_FILE).read_text()):
            raise ValueError(
                f"{out} holds a run directory, not a pool of runs; nothing was overwritten: "
                "choose another --out"
            )
    pooled = pool_runs(sources)
    out.mkdir(parents=True, exist_ok=True)
    config = dict(pooled.config, command=command, pooled_from=[str(d) for d in sources])
    (out / CONFIG_FILE).write_text(json.dumps(config, indent=2) + "\n")
    (out / RUNS_FILE).write_text(json.dumps(pooled.runs, indent=1) + "\n")
    save_npz(out / METRICS_FILE, pooled.metrics)
    return load_run(out)


def as_run(run: RunDir | str | Path) -> RunDir:
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


def evaluation_index(steps: Sequence[int], at: int) -> int:
    """The index of the evaluation at `at` env steps among `steps`; ValueError naming the
    evaluations there are when there is none at `at`."""
    hits = np.flatnonzero(np.asarray(steps) == at)
    if len(hits) == 0:
        raise ValueError(
            f"no evaluation at {at:,} env steps: there are evaluations at "
            f"{int(steps[0]):,}, {int(steps[1] if len(steps) > 1 else steps[0]):,}, ..., "
            f"{int(steps[-1]):,}"
        )
    return int(hits[0])


def read_at(run: RunDir, at: int) -> RunDir:
    """`run` as if it had stopped at its evaluation at `at` env steps: the period metrics up to
    that evaluation, so that its summary and comparisons read the return at `at` as the final
    return and the AUC up to `at` (the 100k and 200k readings of a 400k run). The state samples,
    drawn over the whole run, are dropped unless `at` is its last evaluation. ValueError naming
    the evaluations there are when there is none at `at`."""
    periods = evaluation_index(env_steps_axis(run), at) + 1
    if periods == run.periods:
        return run
    return dataclasses.replace(
        run,
        metrics=pool_metrics([run], periods),
        timing={},
        periods=periods,
        expected_periods=periods,
        partial=False,
    )


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


def group_members(group_dir: str | Path) -> list[Path]:
    """The member run directories of a `SweepGroup` output directory (its group.json), in order."""
    group_dir = Path(group_dir)
    path = group_dir / GROUP_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{group_dir} is not a group of runs (no group.json)")
    return [group_dir / name for name in json.loads(path.read_text())["members"]]
