"""Tests for arld_jax.losses (SAC losses), the tanh-Gaussian log-density and one agent update step.

Loss values are checked against numbers worked out by hand in the comments (STYLE.md habit 12).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from arld_jax import config, losses, networks
from arld_jax.agents import base as agent_base
from arld_jax.agents import sac as agent_lib
from arld_jax.types import Transition

# vmapped over a batch exactly as agent.py does it.
_soft_q_target_batch = jax.vmap(losses.soft_q_target, in_axes=(0, 0, 0, 0, None, None, None))


# ---------------------------------------------------------------- soft_q_target


def test_soft_q_target_hand_computed() -> None:
    # alpha = 0.2, gamma = 0.9, reward_scale = 2.
    # row 0: r=1,    d=0, Q'=[2, 3],  logp'=-0.5: V' = min(2,3) - 0.2*(-0.5) = 2.1
    #        y = 2*1 + 0.9*1*2.1 = 3.89
    # row 1: r=1,    d=1, Q'=[2, 3],  logp'=-0.5: terminated, no bootstrap: y = 2*1 = 2
    # row 2: r=-0.5, d=0, Q'=[4, -1], logp'=1.0:  V' = -1 - 0.2*1 = -1.2
    #        y = 2*(-0.5) + 0.9*(-1.2) = -1 - 1.08 = -2.08
    reward = jnp.array([1.0, 1.0, -0.5])
    terminated = jnp.array([0.0, 1.0, 0.0])
    next_q = jnp.array([[2.0, 3.0], [2.0, 3.0], [4.0, -1.0]])
    next_log_prob = jnp.array([-0.5, -0.5, 1.0])
    y = _soft_q_target_batch(reward, terminated, next_q, next_log_prob, 0.2, 0.9, 2.0)
    np.testing.assert_allclose(y, [3.89, 2.0, -2.08], rtol=1e-6)


def test_soft_q_target_uses_the_smaller_critic() -> None:
    # r=0, d=0, gamma=1, alpha=0 -> y = min(Q'); swapping the critics must not matter.
    for next_q, expected in (([5.0, -3.0], -3.0), ([-3.0, 5.0], -3.0), ([1.0, 1.5], 1.0)):
        y = losses.soft_q_target(0.0, 0.0, jnp.array(next_q), 0.0, 0.0, 0.99, 1.0)
        np.testing.assert_allclose(y, 0.99 * expected, rtol=1e-6)


def test_terminated_stops_bootstrapping() -> None:
    """With terminated = 1 the target is reward_scale * r whatever Q' and log pi' are, and no
    gradient reaches Q'; with terminated = 0 it does (gamma per unit of the smaller critic)."""

    def target(next_q: jax.Array, terminated: float) -> jax.Array:
        return losses.soft_q_target(0.7, terminated, next_q, -1.3, 0.2, 0.9, 3.0)

    for next_q in (jnp.array([100.0, 50.0]), jnp.array([-7.0, 2.0])):
        np.testing.assert_allclose(target(next_q, 1.0), 3.0 * 0.7, rtol=1e-6)
        np.testing.assert_array_equal(jax.grad(target)(next_q, 1.0), [0.0, 0.0])
    # Not terminated: dy/dQ'_k = gamma at the argmin critic, 0 at the other.
    np.testing.assert_allclose(jax.grad(target)(jnp.array([-7.0, 2.0]), 0.0), [0.9, 0.0])


# ---------------------------------------------------------------- critic loss

# Shared tiny batch: 3 transitions, 2 critics.
_Q = jnp.array([[1.0, 2.0], [0.0, -1.0], [3.0, 3.0]])
_Y = jnp.array([1.5, 0.5, 2.0])
_W = jnp.array([1.0, 2.0, 0.5])
# td = Q - y:   row 0 [-0.5, 0.5], row 1 [-0.5, -1.5], row 2 [1, 1]
# per-sample l_i = 0.5 * sum_k td^2: row 0 0.5*(0.25+0.25) = 0.25
#                                    row 1 0.5*(0.25+2.25) = 1.25
#                                    row 2 0.5*(1+1)       = 1.0
_PER_SAMPLE = np.array([0.25, 1.25, 1.0])


