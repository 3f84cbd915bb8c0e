"""Sweeps: a base Config, lists of values for sweepable fields, and seeds -> one batch of runs.

Runs are the cartesian product of the swept values (cells, in the order the fields were given) times
the seeds (cell-major). They become ONE `HParams` pytree with a leading run axis, so a single compiled
program trains all of them with `vmap` (and shards the run axis over devices when there are several).
Each run's values are validated by building its own `Config`, so a bad value in a list fails before
anything compiles, naming the field.

Pruning (on by default): a swept value that cannot change a strategy's runs is not swept for it.
b (`query_prob`) only acts in Bernoulli cells, t_query only in active cells, and C, the budget and
eps_d only where an expert is asked at all (`RELEVANT_FOR`). So `--strategy none,bernoulli,active
--query_prob 0.1,0.3 --t_query 0.1,0.2` trains 1 + 2 + 2 cells (per uncertainty), not 12 duplicates
(the `paper` preset's grid: `preset_paper`). A pruned cell keeps the base value of the fields it
ignores and its label omits them. `--full_grid` turns pruning off.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp

from arld_jax import config as config_presets
from arld_jax.config import (
    AGENT_NAMES,
    NOISY_AGENTS,
    STRATEGIES,
    SWEEPABLE,
    SWEEPABLES,
    UNCERTAINTIES,
    Config,
    HParams,
    hparams_from_config,
)
from arld_jax.tasks import REGISTRY as TASKS

REPO_ROOT = Path(__file__).resolve().parent.parent
SHIPPED_EXPERT_PATH = TASKS["halfcheetah"].expert_dir
"""The shipped HalfCheetah expert, relative to the repository root (the default of
`evaluate_expert`); every task's is its `TaskSpec.expert_dir` (`task_expert_dir`)."""
SHIPPED_EXPERT = REPO_ROOT / SHIPPED_EXPERT_PATH

RELEVANT_FOR: dict[str, tuple[str, ...]] = {
    name: spec.strategies for name, spec in SWEEPABLES.items() if spec.strategies is not None
}
"""Swept field -> the strategies whose runs it can change (pruning; every other field: all)."""
IGNORES_UNCERTAINTY: tuple[str, ...] = tuple(a for a in AGENT_NAMES if a not in NOISY_AGENTS)
"""Agents with one uncertainty of their own (Bootstrapped TD3: its heads' disagreement), for which a
swept `uncertainty` changes nothing (pruned)."""


def resolve_expert_path(path: str) -> Path:
    """A relative expert path is taken from the current directory if it exists there, else from the
    repository root (so presets work from anywhere)."""
    p = Path(path)
    if p.is_absolute() or p.exists():
        return p
    return REPO_ROOT / p


def task_expert_dir(env_name: str) -> Path:
    """Where the expert of task `env_name` is shipped (`TaskSpec.expert_dir`), whether or not one
    is there yet: the default `--expert_path` of its runs and `--out` of its `train_expert`.
    ValueError for a task whose expert is known in closed form (the toy tasks)."""
    spec = TASKS[env_name]
    if spec.expert_dir is None:
        raise ValueError(f"task {env_name!r} ships no saved expert (its expert is in closed form)")
    return REPO_ROOT / spec.expert_dir


def expert_path_for(cfg: Config) -> Path | None:
    """The directory of the expert that runs of `cfg` ask: `cfg.expert_path`
    (`resolve_expert_path`), else the expert shipped for the task (`task_expert_dir`); None for a
    task whose expert is known in closed form (the toy tasks). ValueError, saying how to train one,
    when the task has no shipped expert."""
    from arld_jax.expert import META_FILE, train_expert_command

    if cfg.expert_path is not None:
        return resolve_expert_path(cfg.expert_path)
    if TASKS[cfg.env_name].target_action is not None:
        return None
    path = task_expert_dir(cfg.env_name)
    if not (path / META_FILE).is_file():
        raise ValueError(
            f"no expert is shipped for task {cfg.env_name!r} (none at {path}), and a query "
            "strategy other than 'none' needs one. Train one with plain SAC: "
            f"`{train_expert_command(cfg.env_name)}` (it saves the best seed's actor there, "
            "where it becomes the task's default), or pass --expert_path DIR"
        )
    return path


