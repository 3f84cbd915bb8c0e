"""SAC (Haarnoja et al. 2018a/b) and Noisy SAC (paper 3.1) under the agent interface (`base.Agent`).

Plain SAC or Noisy SAC is the sweepable `hp.noisy` (0 or 1), used as the noise scale of the actor's
mean head, so one compiled program vmaps over both. Uncertainty (paper 3.1-3.2): intrinsic
u(s) = sigma_theta(s), the policy's standard deviation; extrinsic (Noisy SAC) u(s) = Var[mu~(s)], the
analytic variance of the perturbed mean.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import chex
import flax.struct
import jax
import jax.numpy as jnp
import optax

from arld_jax import checks, losses
from arld_jax.agents.base import (
    ADAM,
    Acting,
    Agent,
    AgentSpec,
    UpdateMetrics,
    adam_step,
    dummy_inputs,
    matmul_dtype,
    polyak,
    reduce_over_actions,
    same_episode,
)
from arld_jax.networks import Actor, PolicyOutput, TwinCritic, deterministic_action, sample_action
from arld_jax.types import Params, PRNGKey, Transition

if TYPE_CHECKING:
    from arld_jax.config import Config, HParams


@dataclass(frozen=True)
class SACOptions:
    """SAC's own Config fields (static)."""

    log_std_min: float = -20.0
    """Lower clip of the actor's log-std head."""
    log_std_max: float = 2.0
    """Upper clip of the actor's log-std head."""


def check(cfg: Config) -> None:
    if not cfg.log_std_min < cfg.log_std_max:
        checks.fail("log_std_min", cfg.log_std_min, f"< log_std_max ({cfg.log_std_max})")


@flax.struct.dataclass
class SACState:
    """Parameters and optimizer states of one SAC agent (the loop's `TrainState.agent`)."""

    actor_params: Params
    critic_params: Params
    target_critic_params: Params
    log_alpha: jax.Array  # []
    actor_opt: optax.OptState
    critic_opt: optax.OptState
    alpha_opt: optax.OptState


