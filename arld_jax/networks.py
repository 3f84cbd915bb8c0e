"""Actor (tanh-Gaussian with an optionally noisy mean head) and twin critics.

Paper A.1: actor = two hidden layers of 256 ReLU units, then two linear heads (mean and log-std of a
Gaussian per action dimension), squashed by tanh into [-1, 1]; critic = two hidden layers of 256 ReLU
units and a linear Q output. (A.1 says "tanh on the output layers"; we read that as the actor's action
squashing only: a tanh on Q would cap returns at 1.)

The mean head is always a `NoisyDense`. With `noise_scale = 0` it is exactly a plain linear layer
(plain SAC); with `noise_scale = 1` the agent is Noisy SAC (paper 3.1). Keeping both agents on one
parameter structure lets one compiled program vmap over the uncertainty choice.
"""

from __future__ import annotations

from collections.abc import Sequence

import flax.linen as nn
import flax.struct
import jax
import jax.numpy as jnp

from arld_jax.types import PRNGKey

NUM_CRITICS = 2


@jax.custom_vjp
def head_matmul(x: jax.Array, w: jax.Array) -> jax.Array:
    """x @ w for an output head with few columns (the actor's action-sized heads), [..., I] @ [I, O].

    The same product; only the weight gradient is computed differently. d/dw = x^T g contracts
    the batch axis, the leading axis of both operands, and XLA:CPU hands that dot to its generic
    kernel (`python -m benchmarks.dot_layouts`), which is slow when the output has few columns: 75 us for
    256x256x6, where the forward x @ w takes 11 us. Writing x^T out first (`optimization_barrier`
    keeps XLA from folding the transpose back into the dot) turns it into a plain row-major
    product: 36 us. Both heads of `Actor` read the same phi, so XLA computes its transpose once.
    The whole 16-env trainer ran 1.10-1.12x faster with it (benchmarks/README.md, "Where the
    update's time went, and three changes"); on the 256-wide hidden layers the same form made the
    update slower (0.94-0.97x, "Why the weight gradients are the slow dots, and why that does not
    help"), so only the heads use it. On a GPU it costs one small transpose. Not bit-identical
    to autodiff's x^T g (another summation order over the batch); learning with it is checked in
    experiments/README.md."""
    return x @ w


def _head_matmul_fwd(x: jax.Array, w: jax.Array) -> tuple[jax.Array, tuple[jax.Array, jax.Array]]:
    return x @ w, (x, w)


def _head_matmul_bwd(
    residuals: tuple[jax.Array, jax.Array], g: jax.Array
) -> tuple[jax.Array, jax.Array]:
    x, w = residuals
    x_t = jax.lax.optimization_barrier(x.reshape(-1, x.shape[-1]).T)  # [I, batch]
    return g @ w.T, x_t @ g.reshape(-1, g.shape[-1])


head_matmul.defvjp(_head_matmul_fwd, _head_matmul_bwd)


def _head_dot_general(
    x: jax.Array, w: jax.Array, dimension_numbers: object, precision: object = None
) -> jax.Array:
    """`nn.Dense(dot_general=...)` form of `head_matmul` (Dense contracts x's last axis with w's
    first, which is what `head_matmul` computes)."""
    return head_matmul(x, w)


@flax.struct.dataclass
class PolicyOutput:
    """The actor's output for a batch of observations (all [..., action_dim])."""

    mean: jax.Array  # pre-tanh mean; the perturbed mean mu~ for Noisy SAC (paper 3.1)
    log_std: jax.Array  # log sigma_theta(s), clipped
    mean_var: jax.Array  # analytic Var[mu~] = phi^T diag(sigma_w^2) phi + sigma_b^2 (paper 3.1)


class MLP(nn.Module):
    """ReLU hidden layers; matmul inputs in `dtype`, outputs back in float32."""

    hidden_sizes: Sequence[int]
    dtype: jnp.dtype = jnp.float32

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        for width in self.hidden_sizes:
            x = nn.relu(nn.Dense(width, dtype=self.dtype)(x))
        return x.astype(jnp.float32)


