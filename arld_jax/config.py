"""One frozen configuration, the sweepable hyperparameters, presets and validation.

Two kinds of settings (STYLE.md habit 2):

* **Static** fields set array shapes or program structure (number of envs, replay capacity, batch size,
  network width, reference-window size N_r, ...). They are closed over by `make_train` and changing one
  means a new compiled program.
* **Sweepable** fields (`SWEEPABLE`) are values: query strategy, Bernoulli probability b, proportion
  threshold t_query, demonstration length C, budget, uncertainty measure, learning rates, seed, ...
  They travel into the compiled program as a small pytree of arrays (`HParams`), so one program can
  `vmap` over any grid of them together with seeds.

Every check runs in Python, before anything compiles, and names the field, the value and what is allowed.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import math
import textwrap
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import flax.struct
import jax
import jax.numpy as jnp

from arld_jax import checks
from arld_jax.agents import REGISTRY
from arld_jax.tasks import REGISTRY as TASKS

STRATEGIES: tuple[str, ...] = ("none", "greedy", "bernoulli", "active")
"""Query strategies (paper section 4): SAC, GQSAC, BQSAC, AQSAC. The index is the id used on device."""

UNCERTAINTIES: tuple[str, ...] = ("intrinsic", "extrinsic")
"""Uncertainty measures: intrinsic = SAC's sigma_theta(s) (paper 3.2); extrinsic = Noisy SAC's analytic
variance of the perturbed mean (paper 3.1). Choosing "extrinsic" also makes the agent a Noisy SAC."""

STRATEGY_PREFIX: dict[str, str] = {"none": "", "greedy": "GQ", "bernoulli": "BQ", "active": "AQ"}
"""The paper's names of the strategies' agents: SAC, GQSAC, BQSAC, AQSAC (section 4)."""

AGENT_NAMES: tuple[str, ...] = tuple(REGISTRY)
"""Agent families, one module each in `arld_jax.agents` (SAC, TD3, Bootstrapped TD3). One compiled
program per family; the paper's Fig. 1 compares the TD3 family under ARLD."""
NOISY_AGENTS: tuple[str, ...] = tuple(name for name, spec in REGISTRY.items() if spec.noisy)
"""Families with a noisy variant (uncertainty 'extrinsic' = Noisy SAC / Noisy TD3, paper 3.1); the
others have one uncertainty of their own (Bootstrapped TD3: its heads' disagreement)."""
AGENT_OPTIONS: tuple[type, ...] = tuple(
    spec.options for spec in REGISTRY.values() if spec.options is not None
)
"""Each agent's own Config fields (`AgentSpec.options`); `Config` inherits them."""


def paper_name(strategy: str, agent: str = "sac", uncertainty: str = "intrinsic") -> str:
    """The paper's name of a cell's agent: SAC, GQSAC, BQSAC, AQSAC, AQNoisySAC (section 4), and
    likewise AQTD3, BQNoisyTD3, GQBootTD3 for the Fig. 1 families."""
    return STRATEGY_PREFIX[strategy] + REGISTRY[agent].variant(uncertainty)


SHORT_NAMES: dict[str, str] = {"demo_steps": "C", "query_prob": "b"}
"""A swept field's name in a cell's name, where the paper has a shorter one."""


def cell_name(
    values: Mapping[str, Any], swept: Iterable[str], agent: str = "sac", exclude: Iterable[str] = ()
) -> str:
    """A cell in the paper's names, as figures and progress lines show it: its agent
    (`paper_name`), b for a Bernoulli cell, t_query for an active one, then every other swept
    field its strategy uses (`SWEEPABLES`): "SAC", "BQSAC b=0.2", "AQNoisyTD3 t_query=0.1 C=2".
    `values`: the cell's fields (strategy, uncertainty, b, t_query and the swept ones);
    `exclude`: fields not to show (a panel that fixes them)."""
    strategy, exclude = values["strategy"], set(exclude)
    shown = {"bernoulli": "query_prob", "active": "t_query"}.get(strategy)
    names = [shown] if shown and shown not in exclude else []
    skip = {"strategy", "uncertainty", "query_prob", "t_query", *exclude}
    names += [n for n in swept if n not in skip and n in SWEEPABLES and _uses(strategy, n)]
    parts = [paper_name(strategy, agent, values.get("uncertainty") or "intrinsic")]
    for name in names:
        value = values[name]
        text = f"{value:g}" if isinstance(value, float) else str(value)
        parts.append(f"{SHORT_NAMES.get(name, name)}={text}")
    return " ".join(parts)


