"""Throughput, scaling and memory benchmark of arld_jax on this machine (CPU).

    python -m benchmarks.bench                    # everything (about an hour on 2 cores)
    python -m benchmarks.bench --quick            # tiny sizes, toy env for the trainer: smoke test
    python -m benchmarks.bench --only matmul,flops,update --skip-mjx

Sections, in the order they run (benchmarks/README.md says what each figure means):

    matmul      f32 and bf16-input matmul GFLOP/s at 256-wide shapes: the machine's ceiling
    flops       FLOPs of one SAC update (XLA cost analysis and an analytic count) -> updates/s limit
    env         env-only env steps/s with random actions (MJX HalfCheetah, 1 and 16 envs)
    update      update-only updates/s at B=256 on a fixed batch (f32 and bf16 matmul inputs)
    trainer     the full trainer (1 env; 16 envs), with a breakdown of where a period's time goes
    overlap     the trainer with update_before_add (updates may overlap the env step) vs default
    seeds       total updates/s of 1, 2, 4, 8 vmapped seeds against one seed run N times
    first_step  cold and warm (persistent compilation cache) time to the first training chunk
    memory      replay and TrainState bytes per seed at replay capacity 1M
    peers       Brax's own SAC trainer (separate venv, jax 0.9.2) vs arld_jax's, same configs

Every section prints a table as soon as it finishes, and the JSON report
(benchmarks/results/<host>-<date>.json) is rewritten after each one, so a killed run keeps what it
measured. Timings are wall-clock around `block_until_ready`, after a warm-up call that compiles.
This process does NOT use the persistent compilation cache, so its compile times are real; only the
`first_step` children do, each with its own fresh cache directory.

This module is the driver: arguments, the sections' order and the loop over them. The harness
(timing, tables, report) is `harness.py`, the timed programs `programs.py`, the FLOP counts
`flops.py`, the sections `sections.py` and `peers/section.py`, the closing table `summary.py`.
"""

from __future__ import annotations

import argparse
import datetime
import os
import socket
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from benchmarks import sections
from benchmarks.harness import RESULTS_DIR, Bench, log, machine_info
from benchmarks.peers.section import section_peers
from benchmarks.programs import FULL, QUICK
from benchmarks.summary import print_summary

SECTION_FUNCS: dict[str, Callable[[Bench], dict]] = {
    "matmul": sections.section_matmul,
    "flops": sections.section_flops,
    "env": sections.section_env,
    "update": sections.section_update,
    "trainer": sections.section_trainer,
    "overlap": sections.section_overlap,
    "replay": sections.section_replay,
    "seeds": sections.section_seeds,
    "first_step": sections.section_first_step,
    "memory": sections.section_memory,
    "peers": section_peers,
}
"""Every section, in the order a run takes them."""
SECTIONS: tuple[str, ...] = tuple(SECTION_FUNCS)


def default_out(quick: bool) -> Path:
    """benchmarks/results/<host or 'cpu'>-<date>[-quick].json"""
    host = socket.gethostname() or "cpu"
    date = datetime.date.today().isoformat()
    return RESULTS_DIR / f"{host}-{date}{'-quick' if quick else ''}.json"


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    """The benchmark's options (module docstring); `--only` names must be sections."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="tiny sizes; toy env for the trainer")
    parser.add_argument("--skip-mjx", action="store_true", help="toy env everywhere, no MJX")
    parser.add_argument("--out", type=Path, default=None, help="JSON report path")
    parser.add_argument(
        "--only", default=None, help=f"comma-separated sections: {', '.join(SECTIONS)}"
    )
    parser.add_argument("--first-step-child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--cache-dir", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.only:
        unknown = set(args.only.split(",")) - set(SECTIONS)
        if unknown:
            parser.error(f"unknown section(s) {sorted(unknown)}; choose from {', '.join(SECTIONS)}")
    return args


def main(argv: Sequence[str] | None = None) -> None:
    """Run the selected sections in order, saving the report after each, then the summary."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    if args.first_step_child:
        sections.first_step_child(args)
        return
    selected = [s for s in SECTIONS if not args.only or s in args.only.split(",")]
    b = Bench(
        args=args,
        sizes=QUICK if args.quick else FULL,
        out=args.out or default_out(args.quick),
        report={"meta": machine_info(args), "sections": {}},
        section_funcs=SECTION_FUNCS,
    )
    meta = b.report["meta"]
    log(f"arld_jax benchmark ({meta['mode']}): {meta['cpu_model']}, {meta['cpu_count']} cores")
    log(f"jax {meta['versions']['jax']}, brax {meta['versions']['brax']}; report: {b.out}")
    load = meta["load_average_at_start"][0]
    if load > 0.5 * (meta["cpus_usable"] or 1):
        log(f"WARNING: load average {load:.1f} at start: the machine is busy, figures will be low")
    start = time.perf_counter()
    for name in selected:
        if name not in b.report["sections"]:  # matmul may have run already as a dependency
            b.run_section(name)
    meta["load_average_at_end"] = list(os.getloadavg())
    meta["total_wall_s"] = time.perf_counter() - start
    b.save()
    print_summary(b.report["sections"])
    log(f"\ndone in {meta['total_wall_s']:.0f} s; report written to {b.out}")


if __name__ == "__main__":
    main()
