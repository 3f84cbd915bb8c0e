"""SAC losses (Haarnoja et al. 2018a/b), written once as pure functions of arrays.

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