def _uses(strategy: str, name: str) -> bool:
    """Whether runs of `strategy` use the sweepable field `name` (the pruning rule)."""
    return strategy in (SWEEPABLES[name].strategies or STRATEGIES)


def jax_platform() -> str:
    """The platform jax computes on by default: 'cpu', 'gpu' or 'tpu'."""
    return jax.default_backend()


def auto_backend(platform: str) -> str:
    """The physics `backend='auto'` takes on `platform`: MuJoCo's C engine on the CPU, where its
    step costs a small fraction of MJX's; MJX on an accelerator, where the C engine would pay a
    device-host round trip per step and MJX steps the envs on the device."""
    return "mujoco" if platform == "cpu" else "mjx"


def physics_line(cfg: Config, platform: str) -> str:
    """One line saying which physics `cfg` runs and how it relates to 'auto' on `platform`."""
    if TASKS[cfg.env_name].brax_name is None:
        return f"physics: none ({cfg.env_name} is pure JAX; --backend does not apply)"
    auto = auto_backend(platform)
    how = (
        f"--backend auto on {platform}"
        if cfg.backend == auto
        else f"chosen by --backend or the preset; auto would take {auto} on {platform}"
    )
    solver = solver_options(cfg)
    told = "".join(f", {v} {SOLVER_WORDS[k]}" for k, v in solver.items())
    if cfg.integrator != "task":
        told += f", {INTEGRATORS[cfg.integrator]}"
    if cfg.contacts != "task":
        told += f", {CONTACTS[cfg.contacts]}"
    return f"physics: {cfg.backend} ({PHYSICS[cfg.backend]}; {how}{told})"


SOLVER_FIELDS: dict[str, str] = {
    "solver_iterations": "iterations",
    "solver_ls_iterations": "ls_iterations",
}
"""Each solver field of `Config` and the MuJoCo option (`opt.*`) it sets."""
SOLVER_WORDS: dict[str, str] = {"iterations": "solver iterations", "ls_iterations": "line searches"}
"""Each MuJoCo solver option in words (the line a run starts with)."""


def solver_settings(cfg: Config) -> dict[str, int]:
    """The solver fields `cfg` sets (field name -> value), the solver part of `physics_settings`;
    empty when every one is 0 (the task's own, Brax's)."""
    return {f: v for f, v in physics_settings(cfg).items() if f in SOLVER_FIELDS}


def solver_options(cfg: Config) -> dict[str, int]:
    """The MuJoCo solver options `cfg` sets over the task's own (`opt.*` name -> value)."""
    return {SOLVER_FIELDS[f]: v for f, v in solver_settings(cfg).items()}


INTEGRATORS: dict[str, str] = {
    "task": "the task's own integrator",
    "rk4": "4th-order Runge-Kutta",
}
"""Each choice of `Config.integrator`, in words (the line a run starts with)."""
INTEGRATOR_OPT: dict[str, int] = {"rk4": 1}
"""MuJoCo's `opt.integrator` (`mjtIntegrator`: mjINT_RK4 = 1) of each `Config.integrator` other
than 'task'."""


def model_options(cfg: Config) -> dict[str, int]:
    """The MuJoCo options `cfg` sets over the task's own (`opt.*` name -> value): the solver's
    (`solver_options`) and the integrator."""
    options = solver_options(cfg)
    if cfg.integrator != "task":
        options["integrator"] = INTEGRATOR_OPT[cfg.integrator]
    return options


CONTACTS: dict[str, str] = {
    "task": "the task's own contacts",
    "all": "every body geom touches the floor",
}
"""Each choice of `Config.contacts`, in words (the line a run starts with)."""


PHYSICS_FIELDS: tuple[str, ...] = (*SOLVER_FIELDS, "integrator", "contacts")
"""The fields of `Config` that change a Brax task's MuJoCo model from Brax's."""


def physics_settings(cfg: Config) -> dict[str, Any]:
    """The `PHYSICS_FIELDS` of `cfg` set away from their defaults (field name -> value): what a
    run's records (an exported expert, its evaluation) add to name the physics it ran, and what
    `driver.expert_config` reads back."""
    return {f: getattr(cfg, f) for f in PHYSICS_FIELDS if getattr(cfg, f) != physics_default(f)}


def physics_default(name: str) -> Any:
    """The default of the `PHYSICS_FIELDS` field `name`: Brax's own model."""
    return FIELDS[name].default


