"""The table of headline figures printed at the end of a benchmark run."""

from __future__ import annotations

import math
from typing import Any

from benchmarks.harness import print_table


def _get(sections: dict, *path: str) -> Any:
    """sections[path[0]][path[1]]..., or nan when a section was skipped or failed."""
    node: Any = sections
    for p in path:
        if not isinstance(node, dict) or p not in node:
            return float("nan")
        node = node[p]
    return node


def print_summary(sections: dict) -> None:
    """The headline figures of every section that ran, in one table."""
    g = lambda *path: _get(sections, *path)
    env_rows = [
        [f"env only {k.replace('_', ', ')} env(s), env steps/s", v["env_steps_per_s"]]
        for k, v in sections.get("env", {}).items()
        if isinstance(v, dict) and "env_steps_per_s" in v
    ]
    seed_rows = [
        [
            f"{k.replace('_', ' ')} vmapped: total updates/s (x separate; update alone x 1 seed)",
            f"{v['total_updates_per_s']:,.0f} ({v['speedup_vs_separate_runs']:.2f}x; "
            f"{v['update_alone_speedup_vs_one_seed']:.2f}x)",
        ]
        for k, v in sections.get("seeds", {}).items()
        if isinstance(v, dict) and "total_updates_per_s" in v
    ]
    replay_rows = [
        [
            f"replay alone, capacity {v['capacity']:,}, {v['seeds']} seed(s): ms/iter per seed",
            v["ms_per_iteration_per_seed"],
        ]
        for v in sections.get("replay", {}).values()
        if isinstance(v, dict) and "ms_per_iteration_per_seed" in v
    ]
    peers = sections.get("peers", {})
    peer_rows = [
        [
            f"peers {v['num_envs']} env(s): env steps/s arld MJX / arld C / Brax (x Brax)",
            f"{v['arld_env_steps_per_s']:,.1f} / {v['arld_mujoco_env_steps_per_s']:,.1f} / "
            f"{v['brax_env_steps_per_s']:,.1f} ({v['ratio_arld_over_brax']:.2f}x / "
            f"{v['ratio_arld_mujoco_over_brax']:.2f}x)",
        ]
        for v in peers.values()
        if isinstance(v, dict) and "ratio_arld_over_brax" in v
    ]
    if "error" in peers:
        peer_rows.append(
            [
                "peers (Brax SAC vs arld_jax)",
                "ERROR " + " | ".join(peers["error"].splitlines())[:150],
            ]
        )
    rows = [
        ["matmul f32 256-wide, GFLOP/s (best)", g("flops", "matmul_gflops_f32_best")],
        ["matmul bf16-in/f32-acc 256-wide, GFLOP/s (best)", g("flops", "matmul_gflops_bf16_best")],
        ["one update B=256 2x256, GFLOP (XLA)", g("flops", "xla_cost_analysis_flops") / 1e9],
        [
            "one update B=256 2x256, GFLOP (analytic)",
            g("flops", "analytic_matmul_flops", "total") / 1e9,
        ],
        ["physical limit f32, updates/s", g("flops", "limit_updates_per_s_f32")],
        *env_rows,
        ["update only f32, updates/s", g("update", "float32", "updates_per_s")],
        ["update only f32, fraction of limit", g("update", "float32", "fraction_of_limit")],
        [
            "update only f32, fraction of limit (interleaved)",
            g("update", "float32", "fraction_of_limit_interleaved"),
        ],
        ["update only bf16, updates/s", g("update", "bfloat16", "updates_per_s")],
        [
            "update only f32 with noise draws, updates/s",
            g("update", "float32, noise draws (Noisy SAC program)", "updates_per_s"),
        ],
        ["trainer 1 env: env steps/s", g("trainer", "envs_1", "env_steps_per_s")],
        ["trainer 1 env: fraction of limit", g("trainer", "envs_1", "fraction_of_limit")],
        ["trainer 16 envs: env steps/s", g("trainer", "envs_16", "env_steps_per_s")],
        ["trainer 16 envs: fraction of limit", g("trainer", "envs_16", "fraction_of_limit")],
        *replay_rows,
        *seed_rows,
        ["first step cold, wall s", g("first_step", "cold", "wall_to_first_step_s")],
        ["first step warm, wall s", g("first_step", "warm", "wall_to_first_step_s")],
        ["replay at 1M, MiB/seed", g("memory", "replay_bytes_obs17_act6") / 2**20],
        ["TrainState at 1M, MiB/seed", g("memory", "train_state_bytes") / 2**20],
        *peer_rows,
    ]
    ran = [r for r in rows if not (isinstance(r[1], float) and math.isnan(r[1]))]
    print_table("summary (sections that ran)", ["figure", "value"], ran)
