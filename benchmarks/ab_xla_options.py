"""A/B of XLA compiler options on the update alone, interleaved in one process.

    python -m benchmarks.ab_xla_options xla_cpu_prefer_vector_width=512 \\
        xla_cpu_experimental_ynn_fusion_type=LIBRARY_FUSION_TYPE_DOT

Each argument `name=value` is one variant: the benchmark's update-alone program (`programs.update_call`,
B 256, 2x256, HalfCheetah's shapes) compiled with `compile.compiler_options()` plus that option, beside
the baseline with `compile.compiler_options()` alone. All variants are compiled first, then their calls
alternate for `--rounds` rounds, each round starting one variant later, so the VM's drift
(benchmarks/README.md) touches every variant alike. Printed per variant: whether XLA optimized the
update to the same HLO as the baseline's (header line aside; an option can still change the machine
code, as the vector width does, and a variant that changes nothing still times differently, which
shows the A/B's noise), whether the critic losses of its first call are bit-identical to the
baseline's, its median updates/s and its ratio to the baseline (above 1: faster). Values
`true`/`false` are booleans, digits integers, anything else a string (enum options take the proto's
names, as above).
"""

from __future__ import annotations

import argparse
import statistics

import numpy as np

from benchmarks.harness import time_rounds
from benchmarks.programs import HC_ACTION_DIM, HC_OBS_DIM, PAPER_UPDATE, update_call


def parse_option(text: str) -> tuple[str, bool | int | str]:
    """'name=value' -> (name, value as bool, int or str)."""
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"expected name=value, got {text!r}")
    if value in ("true", "false"):
        return name, value == "true"
    return name, int(value) if value.isdigit() else value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("options", nargs="+", type=parse_option, help="name=value, one per variant")
    parser.add_argument("--rounds", type=int, default=8, help="timed calls per variant")
    parser.add_argument("--updates", type=int, default=100, help="scanned updates per call")
    args = parser.parse_args()

    cfg = PAPER_UPDATE
    variants = {"baseline": {}} | {f"{k}={v}": {k: v} for k, v in args.options}
    calls, compiled = {}, {}
    for name, option in variants.items():
        try:
            calls[name], compiled[name] = update_call(
                cfg, HC_OBS_DIM, HC_ACTION_DIM, args.updates, extra_options=option
            )
        except Exception as e:  # noqa: BLE001 (an unknown option or value: report it, go on)
            print(f"{name}: not compiled: {str(e).splitlines()[0][:200]}")
    body = lambda fn: fn.as_text().splitlines()[1:]  # the optimized HLO, without its header line
    same_hlo = {name: body(fn) == body(compiled["baseline"]) for name, fn in compiled.items()}
    first = {name: np.asarray(call()) for name, call in calls.items()}  # from the same start
    identical = {name: np.array_equal(losses, first["baseline"]) for name, losses in first.items()}
    times = time_rounds({name: calls[name] for name in compiled}, args.rounds)
    base = statistics.median(times["baseline"])
    width = max(len(name) for name in times)
    head = f"{'variant':{width}s}  {'same HLO':>8s}  {'bit-identical':>13s}"
    print(f"{head}  {'updates/s':>9s}  {'vs baseline':>11s}")
    for name, ts in times.items():
        median = statistics.median(ts)
        rate, ratio = args.updates / median, base / median
        row = f"{name:{width}s}  {same_hlo[name]!s:>8s}  {identical[name]!s:>13s}"
        print(f"{row}  {rate:9.1f}  {ratio:11.3f}")


if __name__ == "__main__":
    main()
