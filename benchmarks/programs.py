"""The compiled programs the benchmark times, shared by its sections and scripts.

Each builds what the driver builds (`compile.compiler_options()`, `compile.jit_chunk`), at the sizes
given: the matmul chain, the env rollout, the update alone, the trainer's periods and the replay's
work alone.
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp

from arld_jax.agents import Agent, make_agent
from arld_jax.compile import compiler_options, jit_chunk, over_runs
from arld_jax.config import Config, hparams_from_config
from arld_jax.envs import Env
from arld_jax.replay import PrioritizedReplay
from arld_jax.train import Trainer
from arld_jax.types import Transition, example_transition
from benchmarks.harness import block, summarize

# HalfCheetah's sizes; the update-only and FLOP figures use them even when the env is skipped.
HC_OBS_DIM, HC_ACTION_DIM = 17, 6
PAPER_HIDDEN, PAPER_BATCH = (256, 256), 256


@dataclass(frozen=True)
class Sizes:
    """How much work each section does (full run or --quick)."""

    matmul_steps: int  # matmuls in one scanned chain
    repeats: int  # timed calls per measurement (after one warm-up call)
    env_counts: tuple[int, ...]  # parallel envs of the env-only section
    env_steps: int  # scanned env steps per env-only call
    updates: int  # scanned SAC updates per update-only call
    period_env_steps: int  # env steps in one trainer period (eval_every)
    timed_periods: int  # trainer periods timed after the warm-up period
    seed_counts: tuple[int, ...]  # vmapped seeds of the seeds section
    trainer_hidden: tuple[int, ...]  # network of the trainer sections
    trainer_batch: int
    trainer_capacity: int
    toy_episode_length: int


FULL = Sizes(
    matmul_steps=1000,
    repeats=5,
    env_counts=(1, 16),
    env_steps=200,
    updates=100,
    period_env_steps=2000,
    timed_periods=2,
    seed_counts=(1, 2, 4, 8),
    trainer_hidden=PAPER_HIDDEN,
    trainer_batch=PAPER_BATCH,
    trainer_capacity=100_000,
    toy_episode_length=1000,
)


QUICK = Sizes(
    matmul_steps=50,
    repeats=2,
    env_counts=(1,),  # a single MJX compile
    env_steps=20,
    updates=10,
    period_env_steps=160,
    timed_periods=1,
    seed_counts=(1, 2),
    trainer_hidden=(64, 64),
    trainer_batch=64,
    trainer_capacity=10_000,
    toy_episode_length=100,
)


PLAIN_SAC: dict[str, Any] = dict(noisy_runs=False)
"""Every program benchmarked here is plain SAC, built as the driver builds a sweep without a Noisy
SAC run (`Sweep.program_config`: no actor weight-noise draws). The update section also times the
program that draws them (a sweep with a Noisy SAC cell)."""


PAPER_UPDATE = Config(hidden_sizes=PAPER_HIDDEN, batch_size=PAPER_BATCH, **PLAIN_SAC)
"""The update every update-only figure times: B 256, 2x256, f32, plain SAC (HalfCheetah's shapes
come with HC_OBS_DIM, HC_ACTION_DIM)."""


def random_batch(key: jax.Array, batch: int, obs_dim: int, action_dim: int) -> Transition:
    """A fixed random minibatch for the update-only measurement."""
    k_obs, k_act, k_rew, k_next = jax.random.split(key, 4)
    return Transition(
        obs=jax.random.normal(k_obs, (batch, obs_dim)),
        action=jax.random.uniform(k_act, (batch, action_dim), minval=-1.0, maxval=1.0),
        reward=jax.random.normal(k_rew, (batch,)),
        next_obs=jax.random.normal(k_next, (batch, obs_dim)),
        terminated=jnp.zeros(batch),
        is_demo=jnp.zeros(batch),
    )


def agent_and_inputs(
    cfg: Config, obs_dim: int, action_dim: int
) -> tuple[Agent, Any, Transition, jax.Array, Any]:
    """An agent of `cfg`, its initial state, a fixed random batch, unit IS weights and hparams."""
    hp = hparams_from_config(cfg)
    agent = make_agent(cfg, obs_dim, action_dim)
    k_init, k_batch = jax.random.split(jax.random.key(0))
    state = agent.init(k_init, hp)
    batch = random_batch(k_batch, cfg.batch_size, obs_dim, action_dim)
    return agent, state, batch, jnp.ones(cfg.batch_size), hp


def matmul_chain(steps: int, dtype: jnp.dtype) -> Callable[..., jax.Array]:
    """Jitted lax.scan of `steps` matmuls x <- tanh(x @ w), [E,256,256] @ [E,256,256].

    Inputs in `dtype`, accumulation in f32 (`preferred_element_type`). The tanh keeps values in
    range (no inf, no denormals) for any chain length; it costs a few percent of the matmul and is
    not counted, so the GFLOP/s are slightly conservative."""

    def chain(x: jax.Array, w: jax.Array) -> jax.Array:
        def body(x: jax.Array, _: None) -> tuple[jax.Array, None]:
            y = jnp.einsum("eij,ejk->eik", x, w, preferred_element_type=jnp.float32)
            return jnp.tanh(y).astype(dtype), None

        x, _ = jax.lax.scan(body, x, None, length=steps)
        return x

    return jax.jit(chain)


def matmul_call(
    steps: int, ensembles: int, dtype: jnp.dtype, width: int = 256
) -> tuple[Callable[[], jax.Array], int]:
    """One call of a chain of `steps` matmuls on fixed inputs, and its FLOPs (2 * width^3 per
    matmul per member)."""
    k_x, k_w = jax.random.split(jax.random.key(0))
    shape = (ensembles, width, width)
    x = jax.random.normal(k_x, shape).astype(dtype)
    w = (1.5 / math.sqrt(width) * jax.random.normal(k_w, shape)).astype(dtype)
    chain = matmul_chain(steps, dtype)
    return (lambda: chain(x, w)), 2 * width**3 * ensembles * steps


def env_rollout(env: Env, num_envs: int, steps: int) -> Callable[[jax.Array], jax.Array]:
    """Jitted reset, then a lax.scan of `steps` env steps with uniform random actions in [-1, 1].

    The reset sits in the same program so MJX compiles once (an MJX compile takes minutes); it
    costs about one step, i.e. <= 1/steps of a call."""

    def rollout(key: jax.Array) -> jax.Array:
        k_reset, k_steps = jax.random.split(key)

        def body(s: Any, k: jax.Array) -> tuple[Any, jax.Array]:
            a = jax.random.uniform(k, (num_envs, env.action_dim), minval=-1.0, maxval=1.0)
            s = env.step(s, a)
            return s, jnp.sum(s.reward)

        state = env.reset(k_reset, num_envs)
        _, rewards = jax.lax.scan(body, state, jax.random.split(k_steps, steps))
        return jnp.sum(rewards)

    return jax.jit(rollout, compiler_options=compiler_options())


def env_config(env_name: str, num_envs: int, backend: str = "mjx") -> Config:
    """A valid Config with `num_envs` envs (eval_every must be a multiple of num_envs, so the
    default Config(num_envs=16) is rejected; only env_name, backend and num_envs matter to
    make_env)."""
    period = 1000 * num_envs
    return Config(
        env_name=env_name,
        backend=backend,
        num_envs=num_envs,
        eval_every=period,
        total_env_steps=10 * period,
    )


def update_scan(
    agent: Agent, num_updates: int, vmapped: bool = False, extra_options: dict | None = None
) -> Callable[..., Any]:
    """Jitted lax.scan of `num_updates` SAC updates on one fixed batch; `vmapped`: over agents
    (every input with a leading seed axis), as in a seed sweep.
    `extra_options` are XLA options added to `compiler_options()` (`benchmarks.ab_xla_options`)."""

    def run(state: Any, batch: Transition, weights: jax.Array, hp: Any, key: jax.Array) -> Any:
        def body(s: Any, k: jax.Array) -> tuple[Any, jax.Array]:
            s, _, metrics = agent.update(s, batch, weights, jnp.arange(weights.shape[0]), hp, k)
            return s, metrics.critic_loss

        return jax.lax.scan(body, state, jax.random.split(key, num_updates))

    options = compiler_options() | (extra_options or {})
    return jax.jit(jax.vmap(run) if vmapped else run, compiler_options=options)


def update_call(
    cfg: Config,
    obs_dim: int,
    action_dim: int,
    num_updates: int,
    num_seeds: int = 1,
    extra_options: dict | None = None,
) -> tuple[Callable[[], Any], Any]:
    """The update-alone program of `cfg` (`update_scan`, compiled) and a call of it that continues
    from the last call's agents. `num_seeds` > 1 vmaps it over that many agents, one program as in
    a seed sweep (1: the unvmapped single-run program, as `compile.over_runs` runs one seed); every
    agent starts from the same state and batch, each with its own key."""
    agent, state, batch, weights, hp = agent_and_inputs(cfg, obs_dim, action_dim)
    key = jax.random.key(3)
    if num_seeds > 1:
        seeds = lambda x: jnp.broadcast_to(x, (num_seeds, *x.shape))
        state, batch, weights, hp = jax.tree.map(seeds, (state, batch, weights, hp))
        key = jax.random.split(key, num_seeds)
    run = update_scan(agent, num_updates, num_seeds > 1, extra_options)
    compiled = run.lower(state, batch, weights, hp, key).compile()
    holder = {"state": state}

    def call() -> Any:
        holder["state"], losses = compiled(holder["state"], batch, weights, hp, key)
        return losses

    return call, compiled


def trainer_config(
    sizes: Sizes, toy: bool, num_envs: int, update_before_add: bool = False
) -> Config:
    """One warm-up period plus `timed_periods` timed ones, 1 update per env step, 1 eval episode.

    The random warm-up (learning_starts = half a period) lies inside the first period, so every
    timed period is pure training."""
    period = sizes.period_env_steps
    iters_per_eval = period // num_envs
    fields: dict[str, Any] = dict(
        num_envs=num_envs,
        total_env_steps=(1 + sizes.timed_periods) * period,
        eval_every=period,
        learning_starts=period // 2,
        replay_capacity=sizes.trainer_capacity,
        num_eval_episodes=1,
        traces_per_eval=math.gcd(10, iters_per_eval),
        updates_per_env_step=1.0,
        hidden_sizes=sizes.trainer_hidden,
        batch_size=sizes.trainer_batch,
        update_before_add=update_before_add,
        **PLAIN_SAC,
    )
    if toy:
        fields |= dict(env_name="toy", episode_length=sizes.toy_episode_length)
    return Config(**fields)


def broadcast_seeds(tree: Any, n: int) -> Any:
    """Give every leaf a leading seed axis of size `n`."""
    return jax.tree.map(lambda x: jnp.broadcast_to(x, (n, *jnp.shape(x))), tree)


def compile_trainer(trainer: Trainer, num_seeds: int) -> tuple[Any, Any, Any, dict[str, float]]:
    """Init and one-period `run_periods` over seeds, jitted as run.py does (`over_runs`, static
    num_periods, donated state). Returns the compiled chunk, state, hparams and the seconds of tracing and
    lowering (`lower_s`, never cached) and of the XLA compile (`compile_s`, cacheable)."""
    cfg = trainer.cfg
    hps = broadcast_seeds(hparams_from_config(cfg), num_seeds)
    keys = jax.random.split(jax.random.key(cfg.seed), num_seeds)
    state = block(jax.jit(over_runs(trainer.init))(keys, hps))
    run = jit_chunk(trainer)
    start = time.perf_counter()
    lowered = run.lower(state, hps, jnp.int32(0), 1)
    lowered_at = time.perf_counter()
    compiled = lowered.compile()
    seconds = {"lower_s": lowered_at - start, "compile_s": time.perf_counter() - lowered_at}
    return compiled, state, hps, seconds


def time_periods(trainer: Trainer, num_seeds: int, max_timed: int) -> dict:
    """Compile, run the warm-up period, then time up to `max_timed` following periods."""
    cfg = trainer.cfg
    compiled, state, hps, seconds = compile_trainer(trainer, num_seeds)
    start = time.perf_counter()
    state, _ = block(compiled(state, hps, jnp.int32(0)))
    warmup_s = time.perf_counter() - start
    times = []
    for p in range(1, min(cfg.num_evals, 1 + max_timed)):
        start = time.perf_counter()
        state, metrics = block(compiled(state, hps, jnp.int32(p)))
        times.append(time.perf_counter() - start)
    period_s = statistics.median(times)
    updates = cfg.iters_per_eval * cfg.updates_per_iter * num_seeds
    return summarize(times) | {
        "num_seeds": num_seeds,
        "num_envs": cfg.num_envs,
        "lower_s": seconds["lower_s"],
        "compile_s": seconds["lower_s"] + seconds["compile_s"],
        "xla_compile_s": seconds["compile_s"],
        "warmup_period_s": warmup_s,
        "env_steps_per_period": cfg.eval_every * num_seeds,
        "updates_per_period": updates,
        "env_steps_per_s": cfg.eval_every * num_seeds / period_s,
        "updates_per_s": updates / period_s,
        "last_eval_return": float(jnp.mean(metrics.eval_return)),
        "_agent_state": jax.tree.map(lambda x: x[0], state.agent),
    }


def replay_scan(
    per: PrioritizedReplay,
    cfg: Config,
    obs_dim: int,
    action_dim: int,
    iters: int,
    num_seeds: int = 0,
) -> tuple[Callable[..., Any], Transition]:
    """Jitted scan of the trainer's replay work: add num_envs items, then updates_per_iter x
    (sample, set priorities from the sampled batch, so the gather is not optimized away).
    With `num_seeds` > 0 every iteration is vmapped over that many buffers (the state then has a
    leading seed axis), as in a seed-vmapped trainer."""
    example = example_transition(obs_dim, action_dim)

    def one_sample(r: Any, k: jax.Array) -> tuple[Any, jax.Array]:
        batch, idx, weights = per.sample(r, k, jnp.float32(0.5))
        touch = batch.reward + batch.obs.sum(-1) + batch.next_obs.sum(-1) + batch.action.sum(-1)
        r = per.set_priorities(r, idx, jnp.abs(touch) + 1e-3)
        return r, jnp.sum(weights)

    def iteration(r: Any, k: jax.Array) -> tuple[Any, jax.Array]:
        k_item, k_sample = jax.random.split(k)
        leaves, treedef = jax.tree.flatten(example)
        ks = jax.random.split(k_item, len(leaves))
        items = [
            jax.random.normal(kk, (cfg.num_envs, *x.shape))
            for kk, x in zip(ks, leaves, strict=True)
        ]
        r = per.add(r, jax.tree.unflatten(treedef, items))
        r, w = jax.lax.scan(one_sample, r, jax.random.split(k_sample, cfg.updates_per_iter))
        return r, jnp.sum(w)

    def step(r: Any, k: jax.Array) -> tuple[Any, jax.Array]:
        if num_seeds:
            return jax.vmap(iteration)(r, jax.random.split(k, num_seeds))
        return iteration(r, k)

    def run(r: Any, key: jax.Array) -> tuple[Any, jax.Array]:
        r, w = jax.lax.scan(step, r, jax.random.split(key, iters))
        return r, jnp.sum(w)

    return jax.jit(run, donate_argnums=0, compiler_options=compiler_options()), example
