"""SAC losses (Haarnoja et al. 2018a/b) and TD3 targets (Fujimoto et al. 2018), written once as pure functions of arrays.

Each loss takes the parameters it differentiates first (Brax style), so `jax.value_and_grad` applies
directly. The soft target is written for ONE transition and vmapped (rlax style).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def soft_q_target(
    reward: jax.Array,
    terminated: jax.Array,
    next_q: jax.Array,
    next_log_prob: jax.Array,
    alpha: jax.Array,
    gamma: jax.Array,
    reward_scale: jax.Array,
) -> jax.Array:
    """Soft Bellman target of one transition, Haarnoja et al. 2018b eq. (3) with clipped double Q:

    y = reward_scale * r + gamma * (1 - terminated) * (min_k Qbar_k(s', a') - alpha * log pi(a'|s')),
    a' ~ pi(.|s'). `next_q` is [num_critics]. Truncation is not termination: a time-limit step keeps
    bootstrapping (terminated = 0).
    """
    soft_value = jnp.min(next_q) - alpha * next_log_prob
    return reward_scale * reward + gamma * (1.0 - terminated) * soft_value


def critic_loss_from_values(
    q: jax.Array, target: jax.Array, weights: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """Importance-weighted soft Q loss, Haarnoja et al. 2018b eq. (5), summed over the twin critics.

    L = mean_i w_i * sum_k 0.5 (Q_k(s_i, a_i) - y_i)^2, with w_i the prioritized-replay importance
    weights (Schaul et al. 2015). q: [B, num_critics]; target, weights: [B].
    Returns (loss, td_error [B]), td_error = mean_k (Q_k - y), the delta whose square becomes the
    new priority (paper A.1).
    """
    td = q - jax.lax.stop_gradient(target)[:, None]
    loss = jnp.mean(weights * 0.5 * jnp.sum(jnp.square(td), axis=-1))
    return loss, jnp.mean(td, axis=-1)


def actor_loss_from_values(log_prob: jax.Array, q: jax.Array, alpha: jax.Array) -> jax.Array:
    """Policy loss, Haarnoja et al. 2018b eq. (7): mean_i alpha log pi(a_i|s_i) - min_k Q_k(s_i, a_i),
    with a_i ~ pi(.|s_i) reparameterised. log_prob: [B]; q: [B, num_critics]."""
    return jnp.mean(alpha * log_prob - jnp.min(q, axis=-1))


def alpha_loss_from_values(
    log_alpha: jax.Array, log_prob: jax.Array, target_entropy: float
) -> jax.Array:
    """Temperature loss, Haarnoja et al. 2018b eq. (18): mean -alpha (log pi(a|s) + target_entropy)."""
    return -jnp.exp(log_alpha) * jnp.mean(jax.lax.stop_gradient(log_prob) + target_entropy)


# ---------------------------------------------------------------- TD3 (Fujimoto et al. 2018)


def smoothed_target_action(
    next_action: jax.Array, noise: jax.Array, noise_clip: float
) -> jax.Array:
    """Target policy smoothing of one transition (Fujimoto et al. 2018, Algorithm 1):

    a' = clip(pi_targ(s') + clip(eps, -c, c), -1, 1), eps ~ N(0, sigma^2) given as `noise` [A]
    (already scaled by sigma), `next_action` = tanh(mu_targ(s')) [A]. The outer clip to the action
    bounds is the authors' code (`clamp(-max_action, max_action)`); the paper's Algorithm 1 omits it.
    """
    return jnp.clip(next_action + jnp.clip(noise, -noise_clip, noise_clip), -1.0, 1.0)


def td3_q_target(
    reward: jax.Array,
    terminated: jax.Array,
    next_q: jax.Array,
    gamma: jax.Array,
    reward_scale: jax.Array,
) -> jax.Array:
    """Clipped double-Q target of one transition (Fujimoto et al. 2018, Algorithm 1):

    y = reward_scale * r + gamma * (1 - terminated) * min_k Q_targ_k(s', a'), with a' the smoothed
    target action (`smoothed_target_action`). `next_q` is [num_critics]. This is `soft_q_target`
    with alpha = 0; truncation is not termination (terminated = 0 at a time limit).
    """
    return reward_scale * reward + gamma * (1.0 - terminated) * jnp.min(next_q)


def deterministic_actor_loss_from_values(q0: jax.Array, weights: jax.Array) -> jax.Array:
    """Deterministic policy-gradient loss (Silver et al. 2014; TD3 differentiates the first critic
    only, Fujimoto et al. 2018 Algorithm 1): L = -mean_i w_i Q_0(s_i, pi(s_i)).

    q0: [B] the first critic at the actor's action; weights: [B], ones for TD3, the bootstrap mask
    of a head for Bootstrapped TD3 (its head learns only from the transitions it was dealt).
    """
    return -jnp.mean(weights * q0)