ENVS: tuple[str, ...] = tuple(TASKS)
"""Tasks, one module each in `arld_jax.tasks` (Brax's halfcheetah, hopper, walker2d, ant, and the
pure-JAX stand-ins of the tests)."""
PHYSICS: dict[str, str] = {
    "mjx": "MuJoCo-MJX through Brax",
    "mujoco": "MuJoCo's C engine",
    "generalized": "Brax's generalized pipeline",
    "positional": "Brax's positional pipeline",
    "spring": "Brax's spring pipeline",
}
"""Each physics of `Config.backend`, in words (the line a run starts with)."""
MUJOCO_BACKENDS: tuple[str, ...] = ("mjx", "mujoco")
"""The physics that run MuJoCo's solver (its options: `Config.solver_iterations`)."""
BACKENDS: tuple[str, ...] = ("auto", *PHYSICS)
REDUCTIONS: tuple[str, ...] = ("mean", "max", "sum")
WINDOW_RECORDS: tuple[str, ...] = ("all", "agent")
MATMUL_DTYPES: tuple[str, ...] = ("float32", "bfloat16")


@dataclass(frozen=True)
class Config(*AGENT_OPTIONS):
    """Everything that defines a run. Defaults follow the paper (appendix A.1) where it says something.

    The fields below are the loop's; each agent family's own fields (TD3's smoothing noise,
    Bootstrapped TD3's heads, SAC's log-std clips) come from its module (`AgentSpec.options`)."""

    # ---- environment (static) ----
    env_name: str = "halfcheetah"
    """The task, one of `ENVS` (a module each in `arld_jax.tasks`): Brax's 'halfcheetah' (never
    falls), 'hopper', 'walker2d', 'ant', 'ant_contact' (Ant observing and paying for its contact
    forces, as Gymnasium's Ant-v5), 'humanoid' (a fall ends the episode), or the cheap
    pure-JAX stand-ins of the tests: 'toy' (never ends early) and 'toy_fall' (ends when the action
    strays far from the target)."""
    backend: str = "auto"
    """Physics of a Brax task. 'auto' (the default) takes the fastest for the machine when the
    Config is built, so config.json names the physics that ran: 'mujoco' when jax computes on the
    CPU, 'mjx' on an accelerator. 'mjx': MuJoCo-MJX through Brax, stepped on the device. 'mujoco':
    MuJoCo's C engine on the host through `jax.pure_callback`, Brax's same task, model, options,
    observation, reward and health rule, a step many times cheaper than MJX's on CPU
    (`arld_jax.physics`). Or one of Brax's own pipelines ('generalized', 'positional', 'spring').
    The toy tasks ignore it."""
    solver_iterations: int = 0
    """Physics of a Brax task on 'mjx' or 'mujoco': iterations of MuJoCo's constraint solver per
    physics step (`opt.iterations`). 0 (the default) = the task's own, as Brax defines it: 4 from
    Brax's XMLs (HalfCheetah, Hopper, Walker2d), 1 for Ant and Humanoid, where Brax sets Newton's
    solver with 1 iteration and 4 line searches for MJX's speed. MuJoCo's default, the one
    Gymnasium's v5 tasks run, is 100 (the solver stops earlier once it meets its tolerance)."""
    solver_ls_iterations: int = 0
    """Physics of a Brax task on 'mjx' or 'mujoco': line-search iterations of the solver
    (`opt.ls_iterations`). 0 (the default) = the task's own: 50 from Brax's XMLs, 4 for Ant and
    Humanoid. MuJoCo's default (Gymnasium's v5 tasks) is 50."""
    integrator: str = "task"
    """Physics of a Brax task on 'mjx' or 'mujoco': MuJoCo's integrator (`opt.integrator`), one of
    `INTEGRATORS`. 'task' (the default): the task's own, semi-implicit Euler in every Brax XML
    (Brax removed the RK4 of Hopper's, Walker2d's and Humanoid's MuJoCo XMLs). 'rk4': 4th-order
    Runge-Kutta, as Gymnasium's v5 XMLs set (Ant, Hopper, Walker2d, Humanoid); it evaluates the
    dynamics four times per physics step, at the same timestep."""
    contacts: str = "task"
    """Physics of a Brax task on 'mjx' or 'mujoco': which geoms collide with the floor. 'task' (the
    default): Brax's, whose XMLs let only a few geoms touch the floor (Ant:
    its four foot spheres, so its torso and legs pass through the floor; Hopper: its foot;
    Walker2d: torso and feet; HalfCheetah: head, thighs and feet). 'all': every geom of the body
    collides with the floor (not with the body's other geoms), as in Gymnasium's v5 XMLs, where an
    ant resting on its torso or legs stands at the height of its torso's radius, not below it.
    With 'all' the two backends part where a capsule touches the floor (`arld_jax.physics`)."""
    num_envs: int = 1
    """Environments stepped in parallel per run (vmapped). The paper uses one."""
    env_max_batch: int = 0
    """Performance only: when runs are vmapped, their runs x num_envs envs are stepped in chunks of
    at most this many, one chunk after another (`envs.limit_batch`), because MJX on CPU steps one
    batch of 80 envs at about half the total rate of five batches of 16. 0 = auto (16 on CPU, no
    limit on GPU/TPU), -1 = no limit. The physics of each env is the same either way. The 'mujoco'
    backend is never chunked (its host loop costs the same per env at any batch)."""
    episode_length: int = 1000
    """Steps per episode (time limit). HalfCheetah never terminates, so every episode has this length."""
    total_env_steps: int = 100_000
    """Environment steps per run, summed over the parallel envs (the paper's 'timesteps': 400k)."""
    learning_starts: int = 5_000
    """Env steps of uniform-random agent actions before gradient updates start (SAC warm-up)."""
    eval_every: int = 5_000
    """Env steps between evaluations of the deterministic policy tanh(mu) (paper: 5,000)."""
    num_eval_episodes: int = 5
    """Episodes per evaluation, run in parallel (each from a fresh random initial state)."""

    # ---- agent (static: shapes and structure) ----
    agent: str = "sac"
    """Agent family, one of `AGENT_NAMES` (a module each in `arld_jax.agents`): 'sac' is SAC, 'td3'
    TD3 (Fujimoto et al. 2018), 'boot_td3' Bootstrapped TD3 (K heads, Osband et al. 2016). With
    uncertainty 'extrinsic', a family with a noisy variant trains it (Noisy SAC, paper 3.1)."""
    hidden_sizes: tuple[int, ...] = (256, 256)
    """Hidden layer widths of actor and critics (paper A.1: two layers of 256, ReLU)."""
    batch_size: int = 256
    """Minibatch size of one gradient update."""
    replay_capacity: int = 1_000_000
    """Prioritized replay capacity in transitions (ring buffer)."""
    updates_per_env_step: float = 1.0
    """Gradient updates per env step (paper: 1). With num_envs envs, num_envs * this updates run per
    iteration; the product must be a whole number."""
    update_before_add: bool = False
    """Run an iteration's gradient updates on the replay as it was before that iteration's
    transitions are added (they become sampleable one iteration later), so the updates need not
    wait for the env step. Off: on a 2-core CPU it is slower at 1 env (`python -m benchmarks.bench
    --only overlap`, benchmarks/README.md); an accelerator may overlap the two."""
    noisy_sigma_init: float = 0.017
    """Initial sigma_w, sigma_b of the Noisy SAC mean head (Fortunato et al. 2017, independent noise)."""
    noisy_runs: bool = True
    """Whether the compiled program may hold a noisy agent (Noisy SAC / Noisy TD3: a run with
    uncertainty 'extrinsic'). False builds the actor's mean head without its weight-noise draws: the
    same parameters and, since plain runs scale that noise by 0, bit-identical results, in about an
    eighth less update time on the 2-core CPU (benchmarks/README.md, "Brax's SAC trainer against
    arld_jax, side by side"). Sweeps set it for their program (`Sweep.program_config`: False when
    no run is noisy); False with uncertainty 'extrinsic' is an error."""
    matmul_dtype: str = "float32"
    """Dtype of matmul inputs in the MLPs ('bfloat16' uses AMX/tensor cores; accumulation stays f32)."""

    # ---- SAC (sweepable values) ----
    actor_lr: float = 3e-4
    """Adam learning rate of the actor (Haarnoja et al. 2018)."""
    critic_lr: float = 3e-4
    """Adam learning rate of the twin critics."""
    alpha_lr: float = 3e-4
    """Adam learning rate of log(alpha) when autotune_alpha is on."""
    gamma: float = 0.99
    """Discount factor."""
    tau: float = 0.005
    """Polyak averaging weight of the target critics."""
    reward_scale: float = 5.0
    """Multiplier on rewards in the critic target. Paper A.1 fixes alpha = 0.2 and tunes the reward
    scale per environment; 5 is what SAC's authors used for HalfCheetah (Haarnoja et al. 2018a)
    and what our ablation chose: at 1 the policy stays near maximum entropy for ~50k steps and
    learns to run upside down (experiments/sac_ablation, experiments/README.md)."""
    init_alpha: float = 0.2
    """Entropy temperature (fixed, paper A.1) or its initial value when autotuned."""
    autotune_alpha: bool = False
    """Tune the temperature alpha towards the target entropy -dim(A) (Haarnoja et al. 2018b, eq. 18)
    instead of keeping it at init_alpha (the paper, A.1, fixes 0.2). Sweepable."""

    # ---- prioritized replay (paper A.1, Schaul et al. 2015, Vecerik et al. 2017) ----
    per_alpha: float = 0.6
    """Priority exponent: P(i) = p_i^alpha / sum_k p_k^alpha (static)."""
    per_beta0: float = 0.4
    """Initial importance-sampling exponent, annealed linearly to 1 over the run (static)."""
    per_eps: float = 1e-6
    """epsilon in p = delta^2 + epsilon + epsilon_d (static)."""
    eps_demo: float = 1.0
    """epsilon_d: priority bonus of demonstration transitions (sweepable)."""

    # ---- ARLD (sweepable values) ----
    strategy: str = "none"
    """Query strategy: 'none' (SAC), 'greedy' (GQSAC), 'bernoulli' (BQSAC), 'active' (AQSAC)."""
    uncertainty: str = "intrinsic"
    """'intrinsic' (SAC, u = sigma_theta(s)) or 'extrinsic' (Noisy SAC, u = Var[perturbed mean])."""
    query_prob: float = 0.1
    """b: query probability of the Bernoulli strategy (paper best: 0.1 for SAC, 0.4 for Noisy SAC)."""
    t_query: float = 0.1
    """Proportion threshold of the active strategy: query when u is in the top t_query fraction of the
    reference window (paper best: 0.1)."""
    demo_steps: int = 1
    """C: after a query the expert acts for C consecutive steps, capped at the episode end."""
    budget: int = 10_000
    """Demonstration budget in demonstrated env steps per run (paper: 10,000)."""
    seed: int = 0
    """Random seed of the run."""

    # ---- ARLD (static) ----
    window_size: int = 5_000
    """N_r: reference window of recent uncertainties for the active strategy (paper: 5,000)."""
    window_records: str = "all"
    """Which steps enter the reference window: 'all' visited states (default) or only 'agent'-controlled
    ones. See query.py for why 'all' is the default reading."""
    uncertainty_reduce: str = "mean"
    """How a per-action-dimension uncertainty becomes one number: 'mean' (default), 'max' or 'sum'."""
    query_during_warmup: bool = True
    """Allow queries during the random warm-up (the budget is paced from step 0, as in the paper)."""
    expert_path: str | None = None
    """Directory of the expert checkpoint (needed unless every strategy is 'none'). None: the
    expert shipped for the task (`TaskSpec.expert_dir`; HalfCheetah's is experiments/expert), or
    the toy tasks' closed-form expert."""
    expert_stochastic: bool = False
    """Expert samples from its policy instead of acting with tanh(mu)."""

    # ---- recording (static) ----
    traces_per_eval: int = 10
    """Down-sampled points per evaluation period of the uncertainty and budget traces (Figs. 3, 9)."""
    state_sample_size: int = 512
    """Size of the uniform on-device samples of visited and of queried states (Fig. 8)."""

    # ---- bookkeeping ----
    notes: dict[str, Any] = field(default_factory=dict, compare=False, hash=False)
    """Free-form labels carried into results (not used by the trainer)."""

    def __post_init__(self) -> None:
        if self.backend == "auto":  # resolved here, so every record of the run names its physics
            object.__setattr__(self, "backend", auto_backend(jax_platform()))
        validate(self)

    # ---- derived values ----
    @property
    def num_iterations(self) -> int:
        """Loop iterations (each steps every env once)."""
        return self.total_env_steps // self.num_envs

    @property
    def iters_per_eval(self) -> int:
        return self.eval_every // self.num_envs

    @property
    def num_evals(self) -> int:
        return self.total_env_steps // self.eval_every

    @property
    def warmup_iters(self) -> int:
        return math.ceil(self.learning_starts / self.num_envs)

    @property
    def warmup_periods(self) -> int:
        """Evaluation periods holding a warm-up iteration: with fewer (or no) gradient updates they
        run several times faster than the rest, so a time per period is measured apart for them."""
        return math.ceil(self.warmup_iters / self.iters_per_eval)

    @property
    def updates_per_iter(self) -> int:
        return round(self.updates_per_env_step * self.num_envs)

    def replace(self, **changes: Any) -> Config:
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)