def test_critic_loss_hand_computed() -> None:
    # L = mean_i w_i l_i = (1*0.25 + 2*1.25 + 0.5*1.0) / 3 = 3.25 / 3
    # td_error_i = mean_k td: row 0 0 (the critics' errors cancel), row 1 -1, row 2 1
    loss, td = losses.critic_loss_from_values(_Q, _Y, _W)
    np.testing.assert_allclose(loss, 3.25 / 3, rtol=1e-6)
    np.testing.assert_allclose(td, [0.0, -1.0, 1.0], atol=1e-7)


@pytest.mark.parametrize("i", [0, 1, 2])
def test_importance_weights_scale_each_sample(i: int) -> None:
    # A one-hot weight keeps only sample i: L = l_i / B; scaling it by 3 scales L by 3.
    onehot = jnp.zeros(3).at[i].set(1.0)
    loss, _ = losses.critic_loss_from_values(_Q, _Y, onehot)
    np.testing.assert_allclose(loss, _PER_SAMPLE[i] / 3, rtol=1e-6)
    loss3, td3 = losses.critic_loss_from_values(_Q, _Y, 3.0 * onehot)
    np.testing.assert_allclose(loss3, _PER_SAMPLE[i], rtol=1e-6)
    # The weights scale the loss, not the TD errors that become priorities.
    np.testing.assert_allclose(td3, [0.0, -1.0, 1.0], atol=1e-7)


def test_critic_loss_gradients() -> None:
    """No gradient reaches the target (stop_gradient); dL/dQ_ik = w_i td_ik / B."""
    grad_y = jax.grad(lambda y: losses.critic_loss_from_values(_Q, y, _W)[0])(_Y)
    np.testing.assert_array_equal(grad_y, [0.0, 0.0, 0.0])
    grad_q = jax.grad(lambda q: losses.critic_loss_from_values(q, _Y, _W)[0])(_Q)
    # row 0: 1*[-0.5, 0.5]/3; row 1: 2*[-0.5, -1.5]/3; row 2: 0.5*[1, 1]/3
    expected = np.array([[-1 / 6, 1 / 6], [-1 / 3, -1.0], [1 / 6, 1 / 6]])
    np.testing.assert_allclose(grad_q, expected, rtol=1e-6)


# ---------------------------------------------------------------- actor and alpha losses


def test_actor_loss_hand_computed() -> None:
    # alpha = 0.2; row 0: 0.2*(-1)  - min(2, 1)  = -1.2
    #              row 1: 0.2*(0.5) - min(-1, 0) =  1.1;   mean = -0.05
    log_prob = jnp.array([-1.0, 0.5])
    q = jnp.array([[2.0, 1.0], [-1.0, 0.0]])
    np.testing.assert_allclose(losses.actor_loss_from_values(log_prob, q, 0.2), -0.05, atol=1e-7)
    # dL/dlogp = alpha / B = 0.1; dL/dQ = -1/B at the smaller critic only.
    g_lp, g_q = jax.grad(losses.actor_loss_from_values, argnums=(0, 1))(log_prob, q, 0.2)
    np.testing.assert_allclose(g_lp, [0.1, 0.1], rtol=1e-6)
    np.testing.assert_allclose(g_q, [[0.0, -0.5], [-0.5, 0.0]], rtol=1e-6)


def test_alpha_loss_hand_computed() -> None:
    # alpha = 0.5, target entropy -2: mean(logp + H*) = mean([-3, -4, -2]) = -3
    # L = -0.5 * (-3) = 1.5; dL/dlog_alpha = -alpha * (-3) = 1.5 > 0: gradient descent lowers
    # alpha, as it should since the entropy (1) is above the target (-2).
    log_alpha = jnp.log(0.5)
    log_prob = jnp.array([-1.0, -2.0, 0.0])
    np.testing.assert_allclose(losses.alpha_loss_from_values(log_alpha, log_prob, -2.0), 1.5)
    g_alpha, g_lp = jax.grad(losses.alpha_loss_from_values, argnums=(0, 1))(
        log_alpha, log_prob, -2.0
    )
    np.testing.assert_allclose(g_alpha, 1.5, rtol=1e-6)
    np.testing.assert_array_equal(g_lp, [0.0, 0.0, 0.0])  # log pi is a constant for alpha
    # Entropy below target (logp = 3 > 2): the gradient flips sign, alpha rises.
    assert jax.grad(losses.alpha_loss_from_values)(log_alpha, jnp.array([3.0]), -2.0) < 0