@dataclass(frozen=True)
class Sweep:
    """A base config, the swept fields (field -> list of values) and the seeds."""

    cfg: Config
    sweep: dict[str, tuple[Any, ...]] = field(default_factory=dict)
    seeds: tuple[int, ...] = (0,)
    prune: bool = True
    """Drop cells that differ only in a field their strategy ignores (see the module docstring)."""

    def __post_init__(self) -> None:
        for name, values in self.sweep.items():
            if name not in SWEEPABLE:
                raise ValueError(
                    f"Field {name!r} cannot be swept in one compiled program (it sets shapes or "
                    f"program structure); sweepable fields: {', '.join(SWEEPABLE)}."
                )
            if name == "seed":
                raise ValueError("Sweep seeds with `seeds`, not as a swept field.")
            if len(values) == 0:
                raise ValueError(f"Swept field {name!r} has no values.")
        if not self.seeds:
            raise ValueError("seeds is empty: give at least one seed.")
        if len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"seeds {self.seeds} has duplicates.")
        for name, values in self.sweep.items():  # every listed value, also ones pruning drops
            for value in values:
                self.cfg.replace(**{name: value})
        self.run_configs()  # and every run's combination

    def cells(self) -> list[dict[str, Any]]:
        """Every combination of the swept values, in order; when pruning, each combination keeps
        only the fields its strategy uses, and duplicates are dropped (first occurrence kept)."""
        names = list(self.sweep)
        cells, seen = [], set()
        for combo in itertools.product(*self.sweep.values()):
            cell = dict(zip(names, combo, strict=True))
            if self.prune:
                strategy = cell.get("strategy", self.cfg.strategy)
                cell = {
                    k: v for k, v in cell.items() if strategy in RELEVANT_FOR.get(k, (strategy,))
                }
                if self.cfg.agent in IGNORES_UNCERTAINTY:
                    cell.pop("uncertainty", None)
            key = tuple(sorted((k, repr(v)) for k, v in cell.items()))
            if key not in seen:
                seen.add(key)
                cells.append(cell)
        return cells

    def run_configs(self) -> list[Config]:
        """One validated Config per run (cells x seeds, cell-major)."""
        return [self.cfg.replace(**cell, seed=seed) for cell in self.cells() for seed in self.seeds]

    def program_config(self) -> Config:
        """The Config the sweep's one compiled program is built from: the base, with `noisy_runs`
        False when no run is a noisy agent (then no run draws actor weight noise, and the program
        skips those draws; results are bit-identical, tested)."""
        if self.cfg.agent not in NOISY_AGENTS or any(
            c.uncertainty == "extrinsic" for c in self.run_configs()
        ):
            return self.cfg
        # Every run is intrinsic (a base 'extrinsic' is overridden by every cell), so is the program.
        return self.cfg.replace(noisy_runs=False, uncertainty="intrinsic")

    def runs(self) -> list[dict[str, Any]]:
        """The per-run records written to runs.json."""
        records, cells = [], self.cells()
        for i, run_cfg in enumerate(self.run_configs()):
            cell_index, _ = divmod(i, len(self.seeds))
            cell = cells[cell_index]
            record = {"run": i, "cell": cell_index, "seed": run_cfg.seed}
            record["cell_label"] = " ".join(f"{k}={v}" for k, v in cell.items()) or "base"
            record.update({name: getattr(run_cfg, name) for name in SWEEPABLE if name != "seed"})
            records.append(record)
        return records

    @property
    def num_runs(self) -> int:
        return len(self.cells()) * len(self.seeds)

    def needs_expert(self) -> bool:
        return any(c.strategy != "none" for c in self.run_configs())

    def hparams_and_keys(self) -> tuple[HParams, jax.Array]:
        """Stacked HParams [num_runs] and PRNG keys [num_runs] (key = jax.random.key(seed), so a run
        in a sweep equals a single run with the same seed)."""
        configs = self.run_configs()
        hps = jax.tree.map(lambda *xs: jnp.stack(xs), *[hparams_from_config(c) for c in configs])
        keys = jnp.stack([jax.random.key(c.seed) for c in configs])
        return hps, keys

    def to_json(self) -> dict[str, Any]:
        """What identifies the sweep (compared on resume). The cell list is part of it, so a
        pruned and an unpruned sweep of the same lists never resume each other."""
        cfg = dataclasses.asdict(self.cfg)
        cfg["hidden_sizes"] = list(cfg["hidden_sizes"])
        out = {
            "config": cfg,
            "sweep": {k: list(v) for k, v in self.sweep.items()},
            "seeds": list(self.seeds),
        }
        if not self.prune:
            out["sweep"]["(full grid)"] = [True]
        return out