class NoisyDense(nn.Module):
    """Linear layer with independent Gaussian weight noise (Fortunato et al. 2017, 'independent').

    w = mu_w + noise_scale * sigma_w * eps_w and b = mu_b + noise_scale * sigma_b * eps_b, with fresh
    eps ~ N(0, 1) at every call, shared across the leading batch axes (as in NoisyNet). Independent
    (not factorised) noise is what makes the paper's analytic variance exact: each weight is then an
    independent Gaussian, w_ij ~ N(mu_w_ij, sigma_w_ij^2).
    """

    features: int
    sigma_init: float = 0.017
    draw_noise: bool = True
    """False: no noise is drawn and the layer is mu_w, mu_b, exactly what noise_scale = 0 gives
    (same parameters; `Config.noisy_runs`). For programs without a noisy run: the draws are 12% of
    an update on CPU, where XLA lowers the threefry generator as a rolled loop."""

    @nn.compact
    def __call__(
        self, x: jax.Array, noise_key: PRNGKey, noise_scale: jax.Array
    ) -> tuple[jax.Array, jax.Array]:
        in_features = x.shape[-1]
        bound = 1.0 / jnp.sqrt(in_features)
        uniform = lambda key, shape: jax.random.uniform(key, shape, minval=-bound, maxval=bound)  # noqa: E731
        const = nn.initializers.constant(self.sigma_init)
        mu_w = self.param("mu_w", uniform, (in_features, self.features))
        sigma_w = self.param("sigma_w", const, (in_features, self.features))
        mu_b = self.param("mu_b", uniform, (self.features,))
        sigma_b = self.param("sigma_b", const, (self.features,))
        if self.draw_noise:
            k_w, k_b = jax.random.split(noise_key)
            eps_w = jax.random.normal(k_w, mu_w.shape)
            eps_b = jax.random.normal(k_b, mu_b.shape)
            w = mu_w + noise_scale * sigma_w * eps_w
            b = mu_b + noise_scale * sigma_b * eps_b
        else:
            w, b = mu_w, mu_b
        out = head_matmul(x, w) + b
        # Paper 3.1: Var[w phi + b] = phi^T diag(sigma_w^2) phi + Var[b]. The paper writes "+ sigma_b";
        # the variance of b ~ N(mu_b, sigma_b^2) is sigma_b^2, which is what we use.
        var = jnp.square(x) @ jnp.square(sigma_w) + jnp.square(sigma_b)
        return out, var


class Actor(nn.Module):
    """Tanh-Gaussian policy pi(a|s) = tanh(N(mu(s), sigma(s)^2)) with a (possibly noisy) mean head."""

    action_dim: int
    hidden_sizes: Sequence[int] = (256, 256)
    log_std_min: float = -20.0
    log_std_max: float = 2.0
    sigma_init: float = 0.017
    dtype: jnp.dtype = jnp.float32
    draw_noise: bool = True  # False: a plain mean head (`NoisyDense.draw_noise`)

    @nn.compact
    def __call__(self, obs: jax.Array, noise_key: PRNGKey, noise_scale: jax.Array) -> PolicyOutput:
        phi = MLP(self.hidden_sizes, self.dtype)(obs)  # phi(s): the mean head's input
        head = NoisyDense(self.action_dim, self.sigma_init, self.draw_noise, name="mean_head")
        mean, mean_var = head(phi, noise_key, noise_scale)
        log_std = nn.Dense(self.action_dim, name="log_std_head", dot_general=_head_dot_general)(phi)
        log_std = jnp.clip(log_std, self.log_std_min, self.log_std_max)
        return PolicyOutput(mean=mean, log_std=log_std, mean_var=mean_var)


class QNetwork(nn.Module):
    """One critic Q(s, a)."""

    hidden_sizes: Sequence[int] = (256, 256)
    dtype: jnp.dtype = jnp.float32

    @nn.compact
    def __call__(self, obs: jax.Array, action: jax.Array) -> jax.Array:
        x = MLP(self.hidden_sizes, self.dtype)(jnp.concatenate([obs, action], axis=-1))
        return nn.Dense(1)(x)[..., 0]


class TwinCritic(nn.Module):
    """NUM_CRITICS independent critics (clipped double Q); output [..., NUM_CRITICS].

    Two separate QNetworks (parameters `q0`, `q1`), not one `nn.vmap`-stacked ensemble: on XLA:CPU
    the stacked form's batched weight-gradient dots are slower, and separate critics made the
    whole update ~10% faster here (benchmarks/README.md, "Separate twin critics, a full run on another host").
    """

    hidden_sizes: Sequence[int] = (256, 256)
    dtype: jnp.dtype = jnp.float32

    @nn.compact
    def __call__(self, obs: jax.Array, action: jax.Array) -> jax.Array:
        qs = [
            QNetwork(self.hidden_sizes, self.dtype, name=f"q{k}")(obs, action)
            for k in range(NUM_CRITICS)
        ]
        return jnp.stack(qs, axis=-1)


# ---------------------------------------------------------------- tanh-Gaussian helpers

_LOG_2 = jnp.log(2.0)


def tanh_log_det_jacobian(pre_tanh: jax.Array) -> jax.Array:
    """log |d tanh(u)/du| = log(1 - tanh(u)^2), in the stable form 2 (log 2 - u - softplus(-2u))."""
    return 2.0 * (_LOG_2 - pre_tanh - jax.nn.softplus(-2.0 * pre_tanh))


def sample_action(policy: PolicyOutput, key: PRNGKey) -> tuple[jax.Array, jax.Array]:
    """a = tanh(mu + sigma * xi), xi ~ N(0, I) (paper 3.2), and log pi(a|s) summed over dimensions."""
    std = jnp.exp(policy.log_std)
    xi = jax.random.normal(key, policy.mean.shape)
    pre_tanh = policy.mean + std * xi
    gaussian_log_prob = -0.5 * jnp.square(xi) - policy.log_std - 0.5 * jnp.log(2.0 * jnp.pi)
    log_prob = jnp.sum(gaussian_log_prob - tanh_log_det_jacobian(pre_tanh), axis=-1)
    return jnp.tanh(pre_tanh), log_prob


