"""Tests for arld_jax.networks (noisy mean head, log-std clip, twin critics), agent.uncertainty."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from arld_jax import networks
from arld_jax.agents import sac as agent_lib

OBS_DIM, ACTION_DIM, HIDDEN = 4, 3, (8, 8)
NUM_SAMPLES = 20_000


def _phi(params: dict, obs: np.ndarray) -> np.ndarray:
    """The mean head's input phi(s), recomputed from the MLP parameters in float64."""
    x = np.asarray(obs, np.float64)
    mlp = params["params"]["MLP_0"]
    for i in range(len(HIDDEN)):
        layer = mlp[f"Dense_{i}"]
        x = np.maximum(x @ np.asarray(layer["kernel"], np.float64) + np.asarray(layer["bias"]), 0.0)
    return x


@pytest.fixture(scope="module")
def noisy_actor() -> tuple[networks.Actor, dict, np.ndarray]:
    """An actor whose noisy head has non-trivial, unequal sigma_w and sigma_b (~0.3)."""
    actor = networks.Actor(action_dim=ACTION_DIM, hidden_sizes=HIDDEN)
    obs = np.array([[0.8, -1.1, 0.5, 1.3]], np.float32)
    params = jax.jit(actor.init)(jax.random.key(0), obs, jax.random.key(1), jnp.float32(0.0))
    rng = np.random.default_rng(0)
    head = dict(params["params"]["mean_head"])
    head["sigma_w"] = jnp.asarray(0.3 * rng.uniform(0.5, 1.5, head["sigma_w"].shape), jnp.float32)
    head["sigma_b"] = jnp.asarray(0.3 * rng.uniform(0.5, 1.5, head["sigma_b"].shape), jnp.float32)
    params = {"params": {**params["params"], "mean_head": head}}
    assert np.count_nonzero(_phi(params, obs)) >= 2  # some hidden units are active
    return actor, params, obs


def test_noisy_mean_variance_matches_monte_carlo(noisy_actor) -> None:  # noqa: ANN001
    """Paper 3.1: Var[mu~] = phi^T diag(sigma_w^2) phi + sigma_b^2, checked per action dimension
    against the sample variance of 20,000 independently perturbed means (chi-square test)."""
    actor, params, obs = noisy_actor
    keys = jax.random.split(jax.random.key(123), NUM_SAMPLES)
    out = jax.jit(jax.vmap(lambda k: actor.apply(params, obs, k, jnp.float32(1.0))))(keys)
    samples = np.asarray(out.mean, np.float64)[:, 0, :]  # [N, A]
    mean_var = np.asarray(out.mean_var)[0, 0]  # identical for every key
    np.testing.assert_array_equal(
        np.asarray(out.mean_var), np.broadcast_to(out.mean_var[0], out.mean_var.shape)
    )

    # The analytic variance itself, recomputed by hand.
    head = params["params"]["mean_head"]
    phi = _phi(params, obs)[0]
    sw, sb = np.asarray(head["sigma_w"], np.float64), np.asarray(head["sigma_b"], np.float64)
    np.testing.assert_allclose(mean_var, phi**2 @ sw**2 + sb**2, rtol=1e-5)

    n = NUM_SAMPLES
    sample_var = samples.var(axis=0, ddof=1)
    for j in range(ACTION_DIM):
        chi2 = (n - 1) * sample_var[j] / mean_var[j]
        p = 2 * min(stats.chi2.cdf(chi2, n - 1), stats.chi2.sf(chi2, n - 1))
        assert p > 1e-4, (j, sample_var[j], mean_var[j], p)
    # Relative error of a variance estimate is sqrt(2/(n-1)) = 1%: 5% is 5 sd.
    np.testing.assert_allclose(sample_var, mean_var, rtol=0.05)
    # And the perturbed mean is centred on the noise-free one.
    mu = phi @ np.asarray(head["mu_w"], np.float64) + np.asarray(head["mu_b"], np.float64)
    np.testing.assert_array_less(np.abs(samples.mean(axis=0) - mu), 5 * np.sqrt(mean_var / n))


