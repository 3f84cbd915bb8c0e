"""arld_jax's plain SAC against sbx's SAC (the JSONs `sbx_sac.py` writes), at the same env steps.

    python -m benchmarks.peers.vs_sbx experiments/expert_walker2d/training \\
        experiments/sac_300k_peers/sbx-Walker2d-v5-seed{0,1,2,3,4}.json \\
        --at 100000,200000,300000 --out experiments/sac_300k_peers/vs_sbx-Walker2d-v5.md

Ours: one cell of a run directory, or of several pooled (comma-separated, as `summary` and
`compare` take them; `arld_jax.rundir.pool_runs`). sbx: one finished JSON per seed, all of one
env with the same evaluation steps. A seed's evaluation is the mean of its deterministic episodes
on both sides. Each reading gives both sides' mean ± 95% half-width over seeds and Welch's 95%
interval of ours − sbx (`arld_jax.stats.welch_ci95`, how the project reads a difference between
two runs): the return at each `--at`, and over the evaluations both sides have (a shorter run is
read against the same stretch of the longer one) the late return (`stats.late_return`, their last
tenth) and the AUC (mean return).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from arld_jax import rundir, stats


@dataclasses.dataclass(frozen=True)
class Curves:
    """Evaluation curves of one learner's seeds: returns[r, p] at env steps steps[p]."""

    name: str
    seeds: list[Any]
    steps: np.ndarray  # [P] int
    returns: np.ndarray  # [R, P] mean return of each evaluation's episodes


def load_sbx(paths: Sequence[str | Path]) -> Curves:
    """sbx's seeds from their JSONs. ValueError naming the file when one is unfinished
    ("complete": false), when the files differ in env or evaluation steps, or when a seed is
    given twice; FileNotFoundError when one is missing."""
    if not paths:
        raise ValueError("give at least one sbx JSON (written by benchmarks/peers/sbx_sac.py)")
    reports = []
    for path in map(Path, paths):
        if not path.is_file():
            raise FileNotFoundError(f"sbx JSON {path} does not exist")
        report = json.loads(path.read_text())
        if not report.get("complete"):
            last = (report.get("eval_env_steps") or [0])[-1]
            raise ValueError(
                f"{path} is unfinished (its last evaluation at {last:,} of {report.get('steps', 0):,} "
                "env steps); only finished sbx runs are read"
            )
        reports.append((path, report))
    first_path, first = reports[0]
    seeds: list[Any] = []
    for path, report in reports:
        for key in ("env", "eval_env_steps"):
            if report[key] != first[key]:
                raise ValueError(
                    f"{path} and {first_path} differ in {key} ({report[key]!r} against "
                    f"{first[key]!r}); give the JSONs of one env and evaluation schedule"
                )
        if report["seed"] in seeds:
            raise ValueError(f"{path}: seed {report['seed']} is given twice")
        seeds.append(report["seed"])
    returns = np.array([[np.mean(ep) for ep in r["eval_returns"]] for _, r in reports], np.float64)
    return Curves(
        f"sbx {first['env']}", seeds, np.asarray(first["eval_env_steps"], np.int64), returns
    )


def load_ours(run_dirs: Sequence[str | Path]) -> Curves:
    """Our seeds from run directories (pooled when several). ValueError when they hold more than
    one cell: the peer is compared with one configuration of ours."""
    run = rundir.pool_runs(run_dirs)
    cells = rundir.group_cells(run)
    if len(cells) != 1:
        labels = ", ".join(repr(c.cell_label) for c in cells)
        raise ValueError(f"{run.where} holds {len(cells)} cells ({labels}); give a run of one cell")
    returns = np.asarray(run.metrics["eval_return"], np.float64)[cells[0].runs]
    return Curves(f"ours ({run.where})", cells[0].seeds, rundir.env_steps_axis(run), returns)


