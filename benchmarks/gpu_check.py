"""The project on a GPU machine as a user runs it there, in one timed pass:

    python -m benchmarks.gpu_check --out DIR      # 9 minutes at most (--budget_seconds)

1. the versions and the device;
2. the test suite without the browser test (`tests/test_human_browser.py` needs Chromium), with
   pytest-xdist workers on three cores in four, each allocating GPU memory as it needs it, f32
   matrix products at full precision (`JAX_DEFAULT_MATMUL_PRECISION=highest`: on Ampere and later
   XLA's default rounds their inputs to TF32, 1e-4 to 1e-3 apart from the f32 references the tests
   hold) and deterministic XLA ops (the suite checks that a resumed run equals an uninterrupted
   one);
3. one chunk of the `arld` preset as `seed_sweep` runs it, 40 runs vmapped in one program on MJX,
   with XLA's defaults (as a user runs it), its evaluation period shortened to `--eval_every` steps
   with as many warm-up steps (default 1,000): period 1 is the warm-up (random actions, no update)
   and an evaluation, period 2 has an update per env step and an evaluation, so the two differ by
   the updates alone;
4. the same chunk with more seeds vmapped (`--more_seeds`, 25 by default: 200 runs), if the time
   budget still holds it, to show what one program's runs cost as they grow.

Each stage is a subprocess with a deadline cut from `--budget_seconds`; a stage that overruns is
interrupted (pytest then still prints its summary) and the report says so. The sweeps are the
user's commands, read back from their progress lines: the compile time, and env steps/s (all runs)
of each period. DIR gets `gpu-check.json` (rewritten after each stage) and each stage's log; the
sweeps' own output directories go to a temporary directory (their checkpoints are not kept).

Compare the sweep's env steps/s with the same preset on a CPU (experiments/arld_100k/timing.json:
the whole 100k-step run, MJX on this project's 2-core CPU machine).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from benchmarks.harness import PACKAGES as REPORTED
from benchmarks.harness import package_versions

REPO_ROOT = Path(__file__).resolve().parent.parent
PACKAGES = (
    *REPORTED, "jax-cuda12-plugin", "jax-cuda13-plugin", "chex", "orbax-checkpoint", "scipy",
    "pytest", "pytest-xdist",
)  # fmt: skip
COMPILED = re.compile(r"compiled in (\d+) s; (\d+) runs x ([\d,]+) env steps")
PERIOD = re.compile(r"^period (\d+)/(\d+)( \(warm-up\))? \|.*\| ([\d,]+) env steps/s \(all runs\)")
PYTEST_SUMMARY = re.compile(
    r"(\d+ (?:passed|failed|errors?|skipped|deselected|xfailed|xpassed)(?:, \d+ \w+)*) in ([\d.]+)s"
)


def device_info() -> dict[str, Any]:
    """What JAX sees (in a subprocess, so this process never holds the GPU) and nvidia-smi's line."""
    probe = "import jax; d = jax.devices(); print(jax.default_backend(), len(d), d[0].device_kind)"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    smi = (
        subprocess.run(
            ["nvidia-smi", "--query-gpu=name,driver_version,memory.total", "--format=csv,noheader"],
            capture_output=True,
            text=True,
        )
        if shutil.which("nvidia-smi")
        else None
    )
    backend = out.stdout.strip().splitlines()[-1].split(" ", 2) if out.returncode == 0 else None
    return {
        "jax_backend": backend[0] if backend else None,
        "jax_devices": int(backend[1]) if backend else None,
        "device_kind": backend[2] if backend else None,
        "jax_error": None if backend else out.stderr.strip()[-2000:],
        "nvidia_smi": smi.stdout.strip() if smi and smi.returncode == 0 else None,
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
    }


def run_stage(cmd: list[str], log_path: Path, deadline: float, env: dict[str, str]) -> dict:
    """Run `cmd` from the repository root, its output to `log_path`; interrupt it (SIGINT, then
    SIGKILL 30 s later) when `deadline` (time.time()) passes. Returns rc, seconds, timed_out."""
    start = time.time()
    with log_path.open("w") as log:
        log.write(f"$ {shlex.join(cmd)}\n")
        log.flush()
        proc = subprocess.Popen(
            cmd, cwd=REPO_ROOT, stdout=log, stderr=subprocess.STDOUT, env=env, text=True
        )
        timed_out = False
        try:
            proc.wait(timeout=max(deadline - time.time(), 1))
        except subprocess.TimeoutExpired:
            timed_out = True
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    return {
        "command": shlex.join(["python", *cmd[1:]]),
        "returncode": proc.returncode,
        "seconds": round(time.time() - start, 1),
        "timed_out": timed_out,
    }