# ---------------------------------------------------------------- tanh-Gaussian


def test_tanh_log_det_jacobian_matches_direct_formula() -> None:
    u = np.linspace(-4.0, 4.0, 81)
    direct = np.log(1.0 - np.tanh(u) ** 2)  # float64 reference
    got = networks.tanh_log_det_jacobian(jnp.asarray(u, jnp.float32))
    np.testing.assert_allclose(got, direct, rtol=1e-5, atol=1e-5)
    # Far in the tails the direct float32 formula gives -inf; the stable one follows
    # log(1 - tanh^2 u) -> 2 (log 2 - |u|).
    big = jnp.array([-30.0, 30.0])
    np.testing.assert_allclose(
        networks.tanh_log_det_jacobian(big), 2 * (np.log(2.0) - 30.0), rtol=1e-6
    )


def _policy(mean: np.ndarray, log_std: np.ndarray) -> networks.PolicyOutput:
    mean = jnp.asarray(mean, jnp.float32)
    return networks.PolicyOutput(
        mean=mean, log_std=jnp.asarray(log_std, jnp.float32), mean_var=jnp.zeros_like(mean)
    )


def test_sample_action_log_prob_matches_direct_computation() -> None:
    """log pi(a|s) = sum_j [log N(u_j; mu_j, sigma_j) - log(1 - tanh(u_j)^2)], u = atanh(a)."""
    mean = np.array([[0.3, -0.2], [0.0, 0.5], [-0.4, 0.1]])
    log_std = np.array([[-0.5, 0.1], [-1.0, -0.3], [0.0, -2.0]])
    action, log_prob = networks.sample_action(_policy(mean, log_std), jax.random.key(42))
    assert action.shape == (3, 2) and log_prob.shape == (3,)
    a = np.asarray(action, np.float64)
    assert np.all(np.abs(a) < 0.999)  # keep atanh well conditioned for the reference
    u = np.arctanh(a)
    expected = np.sum(
        stats.norm.logpdf(u, loc=mean, scale=np.exp(log_std)) - np.log(1.0 - a**2), axis=-1
    )
    np.testing.assert_allclose(log_prob, expected, rtol=1e-4, atol=1e-4)


def test_sample_action_is_tanh_of_the_gaussian() -> None:
    """atanh of the sampled actions is N(mu, sigma^2) per dimension (KS test, 4000 keys)."""
    mean = np.array([[0.3, -0.6]])
    log_std = np.array([[-0.7, -1.2]])
    keys = jax.random.split(jax.random.key(7), 4000)
    actions, _ = jax.vmap(lambda k: networks.sample_action(_policy(mean, log_std), k))(keys)
    u = np.arctanh(np.asarray(actions, np.float64)[:, 0, :])
    for j in range(2):
        p = stats.kstest(u[:, j], stats.norm(mean[0, j], np.exp(log_std[0, j])).cdf).pvalue
        assert p > 1e-4, (j, p)


# ---------------------------------------------------------------- agent update

OBS_DIM, ACTION_DIM, BATCH = 3, 2, 8
TAU = 0.1
INIT_ALPHA = 0.2


def test_polyak_on_a_small_tree() -> None:
    # theta' <- (1 - 0.1) theta' + 0.1 theta:  a: 0.9*[0, 10] + 0.1*[1, 0] = [0.1, 9.0]
    #                                          b: 0.9*4 + 0.1*0 = 3.6
    target = {"a": jnp.array([0.0, 10.0]), "b": jnp.array(4.0)}
    online = {"a": jnp.array([1.0, 0.0]), "b": jnp.array(0.0)}
    new = agent_base.polyak(target, online, 0.1)
    np.testing.assert_allclose(new["a"], [0.1, 9.0], rtol=1e-6)
    np.testing.assert_allclose(new["b"], 3.6, rtol=1e-6)