FIELDS: dict[str, dataclasses.Field] = {
    f.name: f for f in dataclasses.fields(Config) if f.name != "notes"
}
"""The Config fields that define a run, by name: every one but the free-text `notes`. A command
line sets them and a run directory's identity holds them."""


def field_docs() -> dict[str, str]:
    """Config field -> its docstring (the string literal under each field), from `Config` and the
    agents' option classes it inherits: the one source of `--help`'s field texts."""
    docs: dict[str, str] = {}
    for cls in reversed(Config.__mro__):
        if not dataclasses.is_dataclass(cls):
            continue
        body = ast.parse(textwrap.dedent(inspect.getsource(cls))).body[0].body
        for node, doc in zip(body, body[1:], strict=False):
            if (
                isinstance(node, ast.AnnAssign)
                and isinstance(node.target, ast.Name)
                and isinstance(doc, ast.Expr)
                and isinstance(doc.value, ast.Constant)
                and isinstance(doc.value.value, str)
            ):
                docs[node.target.id] = " ".join(doc.value.value.split())
    return docs


@dataclass(frozen=True)
class Sweepable:
    """How a sweepable Config field travels into the compiled program (one row of `SWEEPABLES`)."""

    hparam: str  # the HParams field that carries it
    dtype: Any  # its device dtype
    encode: Any  # Config value -> number (e.g. a strategy name -> its index)
    strategies: tuple[str, ...] | None = None  # strategies whose runs it can change (None: all)


