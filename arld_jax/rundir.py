"""The run-directory and checkpoint format: what `arld_jax.driver` writes and reads back.

A run directory holds config.json (the run's identity, compared on resume), runs.json, metrics.npz
(per-run arrays, rewritten after every chunk), state_layout.json (a fingerprint of the checkpointed
state's leaves), checkpoints/ (orbax, the complete training state after each chunk), and when
complete timing.json, summary.md/csv and figures/ (`arld_jax.results`, `arld_jax.plots`, which read
it back as a typed `results.RunDir`). A group of runs (one per agent family) has group.json and one
such directory per member.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from arld_jax.config import Config

CHECKPOINT_DIR = "checkpoints"
METRICS_FILE = "metrics.npz"
LAYOUT_FILE = "state_layout.json"  # fingerprint of the checkpointed TrainState's tree and shapes
GROUP_FILE = "group.json"
"""In the output directory of a `SweepGroup`: its members' subdirectory names and the command."""
CONFIG_FILE = "config.json"
"""The run's identity: resolved config, swept fields, seeds (compared on resume), command, expert."""
_FIELDS = {f.name: f for f in dataclasses.fields(Config) if f.name != "notes"}


def check_or_write_identity(out: Path, identity: dict[str, Any]) -> bool:
    """Write config.json, or check it matches. Returns True if the directory already held this run."""
    path = out / CONFIG_FILE
    if path.exists():
        saved = json.loads(path.read_text())
        keys = ("config", "sweep", "seeds")
        old = {k: saved.get(k) for k in keys}
        new = json.loads(json.dumps({k: identity[k] for k in keys}))
        # A Config field added after the run was saved, at its default, is what the run had (new
        # fields keep the old behaviour at their default), so it does not block resuming.
        for f in set(new["config"]) - set(old["config"] or {}):
            if f in _FIELDS and new["config"][f] == json.loads(json.dumps(_FIELDS[f].default)):
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


def state_samples(state, num_runs: int) -> dict[str, np.ndarray]:  # noqa: ANN001
    out = {}
    for name in ("visited", "queried"):
        s = getattr(state, name)
        out[f"{name}_obs"] = np.asarray(s.obs)[:num_runs]
        out[f"{name}_env_step"] = np.asarray(s.env_step)[:num_runs]
        out[f"{name}_valid"] = np.asarray(s.key)[:num_runs] >= 0
    return out
