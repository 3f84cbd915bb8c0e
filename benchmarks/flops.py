"""FLOPs of one SAC update, counted by hand and by XLA, and the updates/s they allow."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from arld_jax.config import Config
from arld_jax.networks import NUM_CRITICS


def dense_layers(in_dim: int, hidden: Sequence[int], head_dims: Sequence[int]) -> list:
    """(in, out) of every Dense layer of an MLP trunk followed by parallel heads."""
    dims = [in_dim, *hidden]
    return list(zip(dims[:-1], dims[1:], strict=True)) + [(dims[-1], o) for o in head_dims]


def layer_flops(layers: Sequence[tuple[int, int]], rows: int) -> int:
    """Forward matmul FLOPs of `layers` on `rows` inputs (one multiply-add = 2 FLOPs)."""
    return sum(2 * rows * i * o for i, o in layers)


def analytic_update_flops(
    obs_dim: int, action_dim: int, hidden: Sequence[int], batch: int
) -> dict[str, int]:
    """Matmul FLOPs of ONE `agent.update` (SAC, twin critics, fixed alpha), counted by hand.

    A Dense layer i -> o on B rows costs 2*B*i*o forward; its backward costs 2*B*i*o for the weight
    gradient and another 2*B*i*o for the input gradient, the latter only when something upstream
    needs it (never for the first layer of the differentiated network, whose input is data).

      actor  = obs -> hidden... -> {mean head, log-std head}, each [h_last -> action_dim]
               (the NoisyDense variance matmul x^2 @ sigma_w^2 feeds no loss, so XLA drops it)
      critic = concat(obs, action) -> hidden... -> 1, NUM_CRITICS of them (twin)

      critic loss = actor fwd on next_obs                      (sample a', log pi(a'|s'))
                  + target twin-critic fwd on (next_obs, a')
                  + twin-critic fwd on (obs, action)
                  + twin-critic bwd: weight grads of every layer, input grads of all but the first
      actor loss  = actor fwd on obs
                  + twin-critic fwd on (obs, a) with the new critic params
                  + twin-critic bwd down to the action: input grads of every layer (the first
                    layer's input grad is computed for the whole concat(obs, a), an upper bound),
                    no critic weight grads
                  + actor bwd: weight grads of every layer, input grads of all but the first

    Not counted (elementwise, O(params) or O(B * action_dim)): Adam, Polyak averaging,
    tanh-Gaussian log-probs, losses, noise sampling. XLA's cost analysis counts those too (and may
    count some ops differently), so its figure is somewhat higher.
    """
    actor = dense_layers(obs_dim, hidden, (action_dim, action_dim))
    critic = dense_layers(obs_dim + action_dim, hidden, (1,))
    actor_fwd = layer_flops(actor, batch)
    twin_fwd = NUM_CRITICS * layer_flops(critic, batch)
    twin_input_grads_but_first = NUM_CRITICS * layer_flops(critic[1:], batch)
    actor_input_grads_but_first = layer_flops(actor[1:], batch)
    critic_loss = actor_fwd + twin_fwd + twin_fwd + twin_fwd + twin_input_grads_but_first
    actor_loss = actor_fwd + twin_fwd + twin_fwd + actor_fwd + actor_input_grads_but_first
    return {
        "critic_loss_and_grad": critic_loss,
        "actor_loss_and_grad": actor_loss,
        "total": critic_loss + actor_loss,
        "actor_forward": actor_fwd,
        "twin_critic_forward": twin_fwd,
    }


def xla_flops(compiled: Any) -> float:
    """The 'flops' entry of a compiled program's cost analysis (a dict, or a list of dicts)."""
    cost = compiled.cost_analysis()
    if isinstance(cost, dict):
        cost = [cost]
    return float(sum(c.get("flops", 0.0) for c in cost or [] if c))


def limit_updates_per_s(cfg: Config, obs_dim: int, action_dim: int, gflops: float) -> float:
    """Physical limit of `cfg`'s update (its own sizes): how many updates per second `gflops`
    (a measured 256-wide matmul rate) allows if every matmul ran at that rate and everything else
    were free (`analytic_update_flops`)."""
    flops = analytic_update_flops(obs_dim, action_dim, cfg.hidden_sizes, cfg.batch_size)["total"]
    return gflops * 1e9 / flops