_QUERYING = tuple(s for s in STRATEGIES if s != "none")
_F32, _I32 = jnp.float32, jnp.int32
SWEEPABLES: dict[str, Sweepable] = {
    "strategy": Sweepable("strategy", _I32, STRATEGIES.index),
    "uncertainty": Sweepable("noisy", _F32, lambda u: float(u == "extrinsic")),
    "query_prob": Sweepable("query_prob", _F32, float, ("bernoulli",)),
    "t_query": Sweepable("t_query", _F32, float, ("active",)),
    "demo_steps": Sweepable("demo_steps", _I32, int, _QUERYING),
    "budget": Sweepable("budget", _I32, int, _QUERYING),
    "eps_demo": Sweepable("eps_demo", _F32, float, _QUERYING),
    "actor_lr": Sweepable("actor_lr", _F32, float),
    "critic_lr": Sweepable("critic_lr", _F32, float),
    "alpha_lr": Sweepable("alpha_lr", _F32, float),
    "gamma": Sweepable("gamma", _F32, float),
    "tau": Sweepable("tau", _F32, float),
    "reward_scale": Sweepable("reward_scale", _F32, float),
    "init_alpha": Sweepable("init_alpha", _F32, float),
    "autotune_alpha": Sweepable("autotune_alpha", _F32, float),
}
"""The one list of sweepable Config fields: the HParams field each becomes, and (pruning) which
strategies it can change. The seed is sweepable too but travels as the PRNG key."""