def test_noise_scale_zero_is_the_plain_linear_head(noisy_actor) -> None:  # noqa: ANN001
    actor, params, obs = noisy_actor
    apply = jax.jit(actor.apply)
    out1 = apply(params, obs, jax.random.key(1), jnp.float32(0.0))
    out2 = apply(params, obs, jax.random.key(2), jnp.float32(0.0))
    np.testing.assert_array_equal(out1.mean, out2.mean)  # no noise at all
    head = params["params"]["mean_head"]
    expected = _phi(params, obs) @ np.asarray(head["mu_w"], np.float64) + np.asarray(head["mu_b"])
    np.testing.assert_allclose(out1.mean, expected, rtol=1e-5, atol=1e-6)
    # ... while noise_scale = 1 does perturb it (sigma ~ 0.3), so the comparison above can fail.
    out3 = apply(params, obs, jax.random.key(1), jnp.float32(1.0))
    assert np.max(np.abs(np.asarray(out3.mean) - np.asarray(out1.mean))) > 1e-3


def test_actor_without_noise_draws_equals_noise_scale_zero(noisy_actor) -> None:  # noqa: ANN001
    """`draw_noise=False` (programs without a noisy run) has the same parameters and gives exactly
    the output the noisy head gives at noise_scale 0, mean_var included."""
    actor, params, obs = noisy_actor
    plain = networks.Actor(action_dim=ACTION_DIM, hidden_sizes=HIDDEN, draw_noise=False)
    same_tree = jax.eval_shape(plain.init, jax.random.key(0), obs, jax.random.key(1), 0.0)
    assert jax.tree.structure(same_tree) == jax.tree.structure(params)
    for scale in (0.0, 1.0):  # the plain head ignores the scale: it never draws noise
        got = jax.jit(plain.apply)(params, obs, jax.random.key(5), jnp.float32(scale))
        want = jax.jit(actor.apply)(params, obs, jax.random.key(5), jnp.float32(0.0))
        jax.tree.map(np.testing.assert_array_equal, got, want)


def test_log_std_is_clipped() -> None:
    actor = networks.Actor(action_dim=3, hidden_sizes=(4,), log_std_min=-5.0, log_std_max=1.5)
    obs = jnp.ones((2, 2))
    params = jax.jit(actor.init)(jax.random.key(0), obs, jax.random.key(1), jnp.float32(0.0))
    # log_std = phi @ 0 + bias: one above the max, one below the min, one inside.
    head = {"kernel": jnp.zeros((4, 3)), "bias": jnp.array([7.0, -30.0, 0.25])}
    params = {"params": {**params["params"], "log_std_head": head}}
    out = jax.jit(actor.apply)(params, obs, jax.random.key(2), jnp.float32(0.0))
    np.testing.assert_allclose(out.log_std, [[1.5, -5.0, 0.25]] * 2)


def test_twin_critic_has_two_independent_critics() -> None:
    obs_dim, action_dim, hidden = 3, 2, (8,)
    rng = np.random.default_rng(0)
    obs = jnp.asarray(rng.normal(size=(5, obs_dim)), jnp.float32)
    action = jnp.asarray(rng.uniform(-1, 1, size=(5, action_dim)), jnp.float32)
    critic = networks.TwinCritic(hidden_sizes=hidden)
    params = jax.jit(critic.init)(jax.random.key(0), obs, action)
    q = jax.jit(critic.apply)(params, obs, action)
    assert q.shape == (5, networks.NUM_CRITICS) == (5, 2)
    assert np.all(np.abs(np.asarray(q[:, 0] - q[:, 1])) > 1e-6)  # different initialisations

    # Critic k is exactly a QNetwork with its own parameters q{k}.
    single_apply = jax.jit(networks.QNetwork(hidden_sizes=hidden).apply)
    for k in range(2):
        params_k = params["params"][f"q{k}"]
        np.testing.assert_allclose(
            q[:, k], single_apply({"params": params_k}, obs, action), rtol=1e-5, atol=1e-6
        )


