"""The `peers` section: Brax's own SAC trainer, in its own virtual environment, beside arld_jax's.

Brax 0.14.2's trainers need an older jax than the project's, so they run in a separate venv
(`ensure_brax_venv` builds it from `BRAX_VENV_PINS`) as a child process (`brax_sac.py` here,
which imports nothing from arld_jax); arld_jax's trainer runs in this process at the same configs.
"""

from __future__ import annotations

import dataclasses
import json
import os
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from arld_jax.train import make_train
from benchmarks.harness import Bench, log, print_table, repo_path
from benchmarks.programs import (
    HC_ACTION_DIM,
    HC_OBS_DIM,
    PAPER_BATCH,
    PAPER_HIDDEN,
    PAPER_UPDATE,
    time_periods,
    trainer_config,
)
from benchmarks.sections import evaluate_seconds, measured_limit

BRAX_VENV_ENV_VAR = "ARLD_BENCH_BRAX_VENV"


BENCH_CACHE = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "arld_jax_bench"


# Brax 0.14.2's trainers need jax < 0.10 (`jax.device_put_replicated`). This set resolves on PyPI
# (pip, 2026-11) and runs brax.training.agents.sac on MJX HalfCheetah; mujoco-mjx 3.17.0 asks for
# mujoco >= 3.17.0.dev0, so mujoco is pinned to the matching 3.17.0.
BRAX_VENV_PINS: tuple[str, ...] = (
    "jax==0.9.2",
    "jaxlib==0.9.2",
    "brax==0.14.2",
    "mujoco-mjx==3.17.0",
    "mujoco==3.17.0",
)


PEER_SCRIPT = Path(__file__).resolve().parent / "brax_sac.py"


PEER_MARKER = "PEER_EVENT "  # = brax_sac.PEER_MARKER (that file must not import arld_jax)


@dataclass(frozen=True)
class PeerSizes:
    """Work of the peers section: the same on both sides (see `section_peers`)."""

    env_counts: tuple[int, ...]  # configs (parallel envs), 1 update per env step each
    period_env_steps: int  # env steps between evaluations (arld eval_every; one Brax epoch)
    eval_episodes: int  # episodes per evaluation (arld num_eval_episodes; Brax num_eval_envs)
    timed_periods: int  # periods timed after the warm-up period (which compiles)
    capacity: int  # replay capacity (arld replay_capacity; Brax max_replay_size)


PEERS_FULL = PeerSizes(
    env_counts=(16, 1), period_env_steps=4000, eval_episodes=5, timed_periods=3, capacity=100_000
)


PEERS_QUICK = PeerSizes(
    env_counts=(16,), period_env_steps=512, eval_episodes=1, timed_periods=1, capacity=10_000
)


def brax_venv_dir() -> Path:
    """The separate virtual environment of Brax's trainer ($ARLD_BENCH_BRAX_VENV overrides)."""
    return Path(os.environ.get(BRAX_VENV_ENV_VAR) or BENCH_CACHE / "brax-venv").expanduser()


def _venv_python(venv: Path) -> Path:
    return venv / ("Scripts/python.exe" if os.name == "nt" else "bin/python")


def _peer_env() -> dict[str, str]:
    """The child's environment: ours without PYTHONPATH/PYTHONHOME (the venv must see only its
    own site-packages; XLA_FLAGS and the rest are kept, so both trainers see the same flags)."""
    return {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}


def _peer_events(stdout: str) -> list[dict]:
    return [
        json.loads(ln[len(PEER_MARKER) :])
        for ln in stdout.splitlines()
        if ln.startswith(PEER_MARKER)
    ]


def _probe_brax_venv(python: Path) -> dict | None:
    """The venv's package versions (the child's info line), or None when it cannot run it."""
    if not python.exists():
        return None
    proc = subprocess.run(
        [str(python), str(PEER_SCRIPT), "--versions-only", "--num-envs", "1", "--num-timesteps",
         "1", "--num-evals", "1", "--num-eval-envs", "1", "--min-replay-size", "0",
         "--max-replay-size", "1"],
        capture_output=True, text=True, timeout=600, env=_peer_env(),
    )  # fmt: skip
    info = [e for e in _peer_events(proc.stdout) if e["event"] == "info"]
    return info[0] if proc.returncode == 0 and info else None


def _pins_met(versions: dict) -> bool:
    pinned = dict(p.split("==") for p in BRAX_VENV_PINS)
    return all(versions.get(k) == v for k, v in pinned.items())