def _cfg(autotune: bool) -> config.Config:
    return config.tiny(
        hidden_sizes=(16, 16),
        autotune_alpha=autotune,
        tau=TAU,
        init_alpha=INIT_ALPHA,
        critic_lr=1e-3,
        alpha_lr=1e-2,
    )


class _Compiled:
    """An agent with its update jitted once (per config), shared by the tests of this module."""

    def __init__(self, autotune: bool) -> None:
        cfg = _cfg(autotune)
        self.agent = agent_lib.make(cfg, OBS_DIM, ACTION_DIM)
        self.hp = config.hparams_from_config(cfg)
        self._update = jax.jit(self.agent.update)
        self._init = jax.jit(self.agent.init)  # one compile instead of op-by-op dispatch

    def update(self, state, batch, weights, hp, key):  # noqa: ANN001, ANN201
        """The agent's update; SAC ignores the replay indices (no bootstrap masks)."""
        return self._update(state, batch, weights, jnp.arange(weights.shape[0]), hp, key)

    def init(self) -> agent_lib.SACState:
        return self._init(jax.random.key(0), self.hp)


@pytest.fixture(scope="module")
def fixed_alpha_agent() -> _Compiled:
    return _Compiled(autotune=False)


@pytest.fixture(scope="module")
def tuned_alpha_agent() -> _Compiled:
    return _Compiled(autotune=True)


def _batch() -> tuple[Transition, jax.Array]:
    rng = np.random.default_rng(0)
    f32 = np.float32
    batch = Transition(
        obs=jnp.asarray(rng.normal(size=(BATCH, OBS_DIM)), f32),
        action=jnp.asarray(rng.uniform(-1, 1, size=(BATCH, ACTION_DIM)), f32),
        reward=jnp.asarray(rng.normal(2.0, 1.0, size=BATCH), f32),
        next_obs=jnp.asarray(rng.normal(size=(BATCH, OBS_DIM)), f32),
        terminated=jnp.asarray([0, 0, 0, 1, 0, 0, 1, 0], f32),
        is_demo=jnp.zeros(BATCH, f32),
    )
    weights = jnp.asarray(rng.uniform(0.5, 1.0, size=BATCH), f32)
    return batch, weights


def test_critic_loss_decreases_on_a_fixed_batch(fixed_alpha_agent: _Compiled) -> None:
    a = fixed_alpha_agent
    state = a.init()
    batch, weights = _batch()
    # A shorter horizon and a larger step so 50 updates are enough; HParams are traced, so this
    # reuses the compiled update.
    hp = a.hp.replace(gamma=jnp.asarray(0.5, jnp.float32), critic_lr=jnp.asarray(3e-3, jnp.float32))
    losses_seen = []
    for i in range(50):
        state, td, metrics = a.update(state, batch, weights, hp, jax.random.key(i))
        losses_seen.append(float(metrics.critic_loss))
    assert td.shape == (BATCH,)
    assert np.all(np.isfinite(losses_seen))
    # Rewards ~2 (std 1) against Q ~0 at init: the loss starts around 0.5*2*(2^2+1)*0.75 ~ 4.
    assert losses_seen[0] > 1.0
    assert np.mean(losses_seen[-5:]) < 0.25 * losses_seen[0], losses_seen


def test_target_critic_moves_by_tau_towards_new_online(fixed_alpha_agent: _Compiled) -> None:
    a = fixed_alpha_agent
    state = a.init()
    # Start from a target that differs from the online critics so the check is not vacuous.
    state = state.replace(target_critic_params=jax.tree.map(lambda p: p + 1.0, state.critic_params))
    batch, weights = _batch()
    new, _, _ = a.update(state, batch, weights, a.hp, jax.random.key(1))
    moved = jax.tree.leaves(
        jax.tree.map(
            lambda n, o: float(jnp.max(jnp.abs(n - o))), new.critic_params, state.critic_params
        )
    )
    assert max(moved) > 0  # the online critics did change
    expected = jax.tree.map(
        lambda t, o: (1 - TAU) * t + TAU * o, state.target_critic_params, new.critic_params
    )
    for got, want in zip(
        jax.tree.leaves(new.target_critic_params), jax.tree.leaves(expected), strict=True
    ):
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6)


