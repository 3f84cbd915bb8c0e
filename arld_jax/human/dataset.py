"""The demonstration dataset: every step a person demonstrates, saved as it happens.

Format: JSON lines (`demonstrations.jsonl` in the run directory), append-only, one line per
demonstrated env step, flushed and fsync'ed before the action goes back to the training loop, so a
crash or `kill -9` loses nothing that entered the replay. The first line is a header naming the
format, the env and its dimensions. A record holds the state (observation), the action the person
gave (or, after a hand-back, the agent's action that was executed instead), the agent's proposed
action, its uncertainty u(s), wall times (when the step was shown, when it was answered), the query
index, step k of C, the env step, and the budget spent.

Why not Farama's `minari`: its `DataCollector` wraps a Gymnasium env (ours is a JAX function inside
a compiled scan) and keeps episodes in memory until `add_to_dataset`/`create_dataset` writes them
to HDF5, so it cannot flush each step as it happens; it would also add gymnasium and h5py to the
dependencies. JSON lines are append-only by nature, readable without this package, and a
half-written last line (a crash mid-write) is detected and ignored on reading.
"""

from __future__ import annotations

import json
import os
import threading
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

FORMAT = "arld_jax.demonstrations/1"
DATASET_FILE = "demonstrations.jsonl"

PERSON = "person"
"""`source` of a step the person demonstrated."""
HANDED_BACK = "handed_back"
"""`source` of a step of a query the person handed back: the agent's action was executed (the loop
had reserved the step as a demonstration; see `arld_jax.human` on hand-back)."""


@dataclass(frozen=True)
class DemoRecord:
    """One demonstrated env step (one line of the dataset)."""

    query: int  # index of the query (a run of C demonstrated steps), 0, 1, ... over the whole run
    k: int  # step k of c within the query (1-based)
    c: int  # length of the query's run: min(C, steps left in the episode, budget left)
    env: int  # env index within the run
    env_step: int  # env steps done before this iteration (the loop's `it * num_envs`)
    obs: list[float]  # the state the person saw
    action: list[float]  # the executed action (the person's, or the agent's after a hand-back)
    agent_action: list[float]  # what the agent proposed
    uncertainty: float  # the agent's u(s)
    demos_used: int  # budget spent, this step included
    budget: int
    source: str  # PERSON or HANDED_BACK
    shown_at: float  # unix time the step was shown (or the run reached it)
    answered_at: float  # unix time the action was given

    @property
    def key(self) -> tuple[int, int]:
        """(env_step, env): where the step happens in the run; unique per run."""
        return (self.env_step, self.env)


def _to_json_line(obj: dict[str, Any]) -> str:
    # allow_nan=False: a NaN must never reach the dataset (it is refused before).
    return json.dumps(obj, allow_nan=False, separators=(",", ":")) + "\n"


class DemoDataset:
    """Append-only writer (thread-safe) and the records already on disk.

    Opening an existing file reads it (a resumed run keeps its demonstrations); its header must
    match the env's, or ValueError."""

    def __init__(self, path: str | Path, header: dict[str, Any]) -> None:
        self.path = Path(path)
        self.header = {"kind": "header", "format": FORMAT} | header
        self._lock = threading.Lock()
        self.records: list[DemoRecord] = []
        if self.path.exists() and self.path.stat().st_size > 0:
            saved_header, self.records = read_dataset(self.path)
            for name in ("env_name", "obs_dim", "action_dim"):
                if saved_header.get(name) != self.header.get(name):
                    raise ValueError(
                        f"{self.path} holds demonstrations for {name}={saved_header.get(name)!r}, "
                        f"but this run has {name}={self.header.get(name)!r}: use another run "
                        "directory (--out)."
                    )
            self._truncate_partial_line()
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._append(self.header)

    def _truncate_partial_line(self) -> None:
        """Drop a half-written last line (a crash mid-write) so appends start on a fresh line."""
        data = self.path.read_bytes()
        if data and not data.endswith(b"\n"):
            with open(self.path, "r+b") as f:
                f.truncate(data.rfind(b"\n") + 1)

    def _append(self, obj: dict[str, Any]) -> None:
        line = _to_json_line(obj)
        with self._lock, open(self.path, "a", encoding="utf-8") as f:
            f.write(line)
            f.flush()
            os.fsync(f.fileno())

    def append(self, record: DemoRecord) -> None:
        """Write one record to disk (flushed and fsync'ed) and keep it in `records`."""
        self._append({"kind": "demo"} | asdict(record))
        with self._lock:
            self.records.append(record)


def read_dataset(path: str | Path) -> tuple[dict[str, Any], list[DemoRecord]]:
    """The header and the records of a dataset file. A half-written LAST line is ignored (a crash
    while writing it); any other unreadable line raises ValueError naming the line."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(
            f"No demonstration dataset at {path}: it is written by `python -m arld_jax.human` "
            f"as {DATASET_FILE} in the run directory."
        )
    lines = path.read_text(encoding="utf-8").split("\n")
    complete, last = lines[:-1], lines[-1]  # `last` is "" when the file ends with a newline
    header: dict[str, Any] | None = None
    records: list[DemoRecord] = []
    for number, line in enumerate(complete, start=1):
        if not line.strip():
            continue
        try:
            obj = json.loads(line)
        except json.JSONDecodeError as err:
            raise ValueError(f"{path}:{number} is not valid JSON ({err})") from None
        if obj.get("kind") == "header":
            if obj.get("format") != FORMAT:
                raise ValueError(f"{path}: format {obj.get('format')!r}, expected {FORMAT!r}")
            header = obj
        elif obj.get("kind") == "demo":
            obj.pop("kind")
            records.append(DemoRecord(**obj))
    del last  # a partial line: written by a process that died mid-write
    if header is None:
        raise ValueError(f"{path} has no header line (format {FORMAT})")
    return header, records


def latest_by_key(records: Iterable[DemoRecord]) -> dict[tuple[int, int], DemoRecord]:
    """The last record at each (env_step, env): a step asked again after a divergence supersedes
    the earlier answer (the file stays append-only)."""
    return {r.key: r for r in records}


def person_pairs(records: Iterable[DemoRecord]) -> tuple[np.ndarray, np.ndarray]:
    """(obs [N, obs_dim], action [N, A]) of the steps the person demonstrated (hand-backs and
    superseded answers left out): the data a recorded expert is cloned from."""
    kept = [r for r in latest_by_key(records).values() if r.source == PERSON]
    if not kept:
        return np.zeros((0, 0), np.float32), np.zeros((0, 0), np.float32)
    obs = np.asarray([r.obs for r in kept], np.float32)
    action = np.asarray([r.action for r in kept], np.float32)
    return obs, action
