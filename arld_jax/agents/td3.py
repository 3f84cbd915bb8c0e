"""TD3 (Fujimoto et al. 2018) and Noisy TD3 (paper section 1, Fig. 1a) under the agent interface.

TD3 = a deterministic actor a = tanh(mu(s)), twin critics with a clipped double-Q target, target
policy smoothing and delayed policy updates (`losses.smoothed_target_action`, `losses.td3_q_target`).
As in `sac.py`, plain TD3 or Noisy TD3 is the sweepable `hp.noisy` (0 or 1), the noise scale of the
actor's `NoisyDense` mean head, so one compiled program vmaps over both.

Readings that are ours (the paper names Noisy TD3 and shows its curves, Fig. 1a, without details):

* Noisy TD3 = parameter noise on the actor (Plappert et al. 2017, the paper's section 3.1 reference)
  in the form the paper uses for Noisy SAC: independent Gaussian noise on the mean head (Fortunato
  et al. 2017). Fresh noise at every training forward pass (online actor in the actor loss, target
  actor in the critic target), as Noisy SAC does; exploration = the perturbed actor plus TD3's
  Gaussian action noise; evaluation = the noise-free mean (mu_w, mu_b).
* Uncertainty u(s): Noisy TD3 (hp.noisy = 1) uses the paper's 3.1 extrinsic measure, the analytic
  variance of the perturbed mean phi^T diag(sigma_w^2) phi + sigma_b^2, reduced over action
  dimensions by `cfg.uncertainty_reduce`. Plain TD3 has no uncertainty of its own; we use the twin
  critics' disagreement at the actor's action, |Q_0(s, mu(s)) - Q_1(s, mu(s))| (one number per
  state, so no reduction over actions).
* Delayed updates count critic updates in the state (`TD3State.step`); the actor and BOTH target
  networks update when the count after this update is a multiple of d (the authors' code:
  `total_it % policy_freq == 0`, so first at update d). The choice is a select on the parameter
  trees, so under vmap every run computes the actor step and keeps it only on those updates.
* The prioritized-replay importance weights scale the critic loss only (as for SAC); the actor loss
  -mean Q_0(s, mu(s)) is unweighted (Fujimoto et al. 2018 use the first critic for the actor).
* The target action is clipped to [-1, 1] after smoothing (the authors' code; Algorithm 1 omits it).
* `Acting.sigma` is the exploration noise std (a constant), TD3's counterpart of SAC's sigma_theta.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

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
from arld_jax.networks import DeterministicActor, TwinCritic
from arld_jax.types import Params, PRNGKey, Transition

if TYPE_CHECKING:
    from arld_jax.config import Config, HParams


@dataclass(frozen=True)
class TD3Options:
    """The TD3 family's own Config fields (static; Bootstrapped TD3 uses them too)."""

    td3_policy_noise: float = 0.2
    """Std of the target policy smoothing noise on a' (Fujimoto et al. 2018: 0.2), for td3/boot_td3."""
    td3_noise_clip: float = 0.5
    """The smoothing noise is clipped to [-c, c] (Fujimoto et al. 2018: c = 0.5)."""
    td3_policy_delay: int = 2
    """d: the actor and both target networks update once every d critic updates (Fujimoto et al.
    2018: d = 2)."""
    td3_exploration_noise: float = 0.1
    """Std of the Gaussian noise added to the actor's action when exploring (Fujimoto et al. 2018:
    0.1); the action is then clipped to [-1, 1]."""


def check(cfg: Config) -> None:
    checks.non_negative(cfg, ("td3_policy_noise", "td3_noise_clip", "td3_exploration_noise"))
    checks.int_at_least(cfg, ("td3_policy_delay",), 1)


@flax.struct.dataclass
class TD3State:
    """Parameters, targets, optimizer states and the update counter of one TD3 agent."""

    actor_params: Params
    critic_params: Params
    target_actor_params: Params
    target_critic_params: Params
    actor_opt: optax.OptState
    critic_opt: optax.OptState
    step: jax.Array  # [] int32: critic updates done (drives the delayed policy updates)


def select_tree(pred: jax.Array, on_true: Any, on_false: Any) -> Any:
    """`on_true` where `pred` else `on_false`, leaf by leaf (a select, so vmap-safe)."""
    return jax.tree.map(lambda a, b: jnp.where(pred, a, b), on_true, on_false)


def is_policy_step(step: jax.Array, delay: int) -> jax.Array:
    """Delayed policy updates (Fujimoto et al. 2018): after critic update number `step` (1-based),
    the actor and the targets update iff step is a multiple of d."""
    return step % delay == 0


