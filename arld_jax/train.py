"""The one scanned training loop: `trainer = make_train(cfg, expert)`.

Shape of a run (STYLE.md habit 6):

    train(key, hp) = run_periods(init(key, hp), hp, first_period=0, num_periods=cfg.num_evals)

* a *period* is `eval_every` env steps followed by one evaluation of the deterministic policy;
* an *iteration* steps every env once: act (the agent, or the expert where the query mask is set),
  env step, replay add, `updates_per_iter` gradient steps (after warm-up).

Everything is pure and jit/vmap-friendly: seeds and sweeps are `jax.vmap(train)` over keys and
`HParams`. The iteration and period indices come in as scan inputs that are NOT batched under vmap, so
the branches that skip updates during warm-up (`only_if`) and reset envs at the time limit of a task
that never ends early (`lax.cond`) stay real branches (not selects that would run both sides) when
vmapped over seeds. On a task whose episodes end at a fall (Hopper, Walker2d, Ant), each env ends and
restarts alone (`episode_ends`, `reset_where`). The resumable
driver (`run.py`) calls `run_periods` chunk by chunk with the same compiled program.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import chex
import flax.struct
import jax
import jax.numpy as jnp

from arld_jax import query
from arld_jax.agents import Agent, AgentState, UpdateMetrics, make_agent
from arld_jax.config import Config, HParams
from arld_jax.envs import EnvState, make_env
from arld_jax.evaluate import Evaluation, evaluate_policy
from arld_jax.expert import Expert, ExpertContext
from arld_jax.replay import ReplayState, make_prioritized_replay, priority_from_td
from arld_jax.tasks.base import select_envs
from arld_jax.types import PRNGKey, Transition, example_transition


def only_if(pred: jax.Array, fn: Callable[[Any], Any], carry: Any) -> Any:
    """`fn(carry)` if `pred` else `carry`, as a loop of 0 or 1 trips.

    Used instead of `lax.cond(pred, fn, lambda c: c, carry)` for the big loop-carried state
    (agent and replay): XLA carries a while loop's state in place, whereas a conditional writes
    its results to new buffers that the enclosing scan then copies back, the whole AgentState at
    every iteration (benchmarks/README.md, "Where the trainer's 'other' time is not, and one copy per iteration"). Keep `pred` unbatched under `vmap` (it
    depends only on the iteration index), or the loop becomes a select that runs `fn` always."""
    return jax.lax.fori_loop(0, pred.astype(jnp.int32), lambda _, c: fn(c), carry)


@flax.struct.dataclass
class StateSample:
    """A uniform sample without replacement of a stream of states, kept on device (Fig. 8).

    Algorithm A-Res (Efraimidis & Spirakis 2006) with equal weights: every item draws a random key in
    [0, 1) and the sample keeps the items with the largest keys. Slots with key < 0 are empty."""

    obs: jax.Array  # [K, obs_dim]
    env_step: jax.Array  # [K] i32, when the state was seen
    key: jax.Array  # [K] f32


def init_state_sample(size: int, obs_dim: int) -> StateSample:
    return StateSample(
        obs=jnp.zeros((size, obs_dim)),
        env_step=jnp.zeros((size,), jnp.int32),
        key=jnp.full((size,), -1.0, jnp.float32),
    )


def add_to_state_sample(
    sample: StateSample, rng: PRNGKey, obs: jax.Array, mask: jax.Array, env_step: jax.Array
) -> StateSample:
    """Offer the masked rows of `obs` [n, obs_dim] to the sample."""
    n = obs.shape[0]
    keys = jnp.where(mask, jax.random.uniform(rng, (n,)), -2.0)
    all_keys = jnp.concatenate([sample.key, keys])
    top, idx = jax.lax.top_k(all_keys, sample.key.shape[0])
    all_obs = jnp.concatenate([sample.obs, obs])
    all_steps = jnp.concatenate([sample.env_step, jnp.broadcast_to(env_step, (n,))])
    return StateSample(obs=all_obs[idx], env_step=all_steps[idx], key=top)


@flax.struct.dataclass
class TrainState:
    """Everything a run needs to continue: the complete state that checkpoints save."""

    agent: AgentState
    replay: ReplayState
    env: EnvState
    query: query.QueryState
    episode_return: jax.Array  # [num_envs] running return of the current training episodes
    episode_step: jax.Array  # [num_envs] i32: steps taken in the current training episodes
    visited: StateSample  # uniform sample of visited states
    queried: StateSample  # uniform sample of states where a query started
    key: PRNGKey


@flax.struct.dataclass
class EpisodeEnds:
    """Sums over the training episodes that end at one iteration (several envs may end at once)."""

    count: jax.Array  # i32: episodes that ended
    fell: jax.Array  # i32: of those, ended by a termination
    return_sum: jax.Array  # f32: sum of their returns
    length_sum: jax.Array  # i32: sum of their lengths

    @staticmethod
    def of(done: jax.Array, fell: jax.Array, returns: jax.Array, lengths: jax.Array) -> EpisodeEnds:
        """From per-env [E] arrays: which episodes end (`done`), by a fall, their returns, lengths."""
        return EpisodeEnds(
            count=jnp.sum(done).astype(jnp.int32),
            fell=jnp.sum(done & fell).astype(jnp.int32),
            return_sum=jnp.sum(jnp.where(done, returns, 0.0)),
            length_sum=jnp.sum(jnp.where(done, lengths, 0)).astype(jnp.int32),
        )


def episode_ends(
    terminated: jax.Array, episode_step: jax.Array, length: int
) -> tuple[jax.Array, jax.Array]:
    """Which envs' episodes end after this step [E], and which of them by the time limit alone.

    `episode_step` counts the steps taken before this one. An episode ends by a termination (the
    task's health rule: the critic does not bootstrap, `losses.soft_q_target`) or by truncation at
    `length` steps (a time limit: the critic bootstraps from the true next state, which the replay
    stores). A step that is both is a termination: the state itself ended the episode.
    Returns (done, truncated)."""
    fell = terminated > 0
    truncated = (episode_step + 1 >= length) & ~fell
    return fell | truncated, truncated


def reset_where(done: jax.Array, fresh: EnvState, current: EnvState) -> EnvState:
    """`fresh` for the envs whose episode ended (`done` [E]), `current` for the others."""
    return select_envs(done, fresh, current)


@flax.struct.dataclass
class IterationOutput:
    """Per-iteration scalars, reduced to period metrics and down-sampled traces."""

    uncertainty: jax.Array  # mean u(s) over envs
    sigma: jax.Array  # mean sigma_theta(s) over envs and action dims
    demos_used: jax.Array  # cumulative demonstrated steps
    new_queries: jax.Array  # queries started at this iteration
    episodes: EpisodeEnds  # training episodes that ended at this iteration
    upside_down: jax.Array  # fraction of envs whose state is upside down (the gait)
    learning: jax.Array  # gradient updates ran at this iteration
    update: UpdateMetrics  # mean over this iteration's updates (zeros in warm-up)


@flax.struct.dataclass
class PeriodMetrics:
    """One row per evaluation period (leading axis [num_periods] after a scan)."""

    env_steps: jax.Array  # env steps done at the end of the period
    eval_return: jax.Array  # mean return of the deterministic policy tanh(mu)
    eval_upside_down: jax.Array  # fraction of the evaluation's states that are upside down
    eval_fell: jax.Array  # fraction of the evaluation episodes that ended by a termination (a fall)
    eval_episode_length: jax.Array  # mean length of the evaluation episodes
    train_return: jax.Array  # mean return of training episodes finished in the period (nan if none)
    episodes: jax.Array  # training episodes finished in the period
    fell: jax.Array  # fraction of them that ended by a termination (nan if none finished)
    episode_length: jax.Array  # their mean length in env steps (nan if none finished)
    upside_down: jax.Array  # fraction of the visited training states that are upside down (gait)
    critic_loss: jax.Array
    actor_loss: jax.Array
    alpha: jax.Array
    entropy: jax.Array
    sigma: jax.Array  # mean sigma_theta(s) on visited states
    uncertainty: jax.Array  # mean u(s) on visited states
    demos_used: jax.Array  # cumulative demonstrated steps at the end of the period
    queries: jax.Array  # queries started in the period
    uncertainty_trace: jax.Array  # [traces_per_eval] mean u(s) (Fig. 3)
    demos_trace: jax.Array  # [traces_per_eval] cumulative demonstrations (Fig. 9)


class Trainer(NamedTuple):
    """Pure functions of one run; vmap them over seeds and hyperparameters."""

    init: Callable[[PRNGKey, HParams], TrainState]
    run_periods: Callable[[TrainState, HParams, jax.Array, int], tuple[TrainState, PeriodMetrics]]
    train: Callable[[PRNGKey, HParams], tuple[TrainState, PeriodMetrics]]
    evaluate: Callable[[AgentState, PRNGKey], Evaluation]
    agent: Agent
    cfg: Config
    obs_dim: int
    action_dim: int


def _masked_mean(x: jax.Array, mask: jax.Array) -> jax.Array:
    return jnp.sum(jnp.where(mask, x, 0.0)) / jnp.maximum(jnp.sum(mask), 1)


def make_train(cfg: Config, expert: Expert | None = None) -> Trainer:
    """Build the trainer of `cfg`. Without an expert, no query is ever made (strategy 'none')."""
    env = make_env(cfg)
    agent = make_agent(cfg, env.obs_dim, env.action_dim)
    per = make_prioritized_replay(cfg.replay_capacity, cfg.batch_size, cfg.per_alpha)
    num_envs, length = cfg.num_envs, cfg.episode_length
    has_expert = expert is not None

    def expert_act(obs: jax.Array, key: PRNGKey, context: ExpertContext) -> jax.Array:
        """The expert's actions, asked only when some env of the run is demonstrated (a real
        branch for one run; under vmap a select, which is what a saved policy costs anyway).
        Its parameters are constants closed over, not loop state."""
        zeros = jnp.zeros((obs.shape[0], env.action_dim))
        if expert is None:
            return zeros
        return jax.lax.cond(
            jnp.any(context.is_demo),
            lambda: expert.act(expert.params, obs, key, context).astype(zeros.dtype),
            lambda: zeros,
        )

    def init(key: PRNGKey, hp: HParams) -> TrainState:
        k_agent, k_env, k_run = jax.random.split(key, 3)
        agent_state = agent.init(k_agent, hp)
        example = example_transition(env.obs_dim, env.action_dim)
        return TrainState(
            agent=agent_state,
            replay=per.init(example),
            env=env.reset(k_env, num_envs),
            query=query.init_query_state(num_envs, cfg.window_size),
            episode_return=jnp.zeros(num_envs),
            episode_step=jnp.zeros(num_envs, jnp.int32),
            visited=init_state_sample(cfg.state_sample_size, env.obs_dim),
            queried=init_state_sample(cfg.state_sample_size, env.obs_dim),
            key=k_run,
        )

    def gradient_steps(
        agent_state: AgentState,
        replay: ReplayState,
        key: PRNGKey,
        hp: HParams,
        it: jax.Array,
        warm: jax.Array,
    ) -> tuple[AgentState, ReplayState, UpdateMetrics]:
        """`updates_per_iter` SAC updates from prioritized replay, priorities refreshed after each.

        During warm-up the agent is not updated (only its TD errors are measured, so priorities
        still follow the current critics). Which of the two runs is chosen by `only_if`, a loop of
        0 or 1 trips on the unbatched `warm`, not by a `lax.cond`: see `only_if` for why."""
        # Importance-sampling exponent annealed linearly from beta0 to 1 (Schaul et al. 2015).
        beta = cfg.per_beta0 + (1.0 - cfg.per_beta0) * it / cfg.num_iterations

        def replay_step(update_fn, k_sample, k_update):  # noqa: ANN001, ANN202
            def step(carry):  # noqa: ANN001, ANN202
                agent_state, replay, _ = carry
                batch, indices, weights = per.sample(replay, k_sample, beta)
                agent_state, td, metrics = update_fn(
                    agent_state, batch, weights, indices, hp, k_update
                )
                # Paper A.1 (DDPGfD): p = delta^2 + eps + eps_d for demonstrations.
                priorities = priority_from_td(td, batch.is_demo, cfg.per_eps, hp.eps_demo)
                return agent_state, per.set_priorities(replay, indices, priorities), metrics

            return step

        def one_update(carry, k):  # noqa: ANN001, ANN202
            agent_state, replay = carry
            k_sample, k_update = jax.random.split(k)
            carry = (agent_state, replay, UpdateMetrics.zeros())  # one only_if below writes it
            carry = only_if(~warm, replay_step(agent.update, k_sample, k_update), carry)
            carry = only_if(warm, replay_step(agent.no_update, k_sample, k_update), carry)
            agent_state, replay, metrics = carry
            return (agent_state, replay), metrics

        keys = jax.random.split(key, cfg.updates_per_iter)
        (agent_state, replay), metrics = jax.lax.scan(one_update, (agent_state, replay), keys)
        return agent_state, replay, jax.tree.map(jnp.mean, metrics)

    def iteration(
        state: TrainState, it: jax.Array, hp: HParams
    ) -> tuple[TrainState, IterationOutput]:
        """One env step of every env, then the gradient updates. `it` is the (unbatched) index."""
        key, k_act, k_rand, k_query, k_expert, k_update, k_reset, k_vis, k_qry = jax.random.split(
            state.key, 9
        )
        obs = state.env.obs  # [num_envs, obs_dim]
        warm = it < cfg.warmup_iters
        acting = agent.act(state.agent, obs, k_act, hp)
        agent_action = acting.action
        random_action = jax.random.uniform(k_rand, agent_action.shape, minval=-1.0, maxval=1.0)
        agent_action = jnp.where(warm, random_action, agent_action)

        # Query: per-env mask; the expert's action replaces the agent's where it is set.
        u = acting.uncertainty  # [num_envs]
        allow = has_expert & (cfg.query_during_warmup | ~warm)
        qstate, is_demo, new_query = query.query_step(
            state.query, k_query, u, length - state.episode_step, hp, allow, cfg.window_records
        )
        context = ExpertContext(
            agent_action=agent_action,
            uncertainty=u,
            is_demo=is_demo,
            new_query=new_query,
            demo_remaining=qstate.demo_remaining,
            demos_used=qstate.demos_used,
            budget=hp.budget,
            env_step=it * num_envs,
        )
        expert_action = expert_act(obs, k_expert, context)
        # An expert may hand a query back: a row of NaNs (`query.hand_back`).
        declined = is_demo & jnp.any(jnp.isnan(expert_action), axis=-1)
        qstate, is_demo = query.hand_back(qstate, is_demo, declined)
        action = jnp.where(is_demo[:, None], expert_action, agent_action)
        chex.assert_shape(action, (num_envs, env.action_dim))

        with jax.named_scope("env_step"):  # named scopes label the ops in a profile (also
            next_env = env.step(state.env, action)  # replay_add/_sample/_priorities, in replay.py)
        if expert is not None and expert.observe is not None:
            # A host side effect (a person's page: the states, and the falls): one run only.
            expert.observe(obs, next_env.obs, next_env.terminated > 0, context)
        transition = Transition(
            obs=obs,
            action=action,  # the executed action (the expert's on demonstrated steps)
            reward=next_env.reward,
            next_obs=next_env.obs,  # true next obs, also at the time limit (before any reset)
            terminated=next_env.terminated,  # 1 only at a fall: a time limit keeps bootstrapping
            is_demo=is_demo.astype(jnp.float32),
        )
        # Default: add, then update. `update_before_add`: update on the replay before this
        # iteration's transitions, so the updates do not depend on this env step.
        replay = state.replay if cfg.update_before_add else per.add(state.replay, transition)
        with jax.named_scope("gradient_steps"):
            agent_state, replay, update_metrics = gradient_steps(
                state.agent, replay, k_update, hp, it, warm
            )
        if cfg.update_before_add:
            replay = per.add(replay, transition)

        # Episode ends: by a fall (terminated) or by the time limit (truncated), env by env.
        episode_return = state.episode_return + next_env.reward
        episode_length = state.episode_step + 1
        done, _ = episode_ends(next_env.terminated, state.episode_step, length)
        episodes = EpisodeEnds.of(done, next_env.terminated > 0, episode_return, episode_length)
        # A C-step demonstration ends with its episode; its unused steps return to the budget.
        qstate = query.end_episodes(qstate, done)
        with jax.named_scope("env_reset"):
            if env.can_terminate:
                # Envs end at different steps: the ended ones restart alone from fresh random
                # initial states. `done` is data, so under vmap the reset is computed every step.
                next_env = reset_where(done, env.reset(k_reset, num_envs), next_env)
                any_done = jnp.any(done)
            else:
                # No task-ended episodes (HalfCheetah): all envs reach the time limit together, at
                # an iteration known from its index, so the reset is a real branch, taken once per
                # episode also under vmap (its predicate is unbatched).
                any_done = it % length == length - 1
                next_env = jax.lax.cond(
                    any_done, lambda: env.reset(k_reset, num_envs), lambda: next_env
                )
            # The agent's per-episode state (Bootstrapped TD3's acting head, one per run): drawn
            # anew when an episode of the run ends; in place (only_if).
            agent_state = only_if(
                any_done,
                lambda s: agent.begin_episode(s, jax.random.fold_in(k_reset, 1)),
                agent_state,
            )
        episode_return = jnp.where(done, 0.0, episode_return)
        episode_step = jnp.where(done, 0, episode_length)

        env_step = (it + 1) * num_envs
        all_envs = jnp.ones(num_envs, bool)
        new_state = TrainState(
            agent=agent_state,
            replay=replay,
            env=next_env,
            query=qstate,
            episode_return=episode_return,
            episode_step=episode_step,
            visited=add_to_state_sample(state.visited, k_vis, obs, all_envs, env_step),
            queried=add_to_state_sample(state.queried, k_qry, obs, new_query, env_step),
            key=key,
        )
        out = IterationOutput(
            uncertainty=jnp.mean(u),
            sigma=jnp.mean(acting.sigma),
            demos_used=qstate.demos_used,
            new_queries=jnp.sum(new_query).astype(jnp.int32),
            episodes=episodes,
            upside_down=jnp.mean(env.upside_down(obs)),
            learning=~warm,
            update=update_metrics,
        )
        return new_state, out

    def evaluate(agent_state: AgentState, key: PRNGKey) -> Evaluation:
        """The agent's deterministic policy on fresh episodes (`evaluate.evaluate_policy`)."""
        policy_fn = lambda obs: agent.act_deterministic(agent_state, obs)  # noqa: E731
        return evaluate_policy(env, policy_fn, key, cfg.num_eval_episodes, length)

    def period(state: TrainState, p: jax.Array, hp: HParams) -> tuple[TrainState, PeriodMetrics]:
        """`iters_per_eval` iterations, then one evaluation."""
        its = p * cfg.iters_per_eval + jnp.arange(cfg.iters_per_eval)
        state, out = jax.lax.scan(lambda s, i: iteration(s, i, hp), state, its)
        key, k_eval = jax.random.split(state.key)
        state = state.replace(key=key)
        with jax.named_scope("evaluate"):
            ev = evaluate(state.agent, k_eval)
        traces = cfg.traces_per_eval
        learning = out.learning
        ends = jax.tree.map(jnp.sum, out.episodes)
        per_episode = lambda total: jnp.where(  # noqa: E731
            ends.count > 0, total / jnp.maximum(ends.count, 1), jnp.nan
        )
        metrics = PeriodMetrics(
            env_steps=(p + 1) * cfg.eval_every,
            eval_return=ev.episode_return,
            eval_upside_down=ev.upside_down,
            eval_fell=ev.fell,
            eval_episode_length=ev.length,
            train_return=per_episode(ends.return_sum),
            episodes=ends.count,
            fell=per_episode(ends.fell.astype(jnp.float32)),
            episode_length=per_episode(ends.length_sum.astype(jnp.float32)),
            upside_down=jnp.mean(out.upside_down),
            critic_loss=_masked_mean(out.update.critic_loss, learning),
            actor_loss=_masked_mean(out.update.actor_loss, learning),
            alpha=out.update.alpha[-1],
            entropy=_masked_mean(out.update.entropy, learning),
            sigma=jnp.mean(out.sigma),
            uncertainty=jnp.mean(out.uncertainty),
            demos_used=out.demos_used[-1],
            queries=jnp.sum(out.new_queries),
            uncertainty_trace=jnp.mean(out.uncertainty.reshape(traces, -1), axis=1),
            demos_trace=out.demos_used.reshape(traces, -1)[:, -1],
        )
        return state, metrics

    def run_periods(
        state: TrainState, hp: HParams, first_period: jax.Array, num_periods: int
    ) -> tuple[TrainState, PeriodMetrics]:
        """Periods first_period .. first_period + num_periods - 1 (num_periods is static).

        Under vmap, pass `first_period` unbatched (in_axes=None)."""
        periods = first_period + jnp.arange(num_periods)
        return jax.lax.scan(lambda s, p: period(s, p, hp), state, periods)

    def train(key: PRNGKey, hp: HParams) -> tuple[TrainState, PeriodMetrics]:
        """A whole run: init, then every period in one scan."""
        _check_expert(hp)
        return run_periods(init(key, hp), hp, jnp.int32(0), cfg.num_evals)

    def _check_expert(hp: HParams) -> None:
        if has_expert or isinstance(hp.strategy, jax.core.Tracer):
            return
        if bool(jnp.any(hp.strategy != query.NONE)):
            raise ValueError(
                "A query strategy other than 'none' needs an expert: pass expert=load_expert(...) "
                "to make_train (or set expert_path)."
            )

    return Trainer(
        init=init,
        run_periods=run_periods,
        train=train,
        evaluate=evaluate,
        agent=agent,
        cfg=cfg,
        obs_dim=env.obs_dim,
        action_dim=env.action_dim,
    )