def deterministic_action(policy: PolicyOutput) -> jax.Array:
    """The evaluation action tanh(mu(s)) (paper 3.2: noise removed when validating)."""
    return jnp.tanh(policy.mean)


# ---------------------------------------------------------------- TD3 family (Fujimoto et al. 2018)


@flax.struct.dataclass
class DeterministicOutput:
    """A deterministic actor's output (all [..., action_dim]); the action is tanh(mean)."""

    mean: jax.Array  # pre-tanh mu(s); the perturbed mean mu~ for Noisy TD3
    mean_var: jax.Array  # analytic Var[mu~] = phi^T diag(sigma_w^2) phi + sigma_b^2 (paper 3.1)


class DeterministicActor(nn.Module):
    """TD3's actor a = tanh(mu(s)) (Fujimoto et al. 2018), with SAC's torso and noisy mean head.

    The same `MLP_0` torso and `NoisyDense` "mean_head" as `Actor`, without the log-std head: with
    `noise_scale = 0` it is TD3's deterministic actor, with 1 it is Noisy TD3 (parameter noise on the
    actor, Plappert et al. 2017; independent Gaussian noise, Fortunato et al. 2017)."""

    action_dim: int
    hidden_sizes: Sequence[int] = (256, 256)
    sigma_init: float = 0.017
    dtype: jnp.dtype = jnp.float32
    draw_noise: bool = True  # False: a plain mean head (`NoisyDense.draw_noise`)

    @nn.compact
    def __call__(
        self, obs: jax.Array, noise_key: PRNGKey, noise_scale: jax.Array
    ) -> DeterministicOutput:
        phi = MLP(self.hidden_sizes, self.dtype)(obs)
        head = NoisyDense(self.action_dim, self.sigma_init, self.draw_noise, name="mean_head")
        mean, mean_var = head(phi, noise_key, noise_scale)
        return DeterministicOutput(mean=mean, mean_var=mean_var)


class MultiHeadActor(nn.Module):
    """Bootstrapped actor: K deterministic heads on one shared torso (Osband et al. 2016, carried
    from DQN's Q heads to TD3's actor). Output: pre-tanh means [..., K, action_dim]."""

    action_dim: int
    num_heads: int
    hidden_sizes: Sequence[int] = (256, 256)
    dtype: jnp.dtype = jnp.float32

    @nn.compact
    def __call__(self, obs: jax.Array) -> jax.Array:
        phi = MLP(self.hidden_sizes, self.dtype)(obs)
        out = nn.Dense(self.num_heads * self.action_dim, name="heads")(phi)
        return out.reshape(*out.shape[:-1], self.num_heads, self.action_dim)


class MultiHeadQNetwork(nn.Module):
    """One critic torso with K linear Q heads: Q_k(s, a), k = 1..K (Osband et al. 2016).

    `action` is either one action per state, [..., A] (every head scores it: the critic loss on
    replayed actions, one torso pass), or one action per head, [..., K, A] (head k scores its own
    action, e.g. its own actor's: K torso passes, head k's output kept). Output [..., K]."""

    num_heads: int
    hidden_sizes: Sequence[int] = (256, 256)
    dtype: jnp.dtype = jnp.float32

    @nn.compact
    def __call__(self, obs: jax.Array, action: jax.Array) -> jax.Array:
        per_head = action.ndim == obs.ndim + 1
        if per_head:
            obs = jnp.broadcast_to(obs[..., None, :], (*action.shape[:-1], obs.shape[-1]))
        x = MLP(self.hidden_sizes, self.dtype)(jnp.concatenate([obs, action], axis=-1))
        q = nn.Dense(self.num_heads, name="head")(x)  # [..., K] or [..., K(action), K(head)]
        return jnp.diagonal(q, axis1=-2, axis2=-1) if per_head else q


class MultiHeadTwinCritic(nn.Module):
    """Bootstrapped twin critics: two independent torsos (`q0`, `q1`, as in `TwinCritic`, so the
    clipped double-Q estimates stay independent), each with K heads. Output [..., K, NUM_CRITICS].

    Shared torsos rather than K x 2 separate networks: the same cost as `TwinCritic` on replayed
    actions, and bootstrapped DQN's own layout (one torso, K heads)."""

    num_heads: int
    hidden_sizes: Sequence[int] = (256, 256)
    dtype: jnp.dtype = jnp.float32

    @nn.compact
    def __call__(self, obs: jax.Array, action: jax.Array) -> jax.Array:
        qs = [
            MultiHeadQNetwork(self.num_heads, self.hidden_sizes, self.dtype, name=f"q{k}")(
                obs, action
            )
            for k in range(NUM_CRITICS)
        ]
        return jnp.stack(qs, axis=-1)