def delayed_policy_step(
    state: Any,
    critic_params: Params,
    critic_opt: optax.OptState,
    actor_params: Params,
    actor_opt: optax.OptState,
    tau: jax.Array,
    delay: int,
) -> Any:
    """Apply one TD3 update's new parameters to `state` (TD3's or Bootstrapped TD3's: same fields):
    the critics always; the actor and the Polyak targets of both only when the update count is a
    multiple of `delay` (Fujimoto et al. 2018, delayed policy updates), by selects (vmap-safe)."""
    step = state.step + 1
    delayed = (
        actor_params,
        actor_opt,
        polyak(state.target_actor_params, actor_params, tau),
        polyak(state.target_critic_params, critic_params, tau),
    )
    kept = (
        state.actor_params,
        state.actor_opt,
        state.target_actor_params,
        state.target_critic_params,
    )
    actor_params, actor_opt, target_actor, target_critic = select_tree(
        is_policy_step(step, delay), delayed, kept
    )
    return state.replace(
        actor_params=actor_params,
        critic_params=critic_params,
        target_actor_params=target_actor,
        target_critic_params=target_critic,
        actor_opt=actor_opt,
        critic_opt=critic_opt,
        step=step,
    )


def td3_step(
    state: Any,
    critic_loss: Callable[[Params], tuple[jax.Array, jax.Array]],
    actor_loss: Callable[[Params, Params], jax.Array],
    hp: HParams,
    delay: int,
) -> tuple[Any, jax.Array, UpdateMetrics]:
    """One update of a TD3-family agent (TD3's or Bootstrapped TD3's state: same fields) from its
    losses: the critics by `critic_loss(critic_params) -> (loss, td)`; the actor by
    `actor_loss(actor_params, critic_params)` against the new critics; applied by
    `delayed_policy_step`. Returns the new state, the TD errors and metrics (the actor loss is
    reported at the current actor, also on updates that do not apply it)."""
    (c_loss, td), c_grads = jax.value_and_grad(critic_loss, has_aux=True)(state.critic_params)
    critic_params, critic_opt = adam_step(
        state.critic_params, c_grads, state.critic_opt, hp.critic_lr
    )
    a_loss, a_grads = jax.value_and_grad(actor_loss)(state.actor_params, critic_params)
    actor_params, actor_opt = adam_step(state.actor_params, a_grads, state.actor_opt, hp.actor_lr)
    new_state = delayed_policy_step(
        state, critic_params, critic_opt, actor_params, actor_opt, hp.tau, delay
    )
    zero = jnp.zeros(())
    metrics = UpdateMetrics(
        critic_loss=c_loss,
        actor_loss=a_loss,
        alpha=zero,
        entropy=zero,
        td_abs=jnp.mean(jnp.abs(td)),
    )
    return new_state, td, metrics


def explore(mean_action: jax.Array, key: PRNGKey, noise_std: float) -> jax.Array:
    """TD3's exploration action clip(a + N(0, sigma^2), -1, 1) (Fujimoto et al. 2018)."""
    noise = noise_std * jax.random.normal(key, mean_action.shape)
    return jnp.clip(mean_action + noise, -1.0, 1.0)


def uncertainty(
    mean_var: jax.Array, q: jax.Array, noisy: jax.Array, how: str = "mean"
) -> jax.Array:
    """TD3's u(s) [...] (see the module docstring).

    mean_var: [..., A] the analytic Var[mu~(s)] of the noisy mean head (Noisy TD3, paper 3.1);
    q: [..., 2] the twin critics at the actor's action (plain TD3: |Q_0 - Q_1|, our reading).
    `noisy` (0 or 1, sweepable) picks one; both are cheap, so both are computed.
    """
    extrinsic = reduce_over_actions(mean_var, how)
    disagreement = jnp.abs(q[..., 0] - q[..., 1])
    return jnp.where(noisy > 0.5, extrinsic, disagreement)


