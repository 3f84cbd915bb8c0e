"""Bootstrapped TD3 (paper section 1, Fig. 1b): bootstrapped DQN (Osband et al. 2016) carried to TD3
(Fujimoto et al. 2018), under the agent interface.

K = `cfg.boot_heads` actor heads on one shared actor torso (`networks.MultiHeadActor`) and K
twin-critic heads on two shared critic torsos (`networks.MultiHeadTwinCritic`), each with its target.
Head k is a complete TD3 learner (target policy smoothing, clipped double Q over its own two critic
heads, delayed actor and target updates) trained only on the transitions its bootstrap mask deals it.

Readings that are ours (the paper names Bootstrapped TD3 and shows its curves, Fig. 1b, without
details):

* Bootstrap masks m_k(i) ~ Bernoulli(p), p = `cfg.boot_mask_prob`, one per (replay slot i, head k),
  drawn as a pure function of (mask_key, i, k) with a mask_key fixed at init (`bootstrap_masks`).
  This equals drawing the mask when the transition is stored (Osband et al. 2016) without storing
  it in the replay; a slot overwritten by the ring buffer keeps its slot's mask.
* Head k's critic loss is TD3's importance-weighted loss with weights m_k(i) w_i (a mean over the
  batch, so a head sees fewer effective samples, as in bootstrapped DQN); head k's actor maximises
  its own head's first critic on its own transitions, -mean_i m_k(i) Q_0^k(s_i, pi_k(s_i)). The
  per-head losses are averaged over heads, which scales the shared torsos' gradients by 1/K
  (Osband et al. 2016 normalise the shared network's gradient by 1/K).
* The priority TD error of a transition is the masked mean over heads of each head's TD error
  (0 for a transition no head was dealt: no head learns from it, so it need not be replayed).
* Acting: one head drawn uniformly when all envs start an episode (`begin_episode`; Osband et al.
  2016 "sample a head for the episode"), explored with TD3's Gaussian action noise. All envs of a
  run share the head (they start their episodes together).
* Uncertainty u(s) = the heads' disagreement, the standard deviation over heads of tanh(mu_k(s)),
  reduced over action dimensions by `cfg.uncertainty_reduce`.
* Evaluation (`act_deterministic`) = the mean over heads of tanh(mu_k(s)), an ensemble vote (a
  continuous-action stand-in for bootstrapped DQN's majority vote).
* `hp.noisy` is ignored: Bootstrapped TD3 has one uncertainty, its heads' disagreement.
* `Acting.sigma` is the exploration noise std (a constant).
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
    dummy_inputs,
    matmul_dtype,
    reduce_over_actions,
)
from arld_jax.agents.td3 import explore, td3_step
from arld_jax.networks import MultiHeadActor, MultiHeadTwinCritic
from arld_jax.types import Params, PRNGKey, Transition

if TYPE_CHECKING:
    from arld_jax.config import Config, HParams


@dataclass(frozen=True)
class BootTD3Options:
    """Bootstrapped TD3's own Config fields (static), beside the TD3 family's (`TD3Options`)."""

    boot_heads: int = 10
    """K: actor heads and twin-critic heads of Bootstrapped TD3 (Osband et al. 2016: K = 10)."""
    boot_mask_prob: float = 0.5
    """p: each head learns from a transition with probability p, a Bernoulli bootstrap mask drawn
    once per (replay slot, head) (Osband et al. 2016: p = 0.5; p = 1 shares all data)."""


def check(cfg: Config) -> None:
    checks.int_at_least(cfg, ("boot_heads",), 1)
    if not 0 < cfg.boot_mask_prob <= 1:
        checks.fail("boot_mask_prob", cfg.boot_mask_prob, "0 < p <= 1")


@flax.struct.dataclass
class BootTD3State:
    """Parameters, targets, optimizer states, counters and keys of one Bootstrapped TD3 agent."""

    actor_params: Params
    critic_params: Params
    target_actor_params: Params
    target_critic_params: Params
    actor_opt: optax.OptState
    critic_opt: optax.OptState
    step: jax.Array  # [] int32: critic updates done (delayed policy updates)
    mask_key: PRNGKey  # fixed at init: the bootstrap masks are a function of it
    head: jax.Array  # [] int32: the acting head of the current episode


def bootstrap_masks(
    mask_key: PRNGKey, indices: jax.Array, num_heads: int, prob: float
) -> jax.Array:
    """Bootstrap masks [B, K] (float 0/1) of the replay slots `indices` [B] (Osband et al. 2016).

    m_k(i) ~ Bernoulli(prob), a deterministic function of (mask_key, i, k): the same slot always
    gets the same heads, whatever batch it is sampled in."""

    def one(i: jax.Array, k: jax.Array) -> jax.Array:
        key = jax.random.fold_in(jax.random.fold_in(mask_key, i), k)
        return jax.random.bernoulli(key, prob)

    heads = jnp.arange(num_heads)
    masks = jax.vmap(lambda i: jax.vmap(lambda k: one(i, k))(heads))(indices)
    return masks.astype(jnp.float32)


def masked_mean_over_heads(td: jax.Array, masks: jax.Array) -> jax.Array:
    """Priority TD error [B] from per-head TD errors td [K, B] and masks [B, K]: the mean over the
    heads a transition was dealt (0 if none)."""
    count = jnp.sum(masks, axis=1)
    return jnp.sum(masks * td.T, axis=1) / jnp.maximum(count, 1.0)


def head_disagreement(actions: jax.Array, how: str = "mean") -> jax.Array:
    """u(s): standard deviation over heads of the heads' actions [..., K, A] -> [...]."""
    return reduce_over_actions(jnp.std(actions, axis=-2), how)