SWEEPABLE: tuple[str, ...] = (*SWEEPABLES, "seed")
"""Config fields that one compiled program can vmap over (values, not shapes)."""


HParams = flax.struct.dataclass(
    type(
        "HParams",
        (),
        {
            "__annotations__": {spec.hparam: "jax.Array" for spec in SWEEPABLES.values()},
            "__doc__": """The sweepable values of one run as device arrays (a leading axis when
    sweeping): one field per row of `SWEEPABLES`, named by its `hparam` (strategy: int32 index into
    STRATEGIES; noisy: 1.0 = the noisy variant, extrinsic uncertainty; demo_steps, budget: int32;
    autotune_alpha: 1.0 = tune alpha, eq. 18; the rest float32).""",
            "__module__": __name__,
        },
    )
)


def hparams_from_config(cfg: Config) -> HParams:
    """The sweepable values of `cfg` as scalar arrays (the seed travels separately, as a PRNG key)."""
    return HParams(
        **{
            s.hparam: jnp.asarray(s.encode(getattr(cfg, name)), s.dtype)
            for name, s in SWEEPABLES.items()
        }
    )


# ---------------------------------------------------------------- validation


def validate(cfg: Config) -> None:
    """Raise ValueError naming the first invalid field of `cfg` (called on construction)."""
    checks.int_at_least(
        cfg,
        (
            "num_envs",
            "episode_length",
            "total_env_steps",
            "eval_every",
            "num_eval_episodes",
            "batch_size",
            "replay_capacity",
            "window_size",
            "traces_per_eval",
            "state_sample_size",
        ),
        1,
    )
    if not isinstance(cfg.env_max_batch, int) or cfg.env_max_batch < -1:
        checks.fail(
            "env_max_batch", cfg.env_max_batch, "an integer >= 1, 0 (auto) or -1 (no limit)"
        )
    checks.choice(cfg, "agent", AGENT_NAMES)
    checks.choice(cfg, "env_name", ENVS)
    checks.choice(cfg, "backend", BACKENDS)
    for name in SOLVER_FIELDS:
        value = getattr(cfg, name)
        if not checks.is_int(value) or value < 0:
            checks.fail(name, value, "an integer >= 1, or 0 (the task's own)")
    checks.choice(cfg, "integrator", tuple(INTEGRATORS))
    checks.choice(cfg, "contacts", tuple(CONTACTS))
    runs_mujoco = TASKS[cfg.env_name].brax_name is not None and cfg.backend in MUJOCO_BACKENDS
    for name, value in physics_settings(cfg).items():
        if not runs_mujoco:
            checks.fail(
                name,
                value,
                f"{physics_default(name)!r} with env_name {cfg.env_name!r} and backend "
                f"{cfg.backend!r} (MuJoCo's model options apply to a Brax task on "
                f"{' or '.join(map(repr, MUJOCO_BACKENDS))})",
            )
    if TASKS[cfg.env_name].contact_forces and cfg.backend not in ("auto", *MUJOCO_BACKENDS):
        checks.fail(
            "backend",
            cfg.backend,
            f"{' or '.join(map(repr, MUJOCO_BACKENDS))} with env_name {cfg.env_name!r} (its "
            "contact forces are computed by MuJoCo; Brax's own pipelines have none)",
        )
    checks.choice(cfg, "strategy", STRATEGIES)
    checks.choice(cfg, "uncertainty", UNCERTAINTIES)
    checks.choice(cfg, "uncertainty_reduce", REDUCTIONS)
    checks.choice(cfg, "window_records", WINDOW_RECORDS)
    checks.choice(cfg, "matmul_dtype", MATMUL_DTYPES)
    if not cfg.hidden_sizes or any(
        not isinstance(h, int) or isinstance(h, bool) or h < 1 for h in cfg.hidden_sizes
    ):
        checks.fail("hidden_sizes", cfg.hidden_sizes, "a non-empty tuple of integers >= 1")
    if cfg.batch_size > cfg.replay_capacity:
        checks.fail("batch_size", cfg.batch_size, f"<= replay_capacity ({cfg.replay_capacity})")
    if cfg.window_size < cfg.num_envs:
        checks.fail("window_size", cfg.window_size, f">= num_envs ({cfg.num_envs})")
    if cfg.num_envs > cfg.replay_capacity:
        checks.fail("num_envs", cfg.num_envs, f"<= replay_capacity ({cfg.replay_capacity})")
    if cfg.eval_every % cfg.num_envs:
        checks.fail("eval_every", cfg.eval_every, f"a multiple of num_envs ({cfg.num_envs})")
    if cfg.total_env_steps % cfg.eval_every:
        checks.fail(
            "total_env_steps", cfg.total_env_steps, f"a multiple of eval_every ({cfg.eval_every})"
        )
    if cfg.iters_per_eval % cfg.traces_per_eval:
        checks.fail(
            "traces_per_eval",
            cfg.traces_per_eval,
            f"a divisor of eval_every / num_envs ({cfg.iters_per_eval})",
        )
    if not isinstance(cfg.learning_starts, int) or cfg.learning_starts < 0:
        checks.fail("learning_starts", cfg.learning_starts, "an integer >= 0")
    if cfg.learning_starts >= cfg.total_env_steps:
        checks.fail(
            "learning_starts", cfg.learning_starts, f"< total_env_steps ({cfg.total_env_steps})"
        )
    upi = cfg.updates_per_env_step * cfg.num_envs
    if cfg.updates_per_env_step <= 0 or abs(upi - round(upi)) > 1e-9:
        checks.fail(
            "updates_per_env_step",
            cfg.updates_per_env_step,
            f"> 0 with updates_per_env_step * num_envs ({cfg.num_envs}) a whole number",
        )
    if not cfg.noisy_sigma_init >= 0:
        checks.fail("noisy_sigma_init", cfg.noisy_sigma_init, ">= 0")
    if not isinstance(cfg.noisy_runs, bool):
        checks.fail("noisy_runs", cfg.noisy_runs, "True or False")
    if not cfg.noisy_runs and cfg.uncertainty == "extrinsic" and cfg.agent in NOISY_AGENTS:
        checks.fail(
            "noisy_runs",
            cfg.noisy_runs,
            f"True when uncertainty is 'extrinsic' (agent {cfg.agent!r} is then its noisy variant, "
            "whose mean head draws weight noise)",
        )
    for name in ("actor_lr", "critic_lr", "alpha_lr", "reward_scale", "init_alpha"):
        if not getattr(cfg, name) > 0:
            checks.fail(name, getattr(cfg, name), "> 0")
    if not 0 <= cfg.gamma < 1:
        checks.fail("gamma", cfg.gamma, "0 <= gamma < 1")
    if not 0 < cfg.tau <= 1:
        checks.fail("tau", cfg.tau, "0 < tau <= 1")
    if not cfg.per_alpha >= 0:
        checks.fail("per_alpha", cfg.per_alpha, ">= 0")
    if not 0 <= cfg.per_beta0 <= 1:
        checks.fail("per_beta0", cfg.per_beta0, "0 <= per_beta0 <= 1")
    if not cfg.per_eps > 0:
        checks.fail("per_eps", cfg.per_eps, "> 0")
    if not cfg.eps_demo >= 0:
        checks.fail("eps_demo", cfg.eps_demo, ">= 0")
    if not 0 <= cfg.query_prob <= 1:
        checks.fail("query_prob", cfg.query_prob, "0 <= b <= 1")
    if not 0 < cfg.t_query <= 1:
        checks.fail("t_query", cfg.t_query, "0 < t_query <= 1")
    if not isinstance(cfg.demo_steps, int) or cfg.demo_steps < 1:
        checks.fail("demo_steps", cfg.demo_steps, "an integer C >= 1")
    if not isinstance(cfg.budget, int) or cfg.budget < 0:
        checks.fail("budget", cfg.budget, "an integer >= 0")
    if not isinstance(cfg.seed, int) or cfg.seed < 0:
        checks.fail("seed", cfg.seed, "an integer >= 0")
    for spec in REGISTRY.values():
        spec.check(cfg)