def make(cfg: Config, obs_dim: int, action_dim: int) -> Agent:
    """Build the TD3 / Noisy TD3 agent for `cfg` (network sizes, dtype and TD3 constants static)."""
    dtype = matmul_dtype(cfg)
    actor = DeterministicActor(
        action_dim=action_dim,
        hidden_sizes=cfg.hidden_sizes,
        sigma_init=cfg.noisy_sigma_init,
        dtype=dtype,
        draw_noise=cfg.noisy_runs,
    )
    critic = TwinCritic(hidden_sizes=cfg.hidden_sizes, dtype=dtype)
    delay = cfg.td3_policy_delay

    def init(key: PRNGKey, hp: HParams) -> TD3State:
        del hp
        k_actor, k_critic, k_noise = jax.random.split(key, 3)
        obs, action = dummy_inputs(obs_dim, action_dim)
        actor_params = actor.init(k_actor, obs, k_noise, jnp.float32(0.0))
        critic_params = critic.init(k_critic, obs, action)
        return TD3State(
            actor_params=actor_params,
            critic_params=critic_params,
            target_actor_params=actor_params,
            target_critic_params=critic_params,
            actor_opt=ADAM.init(actor_params),
            critic_opt=ADAM.init(critic_params),
            step=jnp.zeros((), jnp.int32),
        )

    def critic_loss(critic_params, state, batch, weights, hp, key):  # noqa: ANN001, ANN202
        k_noise, k_smooth = jax.random.split(key)
        next_mean = actor.apply(state.target_actor_params, batch.next_obs, k_noise, hp.noisy).mean
        smoothing = cfg.td3_policy_noise * jax.random.normal(k_smooth, next_mean.shape)
        next_action = jax.vmap(losses.smoothed_target_action, in_axes=(0, 0, None))(
            jnp.tanh(next_mean), smoothing, cfg.td3_noise_clip
        )
        next_q = critic.apply(state.target_critic_params, batch.next_obs, next_action)
        target = jax.vmap(losses.td3_q_target, in_axes=(0, 0, 0, None, None))(
            batch.reward, batch.terminated, next_q, hp.gamma, hp.reward_scale
        )
        q = critic.apply(critic_params, batch.obs, batch.action)
        return losses.critic_loss_from_values(q, target, weights)

    def actor_loss(actor_params, critic_params, obs, hp, key):  # noqa: ANN001, ANN202
        mean = actor.apply(actor_params, obs, key, hp.noisy).mean
        q = critic.apply(critic_params, obs, jnp.tanh(mean))
        return losses.deterministic_actor_loss_from_values(q[:, 0], jnp.ones(q.shape[0]))

    def update(
        state: TD3State,
        batch: Transition,
        weights: jax.Array,
        indices: jax.Array,
        hp: HParams,
        key: PRNGKey,
    ) -> tuple[TD3State, jax.Array, UpdateMetrics]:
        """One TD3 update: the critics; then, every d-th update, the actor (against the new critics)
        and Polyak targets of both. Returns the new state, the batch's TD errors and metrics."""
        del indices
        chex.assert_rank(batch.reward, 1)
        chex.assert_equal_shape([batch.reward, weights])
        k_critic, k_actor = jax.random.split(key)
        return td3_step(
            state,
            lambda critic_params: critic_loss(critic_params, state, batch, weights, hp, k_critic),
            lambda actor_params, critic_params: actor_loss(
                actor_params, critic_params, batch.obs, hp, k_actor
            ),
            hp,
            delay,
        )

    def no_update(
        state: TD3State,
        batch: Transition,
        weights: jax.Array,
        indices: jax.Array,
        hp: HParams,
        key: PRNGKey,
    ) -> tuple[TD3State, jax.Array, UpdateMetrics]:
        """Same signature as `update`: the TD errors `update` would return with this key, nothing
        learned and the counter unchanged (warm-up)."""
        del indices
        _, td = critic_loss(
            state.critic_params, state, batch, weights, hp, jax.random.split(key)[0]
        )
        return state, td, UpdateMetrics.zeros()

    def act(state: TD3State, obs: jax.Array, key: PRNGKey, hp: HParams) -> Acting:
        """clip(tanh(mu~(s)) + N(0, 0.1^2), -1, 1), mu~ perturbed for Noisy TD3; u(s) as above."""
        k_noise, k_explore = jax.random.split(key)
        out = actor.apply(state.actor_params, obs, k_noise, hp.noisy)
        mean_action = jnp.tanh(out.mean)
        q = critic.apply(state.critic_params, obs, mean_action)
        return Acting(
            action=explore(mean_action, k_explore, cfg.td3_exploration_noise),
            uncertainty=uncertainty(out.mean_var, q, hp.noisy, cfg.uncertainty_reduce),
            sigma=jnp.full(obs.shape[:1], cfg.td3_exploration_noise, jnp.float32),
        )

    def act_deterministic(state: TD3State, obs: jax.Array) -> jax.Array:
        """tanh(mu(s)) with the noise-free mean head (mu_w, mu_b)."""
        return jnp.tanh(
            actor.apply(state.actor_params, obs, jax.random.key(0), jnp.float32(0.0)).mean
        )

    return Agent(
        name="td3",
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


SPEC = AgentSpec(
    name="td3",
    make=make,
    display="TD3",
    noisy_display="NoisyTD3",
    uncertainty_titles={
        "intrinsic": "TD3: twin-critic gap |Q₀ − Q₁|",
        "extrinsic": "Extrinsic uncertainty: Noisy TD3 Var[μ̃]",
    },
    options=TD3Options,
    check=check,
)
