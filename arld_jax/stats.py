"""Statistics over seeds: 95% intervals of a mean (Student's t), of a difference of means (Welch's t
and the stratified bootstrap of rliable, vectorised), the interquartile mean with its bootstrap
interval, the probability of improvement, and the area under a curve.

Numpy and scipy only (rliable, the field's reference, checks them in the tests); the run
directories' layout is `arld_jax.rundir`'s.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
from scipy import stats


def mean_ci95(values: np.ndarray) -> tuple[float, float]:
    """Mean and half-width of the 95% confidence interval of the mean.

    NaNs are dropped first. The half-width is ``t.ppf(0.975, n - 1) * sd / sqrt(n)`` with the sample
    standard deviation (ddof=1) and Student's t with n - 1 degrees of freedom. One value gives a
    half-width of nan (no spread to estimate); no values give ``(nan, nan)``.
    """
    x = np.asarray(values, dtype=np.float64).ravel()
    x = x[~np.isnan(x)]
    n = x.size
    if n == 0:
        return math.nan, math.nan
    mean = float(x.mean())
    if n == 1:
        return mean, math.nan
    sd = float(x.std(ddof=1))
    return mean, float(stats.t.ppf(0.975, n - 1) * sd / math.sqrt(n))


def mean_ci95_columns(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`mean_ci95` of every column of ``values`` [n, m] (e.g. runs x periods), NaNs dropped.

    Returns ``(mean [m], half_width [m])``; a column with one finite value has half-width nan, a
    column with none has mean nan too.
    """
    x = np.asarray(values, dtype=np.float64)
    if x.ndim != 2:
        raise ValueError(f"values must be 2-D [n, m], got shape {x.shape}")
    finite = ~np.isnan(x)
    n = finite.sum(axis=0)
    with warnings.catch_warnings(), np.errstate(invalid="ignore", divide="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nanmean(x, axis=0)
        sd = np.nanstd(x, axis=0, ddof=1)
        t = stats.t.ppf(0.975, np.maximum(n - 1, 1))
        half = t * sd / np.sqrt(n)
    half = np.where(n >= 2, half, np.nan)
    mean = np.where(n >= 1, mean, np.nan)
    return mean, half


def welch_ci95(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """95% confidence interval of mean(x) - mean(y), Welch's t (unequal variances): half-width
    ``t.ppf(0.975, df) * se`` with ``se**2 = s_x**2 / n_x + s_y**2 / n_y`` (ddof=1) and the
    Welch-Satterthwaite ``df``. Needs two values per side (else ``(nan, nan)``); two constant
    samples give the point ``(d, d)``.

    Why it sits beside the bootstrap intervals of `compare_runs`: with 5 seeds per side the
    percentile bootstrap interval of a difference is narrower than 95% (it resamples with the
    plug-in variance and normal-like quantiles): with no difference it excluded 0 in 12.4% of
    simulated normal pairs and 13.6% of skewed (lognormal) ones, Welch's in 4.8% and 2.3%
    (`experiments/stats/interval_coverage.md`, which has the command)."""
    x = np.asarray(x, np.float64).ravel()
    y = np.asarray(y, np.float64).ravel()
    n, m = x.size, y.size
    if n < 2 or m < 2:
        return math.nan, math.nan
    diff = float(x.mean() - y.mean())
    vx, vy = x.var(ddof=1) / n, y.var(ddof=1) / m
    se2 = vx + vy
    if se2 == 0.0:
        return diff, diff
    df = se2**2 / (vx**2 / (n - 1) + vy**2 / (m - 1))
    half = float(stats.t.ppf(0.975, df) * math.sqrt(se2))
    return diff - half, diff + half


LATE_SHARE = 0.1
"""The late return is each run's mean evaluation return over the last tenth of its evaluations
present: one evaluation of a few deterministic episodes swings with the policy from one
evaluation to the next, a mean over the last eight (of a 400k run evaluated every 5k) less so."""


def late_window(num_evaluations: int) -> int:
    """How many of the last evaluations the late return averages (`LATE_SHARE` of them, rounded);
    0 where that is fewer than two, and the late return would be the final return."""
    k = round(LATE_SHARE * num_evaluations)
    return k if k >= 2 else 0


def late_return(eval_return: np.ndarray) -> np.ndarray:
    """[R] each run's mean of its last `late_window` evaluations of [R, E] `eval_return`; nan
    where there is no late window (fewer than 20 evaluations)."""
    k = late_window(eval_return.shape[1])
    if not k:
        return np.full(eval_return.shape[0], np.nan)
    return eval_return[:, -k:].mean(axis=1)


def area_under_curve(eval_return: np.ndarray, env_steps: np.ndarray) -> np.ndarray:
    """Normalised area under each run's evaluation curve: its mean evaluation return.

    Definition: ``auc[r] = mean_p eval_return[r, p]``, the simple average of the evaluation returns
    over the P evaluation points (no trapezoid). With evaluations every ``eval_every`` env steps
    this is the area under the step curve that holds each evaluation for its period, divided by the
    length of the run, so it has the units of a return and is comparable between runs of different
    lengths (and between a partial run and a finished one, as "the average return so far"). A NaN
    evaluation makes that run's AUC NaN (and `mean_ci95` then leaves that run out).

    Args:
        eval_return: [R, P] evaluation returns.
        env_steps: [P] (or [R, P]) env steps of the evaluations; only checked against P, since the
            evaluations are equally spaced.

    Returns:
        [R] AUC per run.
    """
    ret = np.asarray(eval_return, dtype=np.float64)
    steps = np.asarray(env_steps)
    if ret.ndim != 2:
        raise ValueError(f"eval_return must be [runs, periods], got shape {ret.shape}")
    if steps.shape[-1] != ret.shape[1]:
        raise ValueError(
            f"env_steps has {steps.shape[-1]} evaluation points but eval_return has {ret.shape[1]}"
        )
    if ret.shape[1] == 0:
        return np.full(ret.shape[0], np.nan)
    return ret.mean(axis=1)


def probability_of_improvement(x: np.ndarray, y: np.ndarray) -> Any:
    """P(X > Y) + P(X = Y) / 2 over all pairs of a run of x and a run of y: rliable's
    `metrics.probability_of_improvement` for one task (its Mann-Whitney U / (n m); tested equal).
    Runs on the last axis, so one call scores every bootstrap resample ([reps, n] against
    [reps, m] gives [reps]); 1-D samples give a float."""
    x, y = np.asarray(x, np.float64)[..., :, None], np.asarray(y, np.float64)[..., None, :]
    p = np.mean(x > y, axis=(-2, -1)) + 0.5 * np.mean(x == y, axis=(-2, -1))
    return float(p) if p.ndim == 0 else p


BOOTSTRAP_REPS = 20_000
"""Resamples of the seeds behind every bootstrap interval `compare` and `compare_runs` give."""

PERCENTILES_95 = (2.5, 97.5)
"""The ends of a 95% percentile-bootstrap interval (rliable's default method, through arch)."""


def resamples(x: np.ndarray, reps: int, rng: np.random.Generator) -> np.ndarray:
    """`reps` resamples of the runs `x` [n] with replacement, [reps, n]: one stratum of rliable's
    stratified bootstrap (each side of a comparison is resampled apart)."""
    return x[rng.integers(0, x.size, (reps, x.size))]


def iqm(values: np.ndarray) -> float:
    """The interquartile mean: the mean of the runs left after cutting 25% at each end (rliable's
    `metrics.aggregate_iqm` for one task, Agarwal et al. 2021; 5 runs: the middle 3). NaNs dropped."""
    x = np.asarray(values, np.float64).ravel()
    x = x[~np.isnan(x)]
    return float(stats.trim_mean(x, 0.25)) if x.size else math.nan


def iqm_ci95(
    values: np.ndarray, reps: int = BOOTSTRAP_REPS, seed: int = 0
) -> tuple[float, float, float]:
    """`iqm` and its 95% percentile-bootstrap interval (the runs resampled with replacement `reps`
    times, numpy seed `seed`): rliable's `get_interval_estimates` of `aggregate_iqm` for one task,
    vectorised, because a summary asks it of every cell (tested to agree with rliable). Fewer than
    two runs: (iqm, nan, nan)."""
    x = np.asarray(values, np.float64).ravel()
    x = x[~np.isnan(x)]
    if x.size < 2:
        return iqm(x), math.nan, math.nan
    n, cut = x.size, int(0.25 * x.size)  # scipy's trim_mean cuts int(0.25 n) at each end
    samples = np.sort(resamples(x, reps, np.random.default_rng(seed)), axis=1)
    boot = samples[:, cut : n - cut].mean(axis=1)
    lo, hi = np.percentile(boot, PERCENTILES_95)
    return iqm(x), float(lo), float(hi)


def bootstrap_difference(x: np.ndarray, y: np.ndarray, reps: int, seed: int) -> dict[str, Any]:
    """mean(x) - mean(y) and P(a run of x > a run of y), each with its 95% stratified-bootstrap CI
    (rliable's `get_interval_estimates`, Agarwal et al. 2021: x and y resampled separately with
    replacement, `reps` times, numpy seed `seed`; percentile interval), vectorised, because every
    pair and reading of a comparison asks it: rliable's resampling loop took about 4 s a call here,
    this takes milliseconds (tested to agree with rliable). Also Welch's t interval of the
    difference (`welch_ci95`), better calibrated with few seeds.
    Keys: diff, diff_lo, diff_hi, welch_lo, welch_hi, p_improve, p_lo, p_hi, n_a, n_b."""
    x = np.asarray(x, np.float64).ravel()
    y = np.asarray(y, np.float64).ravel()
    rng = np.random.default_rng(seed)
    xs, ys = resamples(x, reps, rng), resamples(y, reps, rng)  # [reps, n_a], [reps, n_b]
    diffs = xs.mean(axis=1) - ys.mean(axis=1)
    boot = np.stack([diffs, probability_of_improvement(xs, ys)])
    (diff_lo, diff_hi), (p_lo, p_hi) = np.percentile(boot, PERCENTILES_95, axis=1).T
    welch_lo, welch_hi = welch_ci95(x, y)
    return dict(diff=float(x.mean() - y.mean()), diff_lo=float(diff_lo), diff_hi=float(diff_hi),
                welch_lo=welch_lo, welch_hi=welch_hi,
                p_improve=probability_of_improvement(x, y), p_lo=float(p_lo), p_hi=float(p_hi),
                n_a=len(x), n_b=len(y))  # fmt: skip