def ensure_brax_venv() -> dict:
    """Create the venv (`python -m venv`) and `pip install` the pins when missing or different;
    return its versions, `pip freeze` and whether it was built now (not where it lies: the report
    must read the same off this machine). Raises RuntimeError (with pip's output) when it cannot
    be built, e.g. without network."""
    venv = brax_venv_dir()
    python = _venv_python(venv)
    info = _probe_brax_venv(python)
    built, build_s, log_path = False, 0.0, venv.parent / f"{venv.name}-pip.log"
    if info is None or not _pins_met(info["versions"]):
        log(f"(building the Brax venv {venv}: pip install {' '.join(BRAX_VENV_PINS)}; ~0.5 GB)")
        start = time.perf_counter()
        venv.parent.mkdir(parents=True, exist_ok=True)
        steps = [
            [sys.executable, "-m", "venv", str(venv)],
            [str(python), "-m", "pip", "install", "--upgrade", *BRAX_VENV_PINS],
        ]
        with log_path.open("w") as fh:
            for cmd in steps:
                fh.write(f"$ {' '.join(cmd)}\n")
                fh.flush()
                proc = subprocess.run(
                    cmd, stdout=fh, stderr=subprocess.STDOUT, text=True, timeout=3600,
                    env=_peer_env(),
                )  # fmt: skip
                if proc.returncode:
                    tail = log_path.read_text()[-1500:]
                    raise RuntimeError(
                        f"cannot build the Brax venv {venv} ({' '.join(cmd[:4])} ... exit "
                        f"{proc.returncode}; log {log_path}): {tail}"
                    )
        build_s, built = time.perf_counter() - start, True
        info = _probe_brax_venv(python)
        if info is None or not _pins_met(info["versions"]):
            raise RuntimeError(f"Brax venv {venv} built but its versions do not match: {info}")
    freeze = subprocess.run(
        [str(python), "-m", "pip", "freeze"], capture_output=True, text=True, timeout=600
    ).stdout.split()
    return {
        "override_env_var": BRAX_VENV_ENV_VAR,
        "pins": list(BRAX_VENV_PINS),
        "versions": info["versions"],
        "python": info["python"],
        "devices": info["devices"],
        "pip_freeze": freeze,
        "built_now": built,
        "build_s": build_s,
    }


def brax_run(num_envs: int, ps: PeerSizes) -> dict:
    """Brax's SAC (benchmarks/peers/brax_sac.py) in the venv; rate between the last two progress
    calls (one epoch of `period_env_steps` env steps + one evaluation, nothing compiling)."""
    period = ps.period_env_steps
    prefill = period // 2  # = arld's learning_starts in trainer_config (a multiple of num_envs)
    num_evals = 2 + ps.timed_periods  # initial eval + warm-up epoch (compiles) + timed epochs
    num_timesteps = prefill + (num_evals - 1) * period
    args = {
        "--num-envs": num_envs,
        "--num-timesteps": num_timesteps,
        "--num-evals": num_evals,
        "--num-eval-envs": ps.eval_episodes,
        "--min-replay-size": prefill,
        "--max-replay-size": ps.capacity,
        "--batch-size": PAPER_BATCH,
        "--episode-length": 1000,
    }
    flags = [str(x) for kv in args.items() for x in kv]
    cmd = [str(_venv_python(brax_venv_dir())), str(PEER_SCRIPT), *flags]
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=4 * 3600, env=_peer_env())
    wall = time.perf_counter() - start
    events = _peer_events(proc.stdout)
    progress = [e for e in events if e["event"] == "progress"]
    done = [e for e in events if e["event"] == "done"]
    if proc.returncode or not done or len(progress) < 3:
        raise RuntimeError(f"Brax child failed ({proc.returncode}): {proc.stderr[-2000:]}")
    steps_per_epoch = done[0]["num_training_steps_per_epoch"] * num_envs
    if steps_per_epoch != period:
        raise RuntimeError(f"Brax epoch has {steps_per_epoch} env steps, expected {period}")
    intervals = [
        {
            "env_steps": b["step"] - a["step"],
            "seconds": b["t"] - a["t"],
            "env_steps_per_s": (b["step"] - a["step"]) / (b["t"] - a["t"]),
            "training_sps": b["metrics"].get("training/sps", float("nan")),
            "eval_s": b["metrics"].get("eval/epoch_eval_time", float("nan")),
        }
        for a, b in zip(progress[1:-1], progress[2:], strict=True)  # from the 2nd epoch on
    ]
    last = intervals[-1]
    return {
        "num_envs": num_envs,
        "command": " ".join(
            [str(_venv_python(Path("<brax venv>"))), repo_path(PEER_SCRIPT), *flags]
        ),
        "train_kwargs": {
            "environment": "envs.get_environment('halfcheetah', backend='mjx')",
            "num_envs": num_envs,
            "grad_updates_per_step": num_envs,
            "batch_size": PAPER_BATCH,
            "min_replay_size": prefill,
            "max_replay_size": ps.capacity,
            "episode_length": 1000,
            "discounting": 0.99,
            "learning_rate": 3e-4,
            "reward_scaling": 1.0,
            "tau": 0.005,
            "normalize_observations": False,
            "deterministic_eval": True,
            "num_eval_envs": ps.eval_episodes,
            "num_timesteps": num_timesteps,
            "num_evals": num_evals,
            "network": "make_sac_networks default: 2x256 relu, tanh-normal policy, 2 critics",
        },
        "progress": progress,
        "steady_intervals": intervals,
        "env_steps_per_s": last["env_steps_per_s"],
        "env_steps_per_s_median": statistics.median(i["env_steps_per_s"] for i in intervals),
        "without_eval_env_steps_per_s": last["training_sps"],
        "eval_s": last["eval_s"],
        "to_first_progress_s": progress[0]["t"],
        "last_eval_return": progress[-1]["metrics"].get("eval/episode_reward", float("nan")),
        "child_wall_s": wall,
        "method": "env steps between the last two progress calls / seconds between them "
        "(one training epoch + one evaluation; compiles happen before the first epoch ends)",
    }


