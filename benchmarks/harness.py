"""The benchmark's harness: timing loops, tables, the machine's description and the JSON report.

Every timing here waits for its result (`jax.block_until_ready`); `time_calls` makes one untimed
call first (it compiles), `time_rounds` takes calls already warmed up. `Bench` carries one run's
options, report and the measurements sections share, and runs a section so that a failure is
recorded, not fatal.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.metadata
import json
import math
import os
import platform
import shlex
import socket
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import jax

from arld_jax.compile import compiler_options

if TYPE_CHECKING:
    from benchmarks.programs import Sizes

REPO_ROOT = Path(__file__).resolve().parent.parent
"""The checkout; reports name files relative to it (`repo_path`)."""


RESULTS_DIR = REPO_ROOT / "benchmarks" / "results"


def log(msg: str = "") -> None:
    """Print and flush at once, so a long run shows its progress."""
    print(msg, flush=True)


def block(tree: Any) -> Any:
    """Wait for every array of `tree` (JAX dispatch is asynchronous)."""
    return jax.block_until_ready(tree)


def time_calls(fn: Callable[[], Any], repeats: int) -> list[float]:
    """Seconds of `repeats` calls of `fn` (each waited for), after one untimed warm-up call."""
    block(fn())
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        block(fn())
        times.append(time.perf_counter() - start)
    return times


def time_rounds(calls: dict[str, Callable[[], Any]], rounds: int) -> dict[str, list[float]]:
    """Seconds of each of `calls` (already warmed up), alternated: every round calls each once,
    starting one call later than the round before, so the VM's drift touches them alike and no
    call always runs first."""
    names = list(calls)
    times: dict[str, list[float]] = {name: [] for name in names}
    for r in range(rounds):
        for name in names[r % len(names) :] + names[: r % len(names)]:
            start = time.perf_counter()
            block(calls[name]())
            times[name].append(time.perf_counter() - start)
    return times


def summarize(times: Sequence[float]) -> dict[str, Any]:
    """Median and best of a list of timings."""
    return {"median_s": statistics.median(times), "min_s": min(times), "all_s": list(times)}


def print_table(title: str, header: Sequence[str], rows: Sequence[Sequence[Any]]) -> None:
    """A plain aligned text table."""
    cells = [[str(h) for h in header]] + [[_fmt(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    line = "  ".join("-" * w for w in widths)
    log(f"\n== {title}")
    for i, r in enumerate(cells):
        log(
            "  ".join(
                c.rjust(w) if j else c.ljust(w)
                for j, (c, w) in enumerate(zip(r, widths, strict=True))
            )
        )
        if i == 0:
            log(line)


def _fmt(x: Any) -> str:
    if isinstance(x, float):
        if math.isnan(x):
            return "n/a"
        return f"{x:,.3g}" if abs(x) < 100 else f"{x:,.0f}"
    if isinstance(x, int):
        return f"{x:,}"
    return str(x)


@dataclass
class Bench:
    """The run's options, its JSON report, its sections and measurements shared between them."""

    args: argparse.Namespace
    sizes: Sizes
    out: Path
    report: dict[str, Any]
    section_funcs: dict[str, Callable[[Bench], dict]]  # name -> section, in the order they run
    memo: dict[Any, Any] = field(default_factory=dict)

    @property
    def toy_trainer(self) -> bool:
        """The trainer sections use the toy env (--quick or --skip-mjx)."""
        return self.args.quick or self.args.skip_mjx

    def save(self) -> None:
        """Rewrite the JSON report atomically."""
        self.out.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.out.with_suffix(".tmp")
        tmp.write_text(json.dumps(self.report, indent=2, default=_json_default) + "\n")
        os.replace(tmp, self.out)

    def run_section(self, name: str) -> None:
        """Run one section, record its result and wall time, and rewrite the JSON report."""
        log(f"\n>>> {name} ...")
        start = time.perf_counter()
        try:
            result = self.section_funcs[name](self)
        except Exception as err:  # keep the other sections' figures
            log(f"!!! section {name} failed: {type(err).__name__}: {err}")
            result = {"error": f"{type(err).__name__}: {err}"}
        result["section_wall_s"] = time.perf_counter() - start
        self.report["sections"][name] = result
        self.save()
        log(f"<<< {name} done in {result['section_wall_s']:.1f} s (saved {self.out})")


def _json_default(x: Any) -> Any:
    if hasattr(x, "item"):
        return x.item()
    return str(x)


PACKAGES = ("jax", "jaxlib", "brax", "mujoco", "mujoco-mjx", "flax", "optax", "numpy")
"""The packages whose versions a report records."""


def package_versions(packages: Sequence[str] = PACKAGES) -> dict[str, str | None]:
    """The installed version of each package (None where it is not installed)."""
    found: dict[str, str | None] = {}
    for pkg in packages:
        try:
            found[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            found[pkg] = None
    return found


def machine_info(args: argparse.Namespace) -> dict[str, Any]:
    """Versions, CPU model and flags, core count, date, load and the command (as run from the
    repository root, without this machine's interpreter path)."""
    versions = package_versions()
    cpuinfo = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    model = next(
        (ln.split(":", 1)[1].strip() for ln in cpuinfo.splitlines() if "model name" in ln), ""
    )
    flags_line = next(
        (ln.split(":", 1)[1] for ln in cpuinfo.splitlines() if ln.startswith("flags")), ""
    )
    wanted = ("avx2", "fma", "avx512f", "avx512_bf16", "avx512_vnni", "amx_bf16", "amx_tile")
    return {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "hostname": socket.gethostname(),
        "command": shlex.join(["python", "-m", "benchmarks.bench", *sys.argv[1:]]),
        "mode": "quick" if args.quick else "full",
        "skip_mjx": args.skip_mjx,
        "versions": versions,
        "python": platform.python_version(),
        "cpu_model": model or platform.processor(),
        "cpu_flags": [f for f in wanted if f in flags_line.split()],
        "cpu_count": os.cpu_count(),
        "cpus_usable": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "devices": [str(d) for d in jax.devices()],
        "load_average_at_start": list(os.getloadavg()),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "compiler_options": compiler_options(),  # given to every timed program's jax.jit
        "persistent_cache_dir_in_parent": jax.config.jax_compilation_cache_dir,
    }


def mem_total_bytes() -> int | None:
    """MemTotal of /proc/meminfo, if there is one."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def repo_path(path: Path) -> str:
    """`path` relative to the repository when it lies inside it, else as given: what a report
    records, so that it reads the same off this machine."""
    try:
        return str(Path(path).resolve().relative_to(REPO_ROOT))
    except ValueError:
        return str(path)