def make(cfg: Config, obs_dim: int, action_dim: int) -> Agent:
    """Build the SAC agent for `cfg` (network sizes and dtype are static)."""
    dtype = matmul_dtype(cfg)
    actor = Actor(
        action_dim=action_dim,
        hidden_sizes=cfg.hidden_sizes,
        log_std_min=cfg.log_std_min,
        log_std_max=cfg.log_std_max,
        sigma_init=cfg.noisy_sigma_init,
        dtype=dtype,
        draw_noise=cfg.noisy_runs,
    )
    critic = TwinCritic(hidden_sizes=cfg.hidden_sizes, dtype=dtype)
    target_entropy = -float(action_dim)  # Haarnoja et al. 2018b: -dim(A)

    def init(key: PRNGKey, hp: HParams) -> SACState:
        k_actor, k_critic, k_noise = jax.random.split(key, 3)
        obs, action = dummy_inputs(obs_dim, action_dim)
        actor_params = actor.init(k_actor, obs, k_noise, jnp.float32(0.0))
        critic_params = critic.init(k_critic, obs, action)
        log_alpha = jnp.log(hp.init_alpha).astype(jnp.float32)
        return SACState(
            actor_params=actor_params,
            critic_params=critic_params,
            target_critic_params=critic_params,
            log_alpha=log_alpha,
            actor_opt=ADAM.init(actor_params),
            critic_opt=ADAM.init(critic_params),
            alpha_opt=ADAM.init(log_alpha),
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
        state: SACState,
        batch: Transition,
        weights: jax.Array,
        indices: jax.Array,
        hp: HParams,
        key: PRNGKey,
    ) -> tuple[SACState, jax.Array, UpdateMetrics]:
        """One SAC gradient step: critics, then actor (against the new critics), then alpha, then
        Polyak targets. Returns the new state, the TD errors of the batch (for priorities) and metrics."""
        chex.assert_rank(batch.reward, 1)
        chex.assert_equal_shape([batch.reward, weights])
        k_critic, k_actor = jax.random.split(key)
        (c_loss, td), c_grads = jax.value_and_grad(critic_loss, has_aux=True)(
            state.critic_params, state, batch, weights, hp, k_critic
        )
        critic_params, critic_opt = adam_step(
            state.critic_params, c_grads, state.critic_opt, hp.critic_lr
        )
        (a_loss, log_prob), a_grads = jax.value_and_grad(actor_loss, has_aux=True)(
            state.actor_params, critic_params, state.log_alpha, batch.obs, hp, k_actor
        )
        actor_params, actor_opt = adam_step(
            state.actor_params, a_grads, state.actor_opt, hp.actor_lr
        )
        # Temperature (Haarnoja et al. 2018b, eq. 18) when hp.autotune_alpha is 1, else fixed (paper
        # A.1). Sweepable, so one program compares both: the step is computed and then selected.
        alpha_grad = jax.grad(losses.alpha_loss_from_values)(
            state.log_alpha, log_prob, target_entropy
        )
        tuned = adam_step(state.log_alpha, alpha_grad, state.alpha_opt, hp.alpha_lr)
        log_alpha, alpha_opt = jax.tree.map(
            lambda new, old: jnp.where(hp.autotune_alpha > 0.5, new, old),
            tuned,
            (state.log_alpha, state.alpha_opt),
        )
        new_state = SACState(
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
        state: SACState,
        batch: Transition,
        weights: jax.Array,
        indices: jax.Array,
        hp: HParams,
        key: PRNGKey,
    ) -> tuple[SACState, jax.Array, UpdateMetrics]:
        """Same signature as `update`, but only measures the TD errors (warm-up: no learning yet,
        replay priorities still follow the current critics)."""
        _, td = critic_loss(
            state.critic_params, state, batch, weights, hp, jax.random.split(key)[0]
        )
        zero = jnp.zeros(())
        return state, td, UpdateMetrics(zero, zero, jnp.exp(state.log_alpha), zero, zero)

    def act(state: SACState, obs: jax.Array, key: PRNGKey, hp: HParams) -> Acting:
        """a = tanh(mu + sigma xi) (paper 3.2), u(s) per `cfg.uncertainty_reduce`."""
        k_noise, k_sample = jax.random.split(key)
        pol = policy(state.actor_params, obs, k_noise, hp.noisy)
        action, _ = sample_action(pol, k_sample)
        return Acting(
            action=action,
            uncertainty=uncertainty(pol, hp.noisy, cfg.uncertainty_reduce),
            sigma=jnp.mean(jnp.exp(pol.log_std), axis=-1),
        )

    def act_deterministic(state: SACState, obs: jax.Array) -> jax.Array:
        """tanh(mu(s)); Noisy SAC evaluates with the noise-free mean (mu_w, mu_b)."""
        pol = policy(state.actor_params, obs, jax.random.key(0), jnp.float32(0.0))
        return deterministic_action(pol)

    return Agent(
        name="sac",
        init=init,
        act=act,
        act_deterministic=act_deterministic,
        begin_episode=same_episode,
        update=update,
        no_update=no_update,
        policy_params=lambda state: state.actor_params,
        obs_dim=obs_dim,
        action_dim=action_dim,
    )


def uncertainty(policy: PolicyOutput, noisy: jax.Array, how: str = "mean") -> jax.Array:
    """The agent's uncertainty u(s), [..., A] -> [...].

    Intrinsic (plain SAC, paper 3.2): u(s) = sigma_theta(s), the policy's standard deviation.
    Extrinsic (Noisy SAC, paper 3.1): u(s) = Var[mu~_theta(s)], the analytic variance of the perturbed
    mean. `noisy` (0 or 1, sweepable) picks one; both are cheap, so both are computed.
    """
    intrinsic = reduce_over_actions(jnp.exp(policy.log_std), how)
    extrinsic = reduce_over_actions(policy.mean_var, how)
    return jnp.where(noisy > 0.5, extrinsic, intrinsic)


SPEC = AgentSpec(
    name="sac",
    make=make,
    display="SAC",
    noisy_display="NoisySAC",
    uncertainty_titles={
        "intrinsic": "Intrinsic uncertainty: SAC σθ(s)",
        "extrinsic": "Extrinsic uncertainty: Noisy SAC Var[μ̃θ]",
    },
    options=SACOptions,
    check=check,
    exports_expert=True,
)