def test_head_matmul_is_x_at_w_with_the_same_gradients() -> None:
    """`head_matmul` computes x @ w; only its weight gradient takes another route (a written-out
    x^T), which must give x^T g up to float32 round-off, for any leading axes and under vmap."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=(3, 5, 4)).astype(np.float32)
    w = rng.normal(size=(4, 6)).astype(np.float32)
    np.testing.assert_allclose(
        networks.head_matmul(x, w), x.astype(np.float64) @ w, rtol=1e-5, atol=1e-5
    )

    def loss(matmul, x, w):  # noqa: ANN001, ANN202
        return jnp.sum(jnp.sin(matmul(x, w)))

    got = jax.jit(jax.grad(lambda x, w: loss(networks.head_matmul, x, w), (0, 1)))(x, w)
    # Float64 reference: g = cos(x w); d/dx = g w^T, d/dw = sum over the leading axes of x^T g.
    x64, w64 = x.astype(np.float64), w.astype(np.float64)
    g = np.cos(x64 @ w64)
    np.testing.assert_allclose(got[0], g @ w64.T, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(got[1], np.einsum("abi,abo->io", x64, g), rtol=1e-5, atol=1e-5)
    per_row = jax.vmap(jax.grad(lambda x, w: loss(networks.head_matmul, x, w), 1), (0, None))(x, w)
    np.testing.assert_allclose(per_row, np.einsum("abi,abo->aio", x64, g), rtol=1e-5, atol=1e-5)


def test_actor_gradients_match_plain_matmul_heads(noisy_actor, monkeypatch) -> None:  # noqa: ANN001
    """Every actor parameter's gradient (noisy mean head drawn, log-std head) is the one plain
    `x @ w` heads give, to float32 round-off."""
    actor, params, _ = noisy_actor
    obs = jnp.asarray(np.random.default_rng(1).normal(size=(16, OBS_DIM)), jnp.float32)

    def loss(params):  # noqa: ANN001, ANN202
        out = actor.apply(params, obs, jax.random.key(3), jnp.float32(1.0))
        return jnp.sum(jnp.tanh(out.mean) * jnp.exp(out.log_std)) + jnp.sum(out.mean_var)

    got = jax.grad(loss)(params)
    monkeypatch.setattr(networks, "head_matmul", lambda x, w: x @ w)
    want = jax.grad(loss)(params)
    assert jax.tree.structure(got) == jax.tree.structure(want)
    for g, w in zip(jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
        np.testing.assert_allclose(g, w, rtol=2e-5, atol=1e-6)
    head_grads = got["params"]["mean_head"]
    assert np.any(np.abs(np.asarray(head_grads["sigma_w"])) > 1e-4)  # the noise path is exercised


# ---------------------------------------------------------------- agent.uncertainty

# exp(log_std) = [1, 2, 4]:     mean 7/3, max 4,   sum 7
# mean_var = [0.1, 0.5, 0.3]:   mean 0.3, max 0.5, sum 0.9
_POLICY = networks.PolicyOutput(
    mean=jnp.zeros((1, 3)),
    log_std=jnp.log(jnp.array([[1.0, 2.0, 4.0]])),
    mean_var=jnp.array([[0.1, 0.5, 0.3]]),
)
_EXPECTED = {"mean": (7 / 3, 0.3), "max": (4.0, 0.5), "sum": (7.0, 0.9)}


@pytest.mark.parametrize("how", ["mean", "max", "sum"])
def test_uncertainty_picks_sigma_or_mean_variance(how: str) -> None:
    intrinsic, extrinsic = _EXPECTED[how]
    u0 = agent_lib.uncertainty(_POLICY, jnp.float32(0.0), how)
    u1 = agent_lib.uncertainty(_POLICY, jnp.float32(1.0), how)
    assert u0.shape == u1.shape == (1,)
    np.testing.assert_allclose(u0, [intrinsic], rtol=1e-6)
    np.testing.assert_allclose(u1, [extrinsic], rtol=1e-6)
    # `noisy` is a traced, sweepable value: the same choice under jit.
    jitted = jax.jit(lambda noisy: agent_lib.uncertainty(_POLICY, noisy, how))
    np.testing.assert_allclose(jitted(jnp.float32(1.0)), [extrinsic], rtol=1e-6)