@dataclass(frozen=True)
class SweepGroup:
    """Sweeps that cannot share a compiled program (one per agent family: their states differ),
    trained one after another into subdirectories `agent-<name>` of one output directory, then
    summarised together. `--agent td3,boot_td3` on the command line makes one."""

    members: tuple[tuple[str, Sweep], ...]  # (subdirectory name, sweep), in order

    def __post_init__(self) -> None:
        names = [name for name, _ in self.members]
        if len(set(names)) != len(names) or not names:
            raise ValueError(f"SweepGroup members must have distinct names, got {names}")

    @classmethod
    def per_agent(cls, sweep: Sweep, agents: tuple[str, ...]) -> SweepGroup:
        """The same sweep for each agent family."""
        return cls(
            tuple(
                (f"agent-{a}", dataclasses.replace(sweep, cfg=sweep.cfg.replace(agent=a)))
                for a in agents
            )
        )

    @property
    def num_runs(self) -> int:
        return sum(s.num_runs for _, s in self.members)


# ---------------------------------------------------------------- named sweep presets


def _arld_cells(**extra: tuple[Any, ...]) -> dict[str, tuple[Any, ...]]:
    cells: dict[str, tuple[Any, ...]] = {
        "strategy": STRATEGIES,
        "uncertainty": UNCERTAINTIES,
    }
    cells.update(extra)
    return cells


def _cpu_arld_config() -> Config:
    """The CPU-sized ARLD protocol of the `experiment` preset (experiments/arld_cpu).

    A scaled-down paper protocol: MJX HalfCheetah, paper networks (2x256), batch 256, alpha 0.2,
    prioritized replay with demo bonus; 2 envs per run with one update per iteration (0.5 updates
    per env step: on a 2-core CPU the updates are the whole cost, see benchmarks/), 1,000 warm-up
    steps, 8k env steps per run, one deterministic evaluation episode every 1,000 steps (HalfCheetah's
    deterministic returns vary little across initial states; evaluation costs as much as training
    env steps here), budget 1,500 demonstrated steps, N_r = 1,000, b = 0.1, t_query = 0.1 (the
    paper's best values), C = 5. MJX, not 'auto': the committed run (experiments/arld_cpu) used it."""
    return Config(
        backend="mjx",
        num_envs=2,
        updates_per_env_step=0.5,
        learning_starts=1_000,
        total_env_steps=8_000,
        replay_capacity=8_000,
        eval_every=1_000,
        num_eval_episodes=1,
        budget=1_500,
        window_size=1_000,
        demo_steps=5,
    )


def _default_config() -> Config:
    """The default sweep's protocol: the `arld` protocol (1 env, one update per env step, SAC's
    defaults, MuJoCo's C physics on a CPU through `--backend auto`) cut to what a 2-core CPU runs in
    about ten minutes for 10 runs, sized so that demonstrations show.

    24k env steps per run with a 2k-step random warm-up: plain SAC (reward scale 5) is early on its
    learning curve there, so what demonstrations add is visible. Budget 2,000 demonstrated steps,
    C = 5 steps per query and b = t_query = 0.1 (the paper's best b and t_query; its C grid holds
    5): a query hands the expert a short stretch of running rather than a single step, and the
    budget lasts about the first 6k steps under Bernoulli querying. Three deterministic evaluation
    episodes every 3k steps (HalfCheetah's deterministic returns vary little across initial
    states); N_r 1,000."""
    return Config(
        total_env_steps=24_000,
        replay_capacity=24_000,
        learning_starts=2_000,
        eval_every=3_000,
        num_eval_episodes=3,
        budget=2_000,
        demo_steps=5,
        window_size=1_000,
        query_prob=0.1,
        t_query=0.1,
    )


def preset_default() -> Sweep:
    """The main job: plain SAC against SAC that asks the shipped expert with Bernoulli querying
    (BQSAC, b = 0.1), 5 seeds each, 24k env steps of HalfCheetah at 1 env per run, budget 2,000
    demonstrated steps in runs of C = 5 (10 runs in one compiled program; its committed run, wall
    time and reading: experiments/default_sweep/). The other strategies are one flag away:
    `--strategy none,greedy,bernoulli,active`."""
    return Sweep(
        cfg=_default_config(), sweep={"strategy": ("none", "bernoulli")}, seeds=tuple(range(5))
    )