def test_fixed_alpha_stays_at_init(fixed_alpha_agent: _Compiled) -> None:
    a = fixed_alpha_agent
    state = a.init()
    batch, weights = _batch()
    for i in range(5):
        state, _, metrics = a.update(state, batch, weights, a.hp, jax.random.key(i))
    np.testing.assert_allclose(jnp.exp(state.log_alpha), INIT_ALPHA, rtol=1e-6)
    np.testing.assert_allclose(metrics.alpha, INIT_ALPHA, rtol=1e-6)


@pytest.mark.parametrize("log_std_bias", [0.0, -8.0])
def test_autotuned_alpha_moves_against_the_entropy_gap(
    tuned_alpha_agent: _Compiled, log_std_bias: float
) -> None:
    """Entropy above the target -dim(A) lowers alpha; far below it (sigma ~ e^-8) raises it."""
    a = tuned_alpha_agent
    state = a.init()
    params = state.actor_params
    head = params["params"]["log_std_head"]
    head = {
        "kernel": jnp.zeros_like(head["kernel"]),
        "bias": jnp.full_like(head["bias"], log_std_bias),
    }
    params = {"params": {**params["params"], "log_std_head": head}}
    state = state.replace(actor_params=params)
    batch, weights = _batch()
    new, _, metrics = a.update(state, batch, weights, a.hp, jax.random.key(3))
    target_entropy = -ACTION_DIM
    alpha0, alpha1 = INIT_ALPHA, float(jnp.exp(new.log_alpha))
    np.testing.assert_allclose(metrics.alpha, alpha1, rtol=1e-6)
    if log_std_bias == 0.0:
        assert metrics.entropy > target_entropy
        assert alpha1 < alpha0
    else:
        assert metrics.entropy < target_entropy
        assert alpha1 > alpha0


def test_no_update_measures_the_same_td_and_changes_nothing(fixed_alpha_agent: _Compiled) -> None:
    """The warm-up variant returns the TD errors `update` would use for priorities, same key."""
    a = fixed_alpha_agent
    state = a.init()
    batch, weights = _batch()
    key = jax.random.key(5)
    idx = jnp.arange(weights.shape[0])
    kept, td0, metrics = jax.jit(a.agent.no_update)(state, batch, weights, idx, a.hp, key)
    _, td1, _ = a.update(state, batch, weights, a.hp, key)
    np.testing.assert_allclose(td0, td1, rtol=1e-5, atol=1e-6)
    assert np.max(np.abs(np.asarray(td0))) > 0.1  # rewards ~2 vs Q ~0: a real TD error
    for got, want in zip(jax.tree.leaves(kept), jax.tree.leaves(state), strict=True):
        np.testing.assert_array_equal(got, want)
    assert float(metrics.critic_loss) == float(metrics.actor_loss) == 0.0
    np.testing.assert_allclose(metrics.alpha, INIT_ALPHA, rtol=1e-6)


def test_autotune_is_a_sweepable_value(fixed_alpha_agent: _Compiled) -> None:
    """One compiled update vmapped over hp.autotune_alpha = (0, 1): the run with 0 keeps alpha at
    its initial value, the run with 1 moves it (so fixed and tuned cells share one program)."""
    a = fixed_alpha_agent
    state = a.init()
    batch, weights = _batch()
    hps = jax.tree.map(lambda x: jnp.stack([x, x]), a.hp)
    hps = hps.replace(autotune_alpha=jnp.array([0.0, 1.0]))
    states = jax.tree.map(lambda x: jnp.stack([x, x]), state)
    update = jax.jit(jax.vmap(a.agent.update, in_axes=(0, None, None, None, 0, None)))
    new, _, _ = update(states, batch, weights, jnp.arange(weights.shape[0]), hps, jax.random.key(0))
    alphas = np.exp(np.asarray(new.log_alpha))
    np.testing.assert_allclose(alphas[0], INIT_ALPHA, rtol=1e-6)
    assert abs(alphas[1] - INIT_ALPHA) > 1e-5
