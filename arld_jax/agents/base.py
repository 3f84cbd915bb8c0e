"""The agent interface: what the loop, the query strategies, the replay and the driver know of an agent.

An agent is a bundle of pure functions over its own state pytree (STYLE.md: Brax/PureJaxRL style),
made by `make(cfg, obs_dim, action_dim)` in its module. The module also declares, in one
`SPEC = AgentSpec(...)`, everything the rest of the package knows of it: its name, its names in
tables and figures, whether it has a noisy variant, its own Config fields and their checks, and
whether its actor can serve as an expert. `arld_jax.agents` finds every module with a `SPEC`; the
config's choices, the summaries, the figures, expert export and the contract tests derive from it.
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
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

import flax.struct
import jax
import jax.numpy as jnp
import optax

from arld_jax.types import Params, PRNGKey, Transition

if TYPE_CHECKING:  # config imports the agents' registry: only annotations name it here
    from arld_jax.config import Config, HParams

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
    [AgentState, Transition, jax.Array, jax.Array, "HParams", PRNGKey],
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


def no_checks(cfg: Config) -> None:
    """`AgentSpec.check` of an agent without fields of its own."""
    del cfg


@dataclass(frozen=True)
class AgentSpec:
    """What the package knows of one agent family, declared once in its module as `SPEC`."""

    name: str
    """`Config.agent`, e.g. 'sac'."""
    make: Callable[[Config, int, int], Agent]
    """`make(cfg, obs_dim, action_dim)`: the agent's pure functions."""
    display: str
    """Its name in the paper's style, prefixed by GQ/BQ/AQ for the query strategies: 'SAC'."""
    uncertainty_titles: dict[str, str]
    """Uncertainty measure -> what u(s) is for this agent, as a figure title."""
    noisy_display: str | None = None
    """The name of its noisy variant (uncertainty 'extrinsic', paper 3.1), or None if it has none
    (then it has one uncertainty of its own, and a swept `uncertainty` is pruned)."""
    options: type | None = None
    """A frozen dataclass of its own Config fields (defaults and docstrings); `Config` inherits
    from every agent's, so `--help`, config.json and sweeps see them like any other field."""
    check: Callable[[Config], None] = no_checks
    """Validation of those fields (`arld_jax.checks`), run by `config.validate` for every Config."""
    exports_expert: bool = False
    """Whether a trained actor of this family can be exported as an expert (`expert.py` acts with a
    SAC actor: paper A.1's expert is "a pre-trained prioritized SAC model")."""

    @property
    def noisy(self) -> bool:
        return self.noisy_display is not None

    def variant(self, uncertainty: str) -> str:
        """The name of the variant that a run with this uncertainty measure trains."""
        if uncertainty == "extrinsic" and self.noisy_display is not None:
            return self.noisy_display
        return self.display


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


def matmul_dtype(cfg: Config) -> jnp.dtype:
    """The dtype of the networks' matmul inputs (`Config.matmul_dtype`; accumulation stays f32)."""
    return jnp.bfloat16 if cfg.matmul_dtype == "bfloat16" else jnp.float32


def dummy_inputs(obs_dim: int, action_dim: int) -> tuple[jax.Array, jax.Array]:
    """An observation [1, obs_dim] and an action [1, action_dim] of zeros, to initialise networks."""
    return jnp.zeros((1, obs_dim)), jnp.zeros((1, action_dim))


def reduce_over_actions(x: jax.Array, how: str) -> jax.Array:
    """One uncertainty number per state from a per-action-dimension value ([..., A] -> [...])."""
    return {"mean": jnp.mean, "max": jnp.max, "sum": jnp.sum}[how](x, axis=-1)


def same_episode(state: AgentState, key: PRNGKey) -> AgentState:
    """`begin_episode` of agents without per-episode state."""
    del key
    return state