def preset_experiment() -> Sweep:
    """The committed CPU experiment: 4 strategies x 2 uncertainty measures x 5 seeds, 8k env steps
    each (40 runs in one compiled program; about 40 min on a 2-core CPU)."""
    cfg = _cpu_arld_config()
    return Sweep(cfg=cfg, sweep=_arld_cells(), seeds=(0, 1, 2, 3, 4))


def preset_sac() -> Sweep:
    """Plain SAC on MJX HalfCheetah, 3 seeds, 100k env steps: the SAC learning curve on CPU."""
    return Sweep(cfg=config_presets.halfcheetah(), seeds=(0, 1, 2))


def preset_paper() -> Sweep:
    """The paper's protocol (appendix A.1) for a GPU: 400k steps, 10 seeds, budget 10k, N_r 5k,
    t_query in {0.05, 0.1, 0.2, ..., 0.7}, b in {0.1, ..., 0.5} (Figs. 4-6), C in {1, 2, 3, 5, 10},
    4 strategies x 2 uncertainties. Pruned (b only for Bernoulli, t_query only for active, C only
    where queries happen): 142 cells x 10 seeds = 1,420 runs instead of the 16,000 of the full
    cartesian grid. Narrow it with overrides, e.g. `--strategy active --t_query 0.05,0.1,0.2`."""
    cfg = config_presets.paper()
    sweep = _arld_cells(
        t_query=(0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7),
        query_prob=(0.1, 0.2, 0.3, 0.4, 0.5),
        demo_steps=(1, 2, 3, 5, 10),
    )
    return Sweep(cfg=cfg, sweep=sweep, seeds=tuple(range(10)))


def _arld_100k_config() -> Config:
    """The protocol of the paper's comparison at a quarter of its length.

    The paper (A.1): 400k env steps, 1 env, one update per env step, budget 10,000 demonstrated
    steps, N_r = 5,000, b = 0.1 and t_query = 0.1 (its best values), C = 1 (its grid starts there),
    evaluation every 5,000 steps. Here 100k env steps with the budget scaled to the length
    (10,000 x 100k / 400k = 2,500), everything else as the paper; 5 deterministic evaluation
    episodes. Plain SAC is still below the expert at 100k (4,236 against 6,431: experiments/
    expert/), so demonstrations have room to matter. b = 0.1 for both uncertainty measures (the paper's best b
    for Noisy SAC was 0.4; one b keeps BQSAC and BQNoisySAC spending alike). MJX, not 'auto':
    the committed runs (experiments/arld_100k, fig1_100k) used it and resume by their commands."""
    return Config(backend="mjx", replay_capacity=100_000, budget=2_500)


def preset_arld() -> Sweep:
    """The paper's comparison on this CPU: SAC, GQSAC, BQSAC, AQSAC x {sigma_theta, Noisy SAC},
    5 seeds, 100k env steps at 1 env, budget 2,500 (40 runs in one program; hours on 2 cores)."""
    return Sweep(cfg=_arld_100k_config(), sweep=_arld_cells(), seeds=tuple(range(5)))


def _arld_400k_config() -> Config:
    """The paper's protocol (appendix A.1) as far as this CPU allows.

    As A.1: HalfCheetah, 400k env steps, 1 env, one update per env step (A.1: "we did not do
    multiple learning updates per environment step"), batch 256, 2x256 networks, Adam, alpha fixed
    at 0.2, prioritized replay with the demonstration bonus eps_d, budget 10,000 demonstrated steps,
    N_r = 5,000, an evaluation every 5,000 steps, the expert a pre-trained prioritized SAC (ours:
    experiments/expert), a replay that holds the whole run.

    Where it departs from A.1, and why:
    - physics: Brax's HalfCheetah stepped by MuJoCo's C engine (`backend='mujoco'`), not Gym's
      HalfCheetah: the same model family and reward (forward velocity minus 0.1 x control cost), the
      step this CPU can afford for 400k steps x 25 runs;
    - seeds: 5 (0-4) instead of 10, the cores' limit (the 25 runs take about a day here); seeds
      5-9 run as a second directory with `--seeds 5,6,7,8,9` and pool with `compare A,B C,D`;
    - the grids: A.1 tunes t_query over {0.05, 0.1, ..., 0.7}, C over {1, 2, 3, 5, 10} and b; here
      t_query = 0.1 (the paper's best), b in {0.1, 0.2} (4.3 names 0.1 the best b, Fig. 4 plots 0.2)
      and C = 1 (the start of its grid, as in the `arld` preset);
    - reward scale 5 (A.1 tunes it per environment without giving the value; 5 is what SAC's
      authors used for HalfCheetah and what our ablation chose, experiments/README.md);
    - 10 deterministic evaluation episodes per evaluation (A.1 does not say how many; `paper()`'s
      value), and a 5,000-step uniform-random warm-up (A.1 is silent; our default)."""
    return config_presets.paper(backend="mujoco")