def make(cfg: Config, obs_dim: int, action_dim: int) -> Agent:
    """Build the Bootstrapped TD3 agent for `cfg` (sizes, K, p and the TD3 constants static)."""
    dtype = matmul_dtype(cfg)
    num_heads = cfg.boot_heads
    actor = MultiHeadActor(
        action_dim=action_dim, num_heads=num_heads, hidden_sizes=cfg.hidden_sizes, dtype=dtype
    )
    critic = MultiHeadTwinCritic(num_heads=num_heads, hidden_sizes=cfg.hidden_sizes, dtype=dtype)
    delay = cfg.td3_policy_delay

    def draw_head(key: PRNGKey) -> jax.Array:
        return jax.random.randint(key, (), 0, num_heads, jnp.int32)

    def init(key: PRNGKey, hp: HParams) -> BootTD3State:
        del hp
        k_actor, k_critic, k_mask, k_head = jax.random.split(key, 4)
        obs, action = dummy_inputs(obs_dim, action_dim)
        actor_params = actor.init(k_actor, obs)
        critic_params = critic.init(k_critic, obs, action)
        return BootTD3State(
            actor_params=actor_params,
            critic_params=critic_params,
            target_actor_params=actor_params,
            target_critic_params=critic_params,
            actor_opt=ADAM.init(actor_params),
            critic_opt=ADAM.init(critic_params),
            step=jnp.zeros((), jnp.int32),
            mask_key=k_mask,
            head=draw_head(k_head),
        )

    def masks_of(state: BootTD3State, indices: jax.Array) -> jax.Array:
        return bootstrap_masks(state.mask_key, indices, num_heads, cfg.boot_mask_prob)

    def critic_loss(critic_params, state, batch, weights, masks, hp, key):  # noqa: ANN001, ANN202
        next_mean = actor.apply(state.target_actor_params, batch.next_obs)  # [B, K, A]
        smoothing = cfg.td3_policy_noise * jax.random.normal(key, next_mean.shape)
        # Per head: its own smoothed target action (elementwise, so [B, K, A] as for one [A]),
        # scored by its own target critic heads.
        next_action = losses.smoothed_target_action(
            jnp.tanh(next_mean), smoothing, cfg.td3_noise_clip
        )
        next_q = critic.apply(state.target_critic_params, batch.next_obs, next_action)  # [B, K, 2]
        per_head_target = jax.vmap(losses.td3_q_target, in_axes=(None, None, 0, None, None))
        target = jax.vmap(per_head_target, in_axes=(0, 0, 0, None, None))(
            batch.reward, batch.terminated, next_q, hp.gamma, hp.reward_scale
        )  # [B, K]
        q = critic.apply(critic_params, batch.obs, batch.action)  # [B, K, 2]
        head_loss, head_td = jax.vmap(losses.critic_loss_from_values, in_axes=(1, 1, 1))(
            q, target, masks * weights[:, None]
        )  # [K], [K, B]
        return jnp.mean(head_loss), masked_mean_over_heads(head_td, masks)

    def actor_loss(actor_params, critic_params, obs, masks):  # noqa: ANN001, ANN202
        actions = jnp.tanh(actor.apply(actor_params, obs))  # [B, K, A]
        q0 = critic.apply(critic_params, obs, actions)[..., 0]  # [B, K]: head k at its own action
        head_loss = jax.vmap(losses.deterministic_actor_loss_from_values, in_axes=(1, 1))(q0, masks)
        return jnp.mean(head_loss)

    def update(
        state: BootTD3State,
        batch: Transition,
        weights: jax.Array,
        indices: jax.Array,
        hp: HParams,
        key: PRNGKey,
    ) -> tuple[BootTD3State, jax.Array, UpdateMetrics]:
        """One TD3 update of every head on its masked share of the batch (delayed actor and
        targets as in TD3). Returns the new state, the masked-mean TD errors and metrics."""
        chex.assert_rank(batch.reward, 1)
        chex.assert_equal_shape([batch.reward, weights, indices])
        masks = masks_of(state, indices)
        k_critic = jax.random.split(key)[0]  # as in no_update, so both give the same TD errors
        return td3_step(
            state,
            lambda critic_params: critic_loss(
                critic_params, state, batch, weights, masks, hp, k_critic
            ),
            lambda actor_params, critic_params: actor_loss(
                actor_params, critic_params, batch.obs, masks
            ),
            hp,
            delay,
        )

    def no_update(
        state: BootTD3State,
        batch: Transition,
        weights: jax.Array,
        indices: jax.Array,
        hp: HParams,
        key: PRNGKey,
    ) -> tuple[BootTD3State, jax.Array, UpdateMetrics]:
        """Same signature as `update`: its TD errors with this key, nothing learned (warm-up)."""
        masks = masks_of(state, indices)
        _, td = critic_loss(
            state.critic_params, state, batch, weights, masks, hp, jax.random.split(key)[0]
        )
        return state, td, UpdateMetrics.zeros()

    def act(state: BootTD3State, obs: jax.Array, key: PRNGKey, hp: HParams) -> Acting:
        """The episode's head, clip(tanh(mu_k(s)) + N(0, 0.1^2), -1, 1); u(s) = heads' std."""
        del hp
        actions = jnp.tanh(actor.apply(state.actor_params, obs))  # [n, K, A]
        return Acting(
            action=explore(actions[:, state.head], key, cfg.td3_exploration_noise),
            uncertainty=head_disagreement(actions, cfg.uncertainty_reduce),
            sigma=jnp.full(obs.shape[:1], cfg.td3_exploration_noise, jnp.float32),
        )

    def act_deterministic(state: BootTD3State, obs: jax.Array) -> jax.Array:
        """The heads' ensemble vote: mean over heads of tanh(mu_k(s))."""
        return jnp.mean(jnp.tanh(actor.apply(state.actor_params, obs)), axis=-2)

    def begin_episode(state: BootTD3State, key: PRNGKey) -> BootTD3State:
        """Draw the acting head of the new episode uniformly (Osband et al. 2016)."""
        return state.replace(head=draw_head(key))

    return Agent(
        name="boot_td3",
        init=init,
        act=act,
        act_deterministic=act_deterministic,
        begin_episode=begin_episode,
        update=update,
        no_update=no_update,
        policy_params=lambda state: state.actor_params,
        obs_dim=obs_dim,
        action_dim=action_dim,
    )


SPEC = AgentSpec(
    name="boot_td3",
    make=make,
    display="BootTD3",
    uncertainty_titles={"intrinsic": "Bootstrapped TD3: the heads' disagreement"},
    options=BootTD3Options,
    check=check,
)
