"""The agent interface: what the loop, the query strategies, the replay and the driver know of an agent.

An agent is a bundle of pure functions over its own state pytree (STYLE.md: Brax/PureJaxRL style),
made by `make(cfg, obs_dim, action_dim)` in its module and registered by name in `arld_jax.agents`.
The loop (`arld_jax.train`) never looks inside the state: it calls

* `init(key, hp)` -> state;
* `act(state, obs [n, d], key, hp)` -> `Acting`: the exploration action and the agent's uncertainty
  u(s) [n] that the active query strategy ranks (paper sections 3-4);
* `act_deterministic(state, obs)` -> action [n, A] for evaluation (noise removed, paper 3.2);
* `begin_episode(state, key)` -> state, when all envs start new episodes (Bootstrapped TD3 draws
  its acting head there, Osband et al. 2016; the others return the state unchanged);
* `update(state, batch, weights, indices, hp, key)` -> (state, td [B], UpdateMetrics): one gradient
  step on a prioritized batch (`weights` the importance weights, `indices` the replay slots, which
  bootstrap masks are drawn from); `td` becomes the new priorities (paper A.1);
* `no_update(...)`, same signature: the TD errors only, nothing learned (warm-up);
* `policy_params(state)` -> the actor's parameters (exported as an expert).

`HParams.noisy` (0 or 1, sweepable) turns SAC into Noisy SAC and TD3 into Noisy TD3 in one program:
the mean head is always a noisy linear layer, its noise scale is `hp.noisy`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import flax.struct
import jax
import jax.numpy as jnp
import optax

from arld_jax.config import HParams
from arld_jax.types import Params, PRNGKey, Transition

AgentState = Any
"""An agent's own state pytree (parameters, optimizer states, counters)."""


@flax.struct.dataclass
class Acting:
    """An agent's exploration step on a batch of observations."""

    action: jax.Array  # [n, A] in [-1, 1]
    uncertainty: jax.Array  # [n] u(s), ranked by the active strategy
    sigma: jax.Array  # [n] the exploration noise scale (SAC's sigma_theta), for the metrics


@flax.struct.dataclass
class UpdateMetrics:
    """Scalars of one update (zeros where an agent has no such quantity, e.g. TD3's alpha)."""

    critic_loss: jax.Array
    actor_loss: jax.Array
    alpha: jax.Array
    entropy: jax.Array  # -mean log pi(a|s) on the batch (SAC)
    td_abs: jax.Array  # mean |delta|

    @classmethod
    def zeros(cls) -> UpdateMetrics:
        zero = jnp.zeros(())
        return cls(zero, zero, zero, zero, zero)


UpdateFn = Callable[
    [AgentState, Transition, jax.Array, jax.Array, HParams, PRNGKey],
    tuple[AgentState, jax.Array, UpdateMetrics],
]


class Agent(NamedTuple):
    """The pure functions of one agent (see the module docstring)."""

    name: str
    init: Callable[[PRNGKey, HParams], AgentState]
    act: Callable[[AgentState, jax.Array, PRNGKey, HParams], Acting]
    act_deterministic: Callable[[AgentState, jax.Array], jax.Array]
    begin_episode: Callable[[AgentState, PRNGKey], AgentState]
    update: UpdateFn
    no_update: UpdateFn
    policy_params: Callable[[AgentState], Params]
    obs_dim: int
    action_dim: int


# ---------------------------------------------------------------- shared pieces

ADAM = optax.scale_by_adam()
"""Adam (Kingma & Ba 2015) as a direction; the sweepable learning rate multiplies it outside optax,
so one compiled program serves any learning-rate grid."""


def adam_step(
    params: Params, grads: Params, opt_state: optax.OptState, lr: jax.Array
) -> tuple[Params, optax.OptState]:
    direction, opt_state = ADAM.update(grads, opt_state, params)
    params = jax.tree.map(lambda p, d: p - lr * d, params, direction)
    return params, opt_state


def polyak(target: Params, online: Params, tau: jax.Array) -> Params:
    """Target-network soft update theta' <- tau theta + (1 - tau) theta' (Lillicrap et al. 2015)."""
    return jax.tree.map(lambda t, o: (1.0 - tau) * t + tau * o, target, online)


def reduce_over_actions(x: jax.Array, how: str) -> jax.Array:
    """One uncertainty number per state from a per-action-dimension value ([..., A] -> [...])."""
    return {"mean": jnp.mean, "max": jnp.max, "sum": jnp.sum}[how](x, axis=-1)


def same_episode(state: AgentState, key: PRNGKey) -> AgentState:
    """`begin_episode` of agents without per-episode state."""
    del key
    return state