def preset_arld_400k() -> Sweep:
    """The paper's comparison at its own length (Fig. 4, sigma_theta): SAC, GQSAC, BQSAC with
    b = 0.1 and b = 0.2, AQSAC with t_query = 0.1, 5 seeds, 400k env steps at 1 env, budget
    10,000, C physics (25 runs in one program; 20-30 hours on a 2-core CPU,
    experiments/README.md)."""
    return Sweep(
        cfg=_arld_400k_config(),
        sweep={"strategy": STRATEGIES, "query_prob": (0.1, 0.2)},
        seeds=tuple(range(5)),
    )


def _tasks_sac_config() -> Config:
    """Plain SAC's protocol on any locomotion task (`--env_name`), for parity with other trainers
    and for the task's expert: 300k env steps, 1 env, one update per env step, SAC's defaults
    (2x256 networks, batch 256, alpha 0.2, reward scale 5 as SAC's authors used for Hopper,
    Walker2d, HalfCheetah and Ant), 10 deterministic evaluation episodes every 10k steps (episodes
    of Hopper and Walker2d vary with their initial state more than HalfCheetah's), physics 'auto'
    (MuJoCo's C engine on a CPU)."""
    return Config(
        total_env_steps=300_000,
        replay_capacity=300_000,
        eval_every=10_000,
        num_eval_episodes=10,
    )


def preset_sac_300k() -> Sweep:
    """Plain SAC on a task at 300k env steps, 5 seeds (`--env_name hopper`, `walker2d`, `ant`):
    the parity run against published SAC and sbx. `train_expert --preset sac_300k --env_name T`
    trains the same runs and ships the best seed's actor as T's expert. Which flags made it learn
    each task by 300k: docs/running.md."""
    return Sweep(cfg=_tasks_sac_config(), seeds=tuple(range(5)))


def preset_arld_task() -> Sweep:
    """The paper's comparison with sigma_theta (SAC, GQSAC, BQSAC b = 0.1, AQSAC t_query = 0.1) on
    any task (`--env_name hopper`), at the `arld` protocol: 100k env steps at 1 env, budget 2,500
    (the paper's 10,000 scaled to the length), C = 1, N_r 5,000, 5 seeds; physics 'auto'. Asks the
    task's shipped expert (`train_expert --preset sac_300k --env_name T` makes it)."""
    return Sweep(
        cfg=_arld_100k_config().replace(backend="auto"),
        sweep={"strategy": STRATEGIES},
        seeds=tuple(range(5)),
    )


def preset_fig1() -> SweepGroup:
    """The paper's Fig. 1 on this CPU: the TD3 family under ARLD on the `arld` protocol. TD3 and
    Noisy TD3 (uncertainty 'extrinsic') share one program; Bootstrapped TD3 (its uncertainty is the
    heads' disagreement) is the second. Each with none / greedy / Bernoulli / active, 5 seeds."""
    cfg = _arld_100k_config()
    td3 = Sweep(cfg=cfg.replace(agent="td3"), sweep=_arld_cells(), seeds=tuple(range(5)))
    boot = Sweep(
        cfg=cfg.replace(agent="boot_td3"),
        sweep={"strategy": STRATEGIES},
        seeds=tuple(range(5)),
    )
    return SweepGroup((("agent-td3", td3), ("agent-boot_td3", boot)))


def preset_tiny() -> Sweep:
    """Seconds on the toy env (tests, smoke runs). Strategies that query use the toy expert."""
    return Sweep(cfg=config_presets.tiny(), seeds=(0, 1))


SWEEP_PRESETS: dict[str, Callable[[], Sweep | SweepGroup]] = {
    "default": preset_default,
    "arld": preset_arld,
    "arld_400k": preset_arld_400k,
    "fig1": preset_fig1,
    "experiment": preset_experiment,
    "sac": preset_sac,
    "sac_300k": preset_sac_300k,
    "arld_task": preset_arld_task,
    "paper": preset_paper,
    "tiny": preset_tiny,
}
