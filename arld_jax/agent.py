"""SAC / Noisy SAC agent: state, one jitted-friendly update step, acting and the uncertainty measures.

The agent is a bundle of pure functions made by `make_agent(cfg, obs_dim, action_dim)`. Whether it is
plain SAC or Noisy SAC is the sweepable `hp.noisy` (0 or 1), used as the noise scale of the mean head.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import chex
import flax.struct
import jax
import jax.numpy as jnp
import optax

from arld_jax import losses
from arld_jax.config import Config, HParams
from arld_jax.networks import Actor, PolicyOutput, TwinCritic, deterministic_action, sample_action
from arld_jax.types import Params, PRNGKey, Transition


@flax.struct.dataclass
class AgentState:
    """Parameters and optimizer states of one SAC agent."""

    actor_params: Params
    critic_params: Params
    target_critic_params: Params
    log_alpha: jax.Array  # []
    actor_opt: optax.OptState
    critic_opt: optax.OptState
    alpha_opt: optax.OptState


@flax.struct.dataclass
class UpdateMetrics:
    critic_loss: jax.Array
    actor_loss: jax.Array
    alpha: jax.Array
    entropy: jax.Array  # -mean log pi(a|s) on the batch
    td_abs: jax.Array  # mean |delta|


class Agent(NamedTuple):
    """Pure functions of a SAC agent."""

    init: Callable[[PRNGKey, HParams], AgentState]
    policy: Callable[[Params, jax.Array, PRNGKey, jax.Array], PolicyOutput]
    update: Callable[
        [AgentState, Transition, jax.Array, HParams, PRNGKey],
        tuple[AgentState, jax.Array, UpdateMetrics],
    ]
    no_update: Callable[
        [AgentState, Transition, jax.Array, HParams, PRNGKey],
        tuple[AgentState, jax.Array, UpdateMetrics],
    ]
    actor: Actor
    critic: TwinCritic
    obs_dim: int
    action_dim: int


# Adam (Kingma & Ba 2015) as a direction; the sweepable learning rate multiplies it outside optax so
# one compiled program serves any learning-rate grid.
_ADAM = optax.scale_by_adam()


def _adam_step(
    params: Params, grads: Params, opt_state: optax.OptState, lr: jax.Array
) -> tuple[Params, optax.OptState]:
    direction, opt_state = _ADAM.update(grads, opt_state, params)
    params = jax.tree.map(lambda p, d: p - lr * d, params, direction)
    return params, opt_state


def polyak(target: Params, online: Params, tau: jax.Array) -> Params:
    """Target-network soft update theta' <- tau theta + (1 - tau) theta' (Lillicrap et al. 2015)."""
    return jax.tree.map(lambda t, o: (1.0 - tau) * t + tau * o, target, online)


def make_agent(cfg: Config, obs_dim: int, action_dim: int) -> Agent:
    """Build the SAC agent for `cfg` (network sizes and dtype are static)."""
    dtype = jnp.bfloat16 if cfg.matmul_dtype == "bfloat16" else jnp.float32
    actor = Actor(
        action_dim=action_dim,
        hidden_sizes=cfg.hidden_sizes,
        log_std_min=cfg.log_std_min,
        log_std_max=cfg.log_std_max,
        sigma_init=cfg.noisy_sigma_init,
        dtype=dtype,
    )
    critic = TwinCritic(hidden_sizes=cfg.hidden_sizes, dtype=dtype)
    target_entropy = -float(action_dim)  # Haarnoja et al. 2018b: -dim(A)

    def init(key: PRNGKey, hp: HParams) -> AgentState:
        k_actor, k_critic, k_noise = jax.random.split(key, 3)
        obs = jnp.zeros((1, obs_dim))
        action = jnp.zeros((1, action_dim))
        actor_params = actor.init(k_actor, obs, k_noise, jnp.float32(0.0))
        critic_params = critic.init(k_critic, obs, action)
        log_alpha = jnp.log(hp.init_alpha).astype(jnp.float32)
        return AgentState(
            actor_params=actor_params,
            critic_params=critic_params,
            target_critic_params=critic_params,
            log_alpha=log_alpha,
            actor_opt=_ADAM.init(actor_params),
            critic_opt=_ADAM.init(critic_params),
            alpha_opt=_ADAM.init(log_alpha),
        )

    def policy(
        actor_params: Params, obs: jax.Array, key: PRNGKey, noise_scale: jax.Array
    ) -> PolicyOutput:
        return actor.apply(actor_params, obs, key, noise_scale)

    def critic_loss(critic_params, state, batch, weights, hp, key):  # noqa: ANN001, ANN202
        k_noise, k_sample = jax.random.split(key)
        next_policy = policy(state.actor_params, batch.next_obs, k_noise, hp.noisy)
        next_action, next_log_prob = sample_action(next_policy, k_sample)
        next_q = critic.apply(state.target_critic_params, batch.next_obs, next_action)
        alpha = jnp.exp(state.log_alpha)
        target = jax.vmap(losses.soft_q_target, in_axes=(0, 0, 0, 0, None, None, None))(
            batch.reward, batch.terminated, next_q, next_log_prob, alpha, hp.gamma, hp.reward_scale
        )
        q = critic.apply(critic_params, batch.obs, batch.action)
        return losses.critic_loss_from_values(q, target, weights)

    def actor_loss(actor_params, critic_params, log_alpha, obs, hp, key):  # noqa: ANN001, ANN202
        k_noise, k_sample = jax.random.split(key)
        pol = policy(actor_params, obs, k_noise, hp.noisy)
        action, log_prob = sample_action(pol, k_sample)
        q = critic.apply(critic_params, obs, action)
        return losses.actor_loss_from_values(log_prob, q, jnp.exp(log_alpha)), log_prob

    def update(
        state: AgentState, batch: Transition, weights: jax.Array, hp: HParams, key: PRNGKey
    ) -> tuple[AgentState, jax.Array, UpdateMetrics]:
        """One SAC gradient step: critics, then actor (against the new critics), then alpha, then
        Polyak targets. Returns the new state, the TD errors of the batch (for priorities) and metrics."""
        chex.assert_rank(batch.reward, 1)
        chex.assert_equal_shape([batch.reward, weights])
        k_critic, k_actor = jax.random.split(key)
        (c_loss, td), c_grads = jax.value_and_grad(critic_loss, has_aux=True)(
            state.critic_params, state, batch, weights, hp, k_critic
        )
        critic_params, critic_opt = _adam_step(
            state.critic_params, c_grads, state.critic_opt, hp.critic_lr
        )
        (a_loss, log_prob), a_grads = jax.value_and_grad(actor_loss, has_aux=True)(
            state.actor_params, critic_params, state.log_alpha, batch.obs, hp, k_actor
        )
        actor_params, actor_opt = _adam_step(
            state.actor_params, a_grads, state.actor_opt, hp.actor_lr
        )
        log_alpha, alpha_opt = state.log_alpha, state.alpha_opt
        if cfg.autotune_alpha:
            alpha_grad = jax.grad(losses.alpha_loss_from_values)(
                state.log_alpha, log_prob, target_entropy
            )
            log_alpha, alpha_opt = _adam_step(log_alpha, alpha_grad, alpha_opt, hp.alpha_lr)
        new_state = AgentState(
            actor_params=actor_params,
            critic_params=critic_params,
            target_critic_params=polyak(state.target_critic_params, critic_params, hp.tau),
            log_alpha=log_alpha,
            actor_opt=actor_opt,
            critic_opt=critic_opt,
            alpha_opt=alpha_opt,
        )
        metrics = UpdateMetrics(
            critic_loss=c_loss,
            actor_loss=a_loss,
            alpha=jnp.exp(log_alpha),
            entropy=-jnp.mean(log_prob),
            td_abs=jnp.mean(jnp.abs(td)),
        )
        return new_state, td, metrics

    def no_update(
        state: AgentState, batch: Transition, weights: jax.Array, hp: HParams, key: PRNGKey
    ) -> tuple[AgentState, jax.Array, UpdateMetrics]:
        """Same signature as `update`, but only measures the TD errors (warm-up: no learning yet,
        replay priorities still follow the current critics)."""
        _, td = critic_loss(
            state.critic_params, state, batch, weights, hp, jax.random.split(key)[0]
        )
        zero = jnp.zeros(())
        return state, td, UpdateMetrics(zero, zero, jnp.exp(state.log_alpha), zero, zero)

    return Agent(
        init=init,
        policy=policy,
        update=update,
        no_update=no_update,
        actor=actor,
        critic=critic,
        obs_dim=obs_dim,
        action_dim=action_dim,
    )


def reduce_over_actions(x: jax.Array, how: str) -> jax.Array:
    """One uncertainty number per state from a per-action-dimension value ([..., A] -> [...])."""
    return {"mean": jnp.mean, "max": jnp.max, "sum": jnp.sum}[how](x, axis=-1)


def uncertainty(policy: PolicyOutput, noisy: jax.Array, how: str = "mean") -> jax.Array:
    """The agent's uncertainty u(s), [..., A] -> [...].

    Intrinsic (plain SAC, paper 3.2): u(s) = sigma_theta(s), the policy's standard deviation.
    Extrinsic (Noisy SAC, paper 3.1): u(s) = Var[mu~_theta(s)], the analytic variance of the perturbed
    mean. `noisy` (0 or 1, sweepable) picks one; both are cheap, so both are computed.
    """
    intrinsic = reduce_over_actions(jnp.exp(policy.log_std), how)
    extrinsic = reduce_over_actions(policy.mean_var, how)
    return jnp.where(noisy > 0.5, extrinsic, intrinsic)


def act(
    agent: Agent, actor_params: Params, obs: jax.Array, key: PRNGKey, noise_scale: jax.Array
) -> tuple[jax.Array, PolicyOutput]:
    """Sample a training action for a batch of observations; also return the policy output."""
    k_noise, k_sample = jax.random.split(key)
    pol = agent.policy(actor_params, obs, k_noise, noise_scale)
    action, _ = sample_action(pol, k_sample)
    return action, pol


def act_deterministic(agent: Agent, actor_params: Params, obs: jax.Array) -> jax.Array:
    """Evaluation action tanh(mu(s)); Noisy SAC evaluates with the noise-free mean (mu_w, mu_b)."""
    pol = agent.policy(actor_params, obs, jax.random.key(0), jnp.float32(0.0))
    return deterministic_action(pol)