def arld_peer_run(b: Bench, num_envs: int, ps: PeerSizes, backend: str = "mjx") -> dict:
    """arld_jax's trainer at the peers config: `trainer_config` (1 update per env step,
    learning_starts half a period) with the peers' period, sizes and eval episodes, jitted as the
    driver does (`jit_chunk`, via `time_periods`); the median of the timed periods. `backend`:
    the physics of halfcheetah ('mjx' as Brax, or 'mujoco': MuJoCo's C engine, same model)."""
    sizes = dataclasses.replace(
        b.sizes,
        period_env_steps=ps.period_env_steps,
        timed_periods=ps.timed_periods,
        trainer_hidden=PAPER_HIDDEN,
        trainer_batch=PAPER_BATCH,
        trainer_capacity=ps.capacity,
    )
    cfg = trainer_config(sizes, False, num_envs).replace(
        num_eval_episodes=ps.eval_episodes,
        autotune_alpha=True,  # as Brax (arld computes the alpha step either way: same work)
        backend=backend,
    )
    trainer = make_train(cfg)
    timing = time_periods(trainer, 1, ps.timed_periods)
    eval_s = evaluate_seconds(b, trainer, timing["_agent_state"])
    out = {k: v for k, v in timing.items() if not k.startswith("_")}
    return out | {
        "env": cfg.env_name,
        "backend": cfg.backend,
        "eval_every": cfg.eval_every,
        "num_eval_episodes": cfg.num_eval_episodes,
        "learning_starts": cfg.learning_starts,
        "replay_capacity": cfg.replay_capacity,
        "hidden_sizes": list(cfg.hidden_sizes),
        "batch_size": cfg.batch_size,
        "updates_per_env_step": cfg.updates_per_env_step,
        "autotune_alpha": cfg.autotune_alpha,
        "eval_s": eval_s,
        "without_eval_env_steps_per_s": cfg.eval_every / (timing["median_s"] - eval_s),
        "method": "median over timed periods of eval_every env steps + one evaluation "
        "(time_periods); without eval: minus trainer.evaluate timed alone",
    }