def read_sweep_log(text: str) -> dict[str, Any]:
    """The compile time, run count and per-period env steps/s printed by `seed_sweep`."""
    compiled = COMPILED.search(text)
    periods = [
        {
            "period": int(m.group(1)),
            "warm_up": bool(m.group(3)),
            "env_steps_per_second_all_runs": int(m.group(4).replace(",", "")),
        }
        for m in map(PERIOD.match, text.splitlines())
        if m
    ]
    return {
        "compile_seconds": int(compiled.group(1)) if compiled else None,
        "num_runs": int(compiled.group(2)) if compiled else None,
        "periods": periods,
    }


def read_pytest_log(text: str) -> dict[str, Any]:
    """pytest's closing line ('N passed, M failed ... in S s') and the failed tests' ids."""
    summary = PYTEST_SUMMARY.findall(text)
    return {
        "summary": summary[-1][0] if summary else None,
        "seconds": float(summary[-1][1]) if summary else None,
        "failed": sorted(set(re.findall(r"^(?:FAILED|ERROR) (\S+)", text, flags=re.M))),
    }


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True, help="where the report and logs go")
    p.add_argument("--budget_seconds", type=float, default=540.0, help="all stages together")
    p.add_argument("--test_seconds", type=float, default=240.0, help="the test suite's share")
    p.add_argument("--eval_every", type=int, default=1000, help="the sweeps' period and warm-up")
    p.add_argument("--preset", default="arld", help="the sweep preset to time (default: arld)")
    p.add_argument("--more_seeds", type=int, default=25, help="seeds of the larger sweep; 0: none")
    p.add_argument("--tests", default="tests", help="pytest's paths (default: the suite)")
    args = p.parse_args(argv)

    t0 = time.time()
    args.out.mkdir(parents=True, exist_ok=True)
    report: dict[str, Any] = {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "command": shlex.join(["python", "-m", "benchmarks.gpu_check", *(argv or sys.argv[1:])]),
        "versions": package_versions(PACKAGES),
        "device": device_info(),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
    }
    save = lambda: (args.out / "gpu-check.json").write_text(json.dumps(report, indent=2) + "\n")  # noqa: E731
    save()
    end = t0 + args.budget_seconds

    workers = max(1, (os.cpu_count() or 2) * 3 // 4)
    test_env = os.environ | {
        "XLA_PYTHON_CLIENT_PREALLOCATE": "false",
        "JAX_DEFAULT_MATMUL_PRECISION": "highest",
        "XLA_FLAGS": f"{os.environ.get('XLA_FLAGS', '')} --xla_gpu_deterministic_ops=true".strip(),
    }
    tests_cmd = [
        sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
        "-n", str(workers), "-rfE", "--durations=10",
        "--ignore=tests/test_human_browser.py", *args.tests.split(),
    ]  # fmt: skip
    stage = run_stage(
        tests_cmd, args.out / "tests.log", min(end, time.time() + args.test_seconds), test_env
    )
    report["tests"] = (
        stage | {"workers": workers} | read_pytest_log((args.out / "tests.log").read_text())
    )
    save()

    sweeps_dir = Path(tempfile.mkdtemp(prefix="gpu_check_"))
    seeds = [None] + ([args.more_seeds] if args.more_seeds else [])
    report["sweeps"] = []
    for n in seeds:
        if end - time.time() < 120:
            report["sweeps"].append({"num_seeds": n, "skipped": "the time budget was spent"})
            break
        name = f"{args.preset}" + (f"-seeds{n}" if n else "")
        cmd = [
            sys.executable, "-m", "arld_jax.run", "seed_sweep", "--preset", args.preset,
            "--eval_every", str(args.eval_every), "--learning_starts", str(args.eval_every),
            "--chunk_periods", "2", "--stop_after_chunks", "1", "--no_plots",
            "--out", str(sweeps_dir / name), *(["--num_seeds", str(n)] if n else []),
        ]  # fmt: skip
        stage = run_stage(cmd, args.out / f"{name}.log", end, os.environ.copy())
        report["sweeps"].append(stage | read_sweep_log((args.out / f"{name}.log").read_text()))
        save()
    report["total_seconds"] = round(time.time() - t0, 1)
    save()
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
