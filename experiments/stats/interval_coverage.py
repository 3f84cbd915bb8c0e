"""How often do `compare`'s two 95% intervals of a difference of means exclude 0 when there is no
difference? Two samples of n seeds are drawn from the same distribution, many times; each pair goes
through `stats.bootstrap_difference` (the stratified percentile bootstrap of rliable, as `compare`
calls it: 20,000 resamples) and `stats.welch_ci95`.
A calibrated 95% interval excludes 0 in about 5% of the pairs.

    python experiments/stats/interval_coverage.py > experiments/stats/interval_coverage.md
"""

from __future__ import annotations

import math
import sys

import numpy as np

from arld_jax import stats
from arld_jax.stats import BOOTSTRAP_REPS as REPS

SIMS = 1000
DRAWS = {
    "normal": lambda rng, n: rng.normal(size=n),
    # skewed, like returns where a few seeds fail: lognormal with sigma 1
    "lognormal": lambda rng, n: rng.lognormal(sigma=1.0, size=n),
}
CASES = [("normal", 5), ("normal", 10), ("lognormal", 5)]


def main() -> None:
    print("# Do the 95% intervals of `compare` hold their level with few seeds?\n")
    print(f"Command: `python {' '.join(sys.argv)} > experiments/stats/interval_coverage.md`.\n")
    print(f"Two samples of n seeds drawn from one distribution, {SIMS:,} times per row (numpy seed "
          f"0); each pair through `stats.bootstrap_difference` (the stratified percentile bootstrap "
          f"of rliable, as `compare` calls it, {REPS:,} resamples) and "
          "`stats.welch_ci95`. With no difference, a calibrated 95% interval excludes 0 in "
          "about 5% of the pairs.\n")  # fmt: skip
    print("| draws | seeds per side | bootstrap CI excludes 0 | Welch t CI excludes 0 |")
    print("|---|---:|---:|---:|")
    rng = np.random.default_rng(0)
    for name, n in CASES:
        boot = welch = 0
        for i in range(SIMS):
            x, y = DRAWS[name](rng, n), DRAWS[name](rng, n)
            row = stats.bootstrap_difference(x, y, reps=REPS, seed=i)
            boot += not (row["diff_lo"] <= 0.0 <= row["diff_hi"])
            welch += not (row["welch_lo"] <= 0.0 <= row["welch_hi"])
        # binomial standard error of a proportion near 5-12%: about 0.7-1.0 points at 1,000 pairs
        se = lambda k: 100 * math.sqrt(k / SIMS * (1 - k / SIMS) / SIMS)  # noqa: E731
        print(f"| {name} | {n} | {100 * boot / SIMS:.1f}% ± {se(boot):.1f} "
              f"| {100 * welch / SIMS:.1f}% ± {se(welch):.1f} |", flush=True)  # fmt: skip
    print("\n(± one binomial standard error.)")


if __name__ == "__main__":
    main()