def reading(name: str, ours: np.ndarray, peer: np.ndarray) -> dict[str, Any]:
    """One row: both sides' mean ± 95% half-width and Welch's 95% interval of ours − peer."""
    ours_mean, ours_ci = stats.mean_ci95(ours)
    peer_mean, peer_ci = stats.mean_ci95(peer)
    lo, hi = stats.welch_ci95(ours, peer)
    return {
        "reading": name,
        "ours_mean": ours_mean,
        "ours_ci95": ours_ci,
        "peer_mean": peer_mean,
        "peer_ci95": peer_ci,
        "difference": ours_mean - peer_mean,
        "welch_lo": lo,
        "welch_hi": hi,
        "separated": bool(lo > 0 or hi < 0),
    }


def readings(ours: Curves, peer: Curves, at: Sequence[int]) -> list[dict[str, Any]]:
    """The return at each of `at` (an evaluation both sides have; ValueError naming those there
    are otherwise), then the late return (where they have 20 or more; `stats.late_window`) and the
    AUC over the evaluations both sides have, so that a shorter run is read against the same
    stretch of the longer one."""
    rows = [
        reading(
            f"return at {step:,}",
            ours.returns[:, rundir.evaluation_index(ours.steps, step)],
            peer.returns[:, rundir.evaluation_index(peer.steps, step)],
        )
        for step in at
    ]
    common = np.intersect1d(ours.steps, peer.steps)
    if common.size == 0:
        raise ValueError(f"{ours.name} and {peer.name} have no evaluation at the same env steps")
    ours_common = ours.returns[:, np.isin(ours.steps, common)]
    peer_common = peer.returns[:, np.isin(peer.steps, common)]
    if stats.late_window(common.size):  # none under 20 evaluations, as in `compare`
        late = f"late return (of {common.size} common evaluations)"
        rows.append(reading(late, stats.late_return(ours_common), stats.late_return(peer_common)))
    ours_auc, peer_auc = (stats.area_under_curve(r, common) for r in (ours_common, peer_common))
    rows.append(reading(f"AUC over {common.size} common evaluations", ours_auc, peer_auc))
    return rows


def markdown(ours: Curves, peer: Curves, rows: list[dict[str, Any]], command: str) -> str:
    """The table, each seed's last evaluation and the command that wrote it."""
    lines = [
        f"# {ours.name} against {peer.name}",
        "",
        f"Mean ± 95% half-width over seeds ({len(ours.seeds)} ours, {len(peer.seeds)} sbx); the "
        "difference is ours − sbx with Welch's 95% interval.",
        "",
        "| reading | ours | sbx | ours − sbx | Welch's 95% | separated |",
        "|---|---:|---:|---:|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['reading']} | {r['ours_mean']:,.0f} ± {r['ours_ci95']:,.0f} | "
            f"{r['peer_mean']:,.0f} ± {r['peer_ci95']:,.0f} | {r['difference']:+,.0f} | "
            f"[{r['welch_lo']:,.0f}, {r['welch_hi']:,.0f}] | {'yes' if r['separated'] else 'no'} |"
        )
    for c in (ours, peer):
        last = ", ".join(f"{s}: {v:,.0f}" for s, v in zip(c.seeds, c.returns[:, -1], strict=True))
        lines += [
            "",
            f"{c.name}, last evaluation ({int(c.steps[-1]):,} env steps) by seed: {last}.",
        ]
    lines += ["", f"Written by `{command}`.", ""]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("ours", help="run directory of plain SAC (several, comma-separated, are pooled)")
    p.add_argument("sbx", nargs="+", help="sbx JSONs, one per seed (benchmarks/peers/sbx_sac.py)")
    p.add_argument(
        "--at", default="100000,200000,300000", help="env steps to read, comma-separated"
    )
    p.add_argument("--out", type=Path, help="also write the table here (markdown)")
    args = p.parse_args(argv)
    try:
        at = [int(s) for s in args.at.split(",")]
    except ValueError:
        p.error(f"--at takes env steps separated by commas (e.g. 100000,300000), got {args.at!r}")
    try:
        ours, peer = load_ours(args.ours.split(",")), load_sbx(args.sbx)
        rows = readings(ours, peer, at)
    except (OSError, ValueError) as err:
        p.error(str(err))
    command = "python -m benchmarks.peers.vs_sbx " + " ".join(
        sys.argv[1:] if argv is None else argv
    )
    text = markdown(ours, peer, rows, command)
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