def section_peers(b: Bench) -> dict:
    """Brax's own SAC trainer (brax.training.agents.sac.train, in a separate venv with jax 0.9.2)
    and arld_jax's trainer, side by side at the same configs on MJX HalfCheetah; arld_jax also with
    the same HalfCheetah stepped by MuJoCo's C engine (`--backend mujoco`), the speed a CPU user
    of arld_jax gets, reported beside (not instead of) the like-for-like MJX ratio.

    Equal work: both do 1 gradient update (batch 256, 2x256 actor and twin critics) per env step,
    evaluate every `period_env_steps` env steps with `eval_episodes` parallel 1,000-step episodes
    of the deterministic policy, and are timed over whole periods (training + evaluation) after a
    warm-up period that compiles. Differences that are part of each trainer and left in: arld_jax
    uses prioritized replay, Brax a uniform queue; Brax's alpha loss runs its own actor forward.
    """
    if b.args.skip_mjx:
        return {"skipped": "--skip-mjx: Brax's trainer runs MJX HalfCheetah only"}
    ps = PEERS_QUICK if b.args.quick else PEERS_FULL
    out: dict[str, Any] = {
        "sizes": dataclasses.asdict(ps),
        "evaluation": (
            f"included on both sides, equal: every {ps.period_env_steps} env steps, "
            f"{ps.eval_episodes} parallel episode(s) of 1000 steps, deterministic policy "
            "(arld: eval_every, num_eval_episodes; Brax: num_evals over num_timesteps, "
            "num_eval_envs, deterministic_eval=True)"
        ),
        "differences_kept": "arld_jax: prioritized replay (sum tree), fixed-size on device, "
        "compiler option xla_cpu_copy_insertion_use_region_analysis, jax of this process; Brax: "
        "uniform replay queue, alpha loss with its own actor forward, pmap over 1 device, "
        "jax 0.9.2 (venv); both tune alpha",
    }
    try:
        out["brax_venv"] = venv = ensure_brax_venv()
    except (RuntimeError, OSError, subprocess.SubprocessError) as err:
        out["error"] = f"Brax venv unavailable, nothing measured: {type(err).__name__}: {err}"
        log(f"!!! peers: {out['error'][:500]}")
        return out
    limit = float("nan")
    matmul = b.report["sections"].get("matmul", {})
    if "float32_e1" in matmul:  # only when the matmul section ran in this process
        limit = measured_limit(b, PAPER_UPDATE, HC_OBS_DIM, HC_ACTION_DIM)
    out["limit_updates_per_s_f32"] = limit
    for num_envs in ps.env_counts:
        log(f"(peers, {num_envs} env(s): Brax SAC in {brax_venv_dir()} ...)")
        brax = brax_run(num_envs, ps)
        log(
            f"(peers, {num_envs} env(s): Brax {brax['env_steps_per_s']:.1f} env steps/s; arld_jax ...)"
        )
        arld = arld_peer_run(b, num_envs, ps)
        log(f"(peers, {num_envs} env(s): arld_jax {arld['env_steps_per_s']:.1f}; C physics ...)")
        arld_c = arld_peer_run(b, num_envs, ps, backend="mujoco")
        out[f"envs_{num_envs}"] = {
            "num_envs": num_envs,
            "env_steps_between_evals": ps.period_env_steps,
            "eval_episodes": ps.eval_episodes,
            "brax_env_steps_per_s": brax["env_steps_per_s"],
            "arld_env_steps_per_s": arld["env_steps_per_s"],
            "ratio_arld_over_brax": arld["env_steps_per_s"] / brax["env_steps_per_s"],
            "brax_without_eval_env_steps_per_s": brax["without_eval_env_steps_per_s"],
            "arld_without_eval_env_steps_per_s": arld["without_eval_env_steps_per_s"],
            "ratio_without_eval": arld["without_eval_env_steps_per_s"]
            / brax["without_eval_env_steps_per_s"],
            "brax_fraction_of_f32_limit": brax["env_steps_per_s"] / limit,
            "arld_fraction_of_f32_limit": arld["env_steps_per_s"] / limit,
            # The same trainer with Brax's halfcheetah stepped by MuJoCo's C engine: the same
            # model and task, other physics code than Brax's MJX (Config.backend = 'mujoco').
            "arld_mujoco_env_steps_per_s": arld_c["env_steps_per_s"],
            "ratio_arld_mujoco_over_brax": arld_c["env_steps_per_s"] / brax["env_steps_per_s"],
            "arld_mujoco_without_eval_env_steps_per_s": arld_c["without_eval_env_steps_per_s"],
            "ratio_arld_mujoco_without_eval": arld_c["without_eval_env_steps_per_s"]
            / brax["without_eval_env_steps_per_s"],
            "arld_mujoco_fraction_of_f32_limit": arld_c["env_steps_per_s"] / limit,
            "brax": brax,
            "arld": arld,
            "arld_mujoco": arld_c,
        }
        b.save()
    rows = [
        [
            f"{r['num_envs']} env(s)",
            f"{r['env_steps_between_evals']:,} / {r['eval_episodes']}",
            r["brax_env_steps_per_s"],
            r["arld_env_steps_per_s"],
            r["ratio_arld_over_brax"],
            r["brax_without_eval_env_steps_per_s"],
            r["arld_without_eval_env_steps_per_s"],
            r["ratio_without_eval"],
            f"{r['brax_fraction_of_f32_limit']:.2f} / {r['arld_fraction_of_f32_limit']:.2f}",
            r["arld_mujoco_env_steps_per_s"],
            r["ratio_arld_mujoco_over_brax"],
            r["ratio_arld_mujoco_without_eval"],
            f"{r['arld_mujoco_fraction_of_f32_limit']:.2f}",
        ]
        for r in out.values()
        if isinstance(r, dict) and "ratio_arld_over_brax" in r
    ]
    print_table(
        f"peers: Brax {venv['versions']['brax']} SAC (jax {venv['versions']['jax']}) vs arld_jax, "
        "HalfCheetah, 1 update per env step, B 256, 2x256; arld on MJX as Brax, and 'C' = arld "
        "with MuJoCo's C engine (--backend mujoco)",
        [
            "config",
            "steps/eval / episodes",
            "brax steps/s",
            "arld steps/s",
            "arld/brax",
            "brax no-eval",
            "arld no-eval",
            "arld/brax no-eval",
            "of f32 limit brax / arld",
            "arld C steps/s",
            "C/brax",
            "C/brax no-eval",
            "C of f32 limit",
        ],
        rows,
    )
    return out