# ---------------------------------------------------------------- presets


def tiny(**overrides: Any) -> Config:
    """A seconds-long run on the pure-JAX toy env, for tests."""
    base = dict(
        env_name="toy",
        num_envs=2,
        episode_length=50,
        total_env_steps=2_000,
        learning_starts=200,
        eval_every=500,
        num_eval_episodes=4,
        hidden_sizes=(32, 32),
        batch_size=32,
        replay_capacity=2_000,
        window_size=50,
        traces_per_eval=5,
        state_sample_size=32,
        budget=200,
        reward_scale=1.0,  # the default 5 is HalfCheetah's tuning; the toy env's rewards are in [-1, 1]
    )
    base.update(overrides)
    return Config(**base)


def halfcheetah(**overrides: Any) -> Config:
    """Plain SAC on MJX HalfCheetah, paper network and hyperparameters, 100k env steps.

    MJX, not 'auto': the `sac` preset's and the shipped expert's committed runs (experiments/
    sac_100k, sac_ablation, expert/training) used it, and their commands must reproduce them."""
    base: dict[str, Any] = dict(replay_capacity=100_000, backend="mjx")
    base.update(overrides)
    return Config(**base)


def paper(**overrides: Any) -> Config:
    """The paper's protocol (appendix A.1): 400k steps, 1 env, budget 10k, N_r 5k, eval every 5k.

    Physics 'auto': MJX on the accelerator a run of this length wants, the C engine on a CPU."""
    base: dict[str, Any] = dict(
        total_env_steps=400_000, replay_capacity=400_000, num_eval_episodes=10
    )  # budget 10k, N_r 5k, eval every 5k and 1 env are the defaults
    base.update(overrides)
    return Config(**base)


PRESETS = {"tiny": tiny, "halfcheetah": halfcheetah, "paper": paper}
"""Base configs; the named sweeps of `arld_jax.sweep.SWEEP_PRESETS` start from these."""
