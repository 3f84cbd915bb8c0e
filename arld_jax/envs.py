"""Batched environments: HalfCheetah through Brax (MJX physics, or MuJoCo's C engine on the host),
and a cheap pure-JAX stand-in for tests.

`make_env(cfg)` returns reset/step functions over a leading env axis. Time limits and resets are NOT
handled here: HalfCheetah never terminates, so every episode lasts exactly `cfg.episode_length` steps
and all envs of a run start and end together. The training loop therefore resets all envs at the
iteration that ends an episode, from fresh random initial states (Brax's AutoResetWrapper would
replay the first initial state forever), under a `lax.cond` whose predicate depends only on the
iteration index, so the reset costs nothing on the other 999 steps, also under `vmap` over seeds.
"""

from __future__ import annotations

import contextlib
import os
import queue
import sys
import tempfile
import warnings
from collections.abc import Callable, Iterator
from typing import Any, NamedTuple

import flax.struct
import jax
import jax.numpy as jnp
import numpy as np

from arld_jax import gait
from arld_jax.config import Config
from arld_jax.types import PRNGKey


@flax.struct.dataclass
class EnvState:
    """A batch of environment states. `obs` after a step is the true next observation."""

    inner: Any  # backend state (Brax State, or the toy env's state vector)
    obs: jax.Array  # [num_envs, obs_dim]
    reward: jax.Array  # [num_envs]
    terminated: jax.Array  # [num_envs] float32 (always 0 for HalfCheetah)


class Env(NamedTuple):
    reset: Callable[[PRNGKey, int], EnvState]  # (key, n) -> n fresh random initial states
    step: Callable[[EnvState, jax.Array], EnvState]  # (state [n], action [n, A]) -> state [n]
    obs_dim: int
    action_dim: int
    upside_down: Callable[[jax.Array], jax.Array]  # obs [..., obs_dim] -> bool [...] (the gait)
    can_terminate: bool = False  # static: whether `step` can ever set `terminated` (a fall)


def halfcheetah_upside_down(obs: jax.Array) -> jax.Array:
    """True where the HalfCheetah's torso is upside down (`gait.upside_down`)."""
    return gait.upside_down(obs, jnp)


def never_upside_down(obs: jax.Array) -> jax.Array:
    """The toy env has no body: never upside down."""
    return jnp.zeros(obs.shape[:-1], bool)


CPU_ENV_MAX_BATCH = 16
"""`env_max_batch = 0` (auto) means this many on CPU (measured: see `Config.env_max_batch`)."""


def make_env(cfg: Config) -> Env:
    """The batched env named by `cfg.env_name`, its vmapped step limited by `cfg.env_max_batch`."""
    if cfg.env_name == "toy":
        env = _toy_env()
    elif cfg.env_name == "toy_fall":
        env = _toy_env(fall_error=TOY_FALL_ERROR)
    elif cfg.backend == "mujoco":
        return mujoco_halfcheetah()  # a host loop: no chunking to tune
    else:
        env = _brax_env("halfcheetah", cfg.backend)
    max_batch = cfg.env_max_batch
    if max_batch == 0:  # auto: chunk on CPU only; accelerators want the widest batch
        max_batch = CPU_ENV_MAX_BATCH if jax.default_backend() == "cpu" else -1
    return env._replace(step=limit_batch(env.step, max_batch))


def limit_batch(step: Callable[[EnvState, jax.Array], EnvState], max_batch: int) -> Callable:
    """`step` (batched over a leading env axis), except that under `jax.vmap` (over runs) the vmapped
    axis is folded into the env axis and the envs are stepped `max_batch` at most at a time, chunk
    after chunk (`lax.map`). Without vmap, or with max_batch < 1, it is `step` itself.

    Why: on CPU, MJX's cost per env grows with the batch (80 envs step at about half the total rate
    of 5 x 16), while the rest of a vmapped sweep wants the widest batch. Chunk j holds envs j,
    j + num_chunks, j + 2 num_chunks, ... (strided), so when the run axis is sharded over devices
    every chunk keeps its share on each device. Chunks are padded by repeating envs; the padded
    results are dropped."""
    if max_batch < 1:
        return step

    @jax.custom_batching.custom_vmap
    def limited(state: EnvState, action: jax.Array) -> EnvState:
        return step(state, action)

    @limited.def_vmap
    def _rule(axis_size: int, in_batched: list, state: EnvState, action: jax.Array):  # noqa: ANN202
        args = jax.tree.map(
            lambda x, b: x if b else jnp.broadcast_to(x, (axis_size, *jnp.shape(x))),
            (state, action),
            tuple(in_batched),
        )
        n = action.shape[-2]  # envs per run
        total = axis_size * n
        num_chunks = -(-total // max_batch)
        size = -(-total // num_chunks)  # balanced chunks: 80 -> 5 x 16, 20 -> 2 x 10
        padded = num_chunks * size

        def flat(x: jax.Array) -> jax.Array:
            return x.reshape(total, *x.shape[2:])

        def unflat(x: jax.Array) -> jax.Array:
            return x.reshape(axis_size, n, *x.shape[1:])

        if num_chunks == 1:
            out = jax.tree.map(unflat, step(*jax.tree.map(flat, args)))
            return out, jax.tree.map(lambda _: True, out)

        def to_chunks(x: jax.Array) -> jax.Array:  # [total, ...] -> [num_chunks, size, ...]
            x = flat(x)
            if padded > total:  # pad by repeating envs
                x = x[jnp.arange(padded) % total]
            return jnp.swapaxes(x.reshape(size, num_chunks, *x.shape[1:]), 0, 1)

        def from_chunks(x: jax.Array) -> jax.Array:
            x = jnp.swapaxes(x, 0, 1).reshape(padded, *x.shape[2:])
            return unflat(x[:total])

        out = jax.lax.map(lambda a: step(*a), jax.tree.map(to_chunks, args))
        out = jax.tree.map(from_chunks, out)
        return out, jax.tree.map(lambda _: True, out)

    return limited


# Third-party messages that every run printed and no user can act on: MuJoCo-MJX's optional Warp
# backend is not installed (printed at import), Brax's notice that its envs are unmaintained (we
# keep Brax's halfcheetah on purpose, docs/design.md), MuJoCo's deprecation of the `settotalmass`
# attribute in Brax's half_cheetah.xml (printed by MuJoCo's C compiler).
_THIRD_PARTY_NOISE = (
    "Failed to import warp",
    "Failed to import mujoco_warp",
    "settotalmass",
    "not actively being maintained",
)


@contextlib.contextmanager
def without_third_party_noise() -> Iterator[None]:
    """Run the block with stdout/stderr captured at the file-descriptor level (MuJoCo's C code
    writes there directly), then re-print every captured line except `_THIRD_PARTY_NOISE`; an
    exception in the block re-prints everything, so nothing that explains an error is lost."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = {fd: os.dup(fd) for fd in (1, 2)}
    with tempfile.TemporaryFile(mode="w+b") as capture, warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*not actively being maintained.*")
        failed = False
        try:
            for fd in (1, 2):
                os.dup2(capture.fileno(), fd)
            yield
        except BaseException:
            failed = True
            raise
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            for fd, copy in saved.items():
                os.dup2(copy, fd)
                os.close(copy)
            capture.seek(0)
            for line in capture.read().decode(errors="replace").splitlines():
                if line.strip() and (failed or not any(n in line for n in _THIRD_PARTY_NOISE)):
                    print(line, file=sys.stderr)


def _brax_env(name: str, backend: str) -> Env:
    with without_third_party_noise():
        # Imported lazily: the toy env and the unit tests do not need Brax.
        from brax import envs as brax_envs

        env = brax_envs.get_environment(name, backend=backend)

    def wrap(s: Any) -> EnvState:
        return EnvState(inner=s, obs=s.obs, reward=s.reward, terminated=s.done)

    def reset(key: PRNGKey, n: int) -> EnvState:
        return wrap(jax.vmap(env.reset)(jax.random.split(key, n)))

    def step(state: EnvState, action: jax.Array) -> EnvState:
        return wrap(jax.vmap(env.step)(state.inner, action))

    upside_down = halfcheetah_upside_down if name == "halfcheetah" else never_upside_down
    return Env(
        reset=reset,
        step=step,
        obs_dim=env.observation_size,
        action_dim=env.action_size,
        upside_down=upside_down,
    )


@flax.struct.dataclass
class MujocoState:
    """What MuJoCo's C step reads of a batch of envs, carried in the loop as float32 (as MJX's)."""

    qpos: jax.Array  # [n, nq]
    qvel: jax.Array  # [n, nv]
    qacc_warmstart: jax.Array  # [n, nv]: the solver's warm start, part of mj_step's state
    x: jax.Array  # [n]: the torso's x as last computed (Brax's `pipeline_state.x.pos[0, 0]`)


class _HostPhysics:
    """MuJoCo's C step of a batch of envs as a pure function of numpy arrays (any leading shape).

    State in, state out: each call writes (qpos, qvel, warm start, ctrl) into a scratch MjData and
    takes `n_frames` C steps, so the result depends on its arguments only, as
    `jax.pure_callback` requires (and a checkpoint resumes bit-identically)."""

    def __init__(self, model: Any, n_frames: int, torso: int) -> None:
        self.model, self.n_frames, self.torso = model, n_frames, torso
        self._spare: queue.SimpleQueue = queue.SimpleQueue()  # scratch MjData, one per caller

    @contextlib.contextmanager
    def _data(self) -> Iterator[Any]:
        """A scratch MjData no other call is using: XLA may run the callbacks of programs
        dispatched back to back on several threads at once. (A `threading.local` MjData crashed
        the process there; a pool of spares does not: tests/test_envs.py.)"""
        import mujoco

        try:
            data = self._spare.get_nowait()
        except queue.Empty:
            data = mujoco.MjData(self.model)
        try:
            yield data
        finally:
            self._spare.put(data)

    def step(self, packed: Any) -> np.ndarray:
        """[..., nq + nv + nv + nu] = (qpos, qvel, warm start, ctrl) -> [..., nq + nv + nv + 1] =
        (qpos, qvel, warm start, torso x) after `n_frames` C steps. Packed into one array each way
        because each argument of a host callback costs tens of microseconds."""
        import mujoco

        m = self.model
        # The callback gets a jax.Array: take a numpy view, or every index below is a JAX dispatch.
        packed = np.asarray(packed)
        lead, flat = packed.shape[:-1], packed.reshape(-1, packed.shape[-1])
        q, v, w = m.nq, m.nq + m.nv, m.nq + 2 * m.nv
        out = np.empty((len(flat), w + 1), np.float32)
        with self._data() as d:
            for i, row in enumerate(flat):
                d.qpos[:], d.qvel[:], d.qacc_warmstart[:], d.ctrl[:] = (
                    row[:q], row[q:v], row[v:w], row[w:],
                )  # fmt: skip
                mujoco.mj_step(m, d, nstep=self.n_frames)
                out[i, :q], out[i, q:v], out[i, v:w] = d.qpos, d.qvel, d.qacc_warmstart
                out[i, w] = d.xpos[self.torso, 0]  # as of the last frame's start, as MJX's x
        return out.reshape(*lead, w + 1)

    def torso_x(self, qpos: np.ndarray) -> np.ndarray:
        import mujoco

        lead, m = qpos.shape[:-1], self.model
        qpos = np.asarray(qpos).reshape(-1, m.nq)
        out = np.empty(len(qpos), np.float32)
        with self._data() as d:
            for i in range(len(qpos)):
                d.qpos[:] = qpos[i]
                mujoco.mj_kinematics(m, d)
                out[i] = d.xpos[self.torso, 0]
        return out.reshape(lead)


def mujoco_halfcheetah() -> Env:
    """Brax's halfcheetah stepped by MuJoCo's C engine on the host (`Config.backend = 'mujoco'`).

    The same task as the 'mjx' backend, taken from Brax's env object itself: its MjModel (MJX's
    options: Newton solver, 4 iterations), its 5 frames per step, its reset distribution with the
    same key splits (so the same key gives bit-identical initial states), its observation
    (qpos[1:], qvel) and its reward ((x' - x) / dt - 0.1 |a|^2, x the torso's x as Brax reads it).
    Only the arithmetic differs: float64 inside a C step (MJX: float32), the state rounded to float32
    between steps; the two stay within 2e-3 of each other over 10 steps, then part as any two
    chaotic trajectories do (tests/test_envs.py). Why: on CPU an MJX step of one env costs about as
    much as a SAC update; a C step with its callback about 64 us (benchmarks/README.md). The loop calls
    the host once per env step (`jax.pure_callback`, vmapped runs in one call); on a GPU that is a
    device-host round trip per step, so there 'mjx' is the backend to use."""
    with without_third_party_noise():
        from brax import envs as brax_envs

        brax_env = brax_envs.get_environment("halfcheetah", backend="mjx")
    model = brax_env.sys.mj_model
    # Brax's Halfcheetah keeps its constants in private attributes (brax 0.14.2, pinned): read,
    # not copied, so both backends keep one definition of the task.
    n_frames, dt = int(brax_env._n_frames), float(brax_env.dt)
    noise = float(brax_env._reset_noise_scale)
    forward_weight, ctrl_weight = (
        float(brax_env._forward_reward_weight),
        float(brax_env._ctrl_cost_weight),
    )
    init_q = jnp.asarray(model.qpos0, jnp.float32)
    host = _HostPhysics(model, n_frames, torso=model.body("torso").id)
    nq, nv = model.nq, model.nv

    def obs_of(qpos: jax.Array, qvel: jax.Array) -> jax.Array:
        return jnp.concatenate([qpos[..., 1:], qvel], axis=-1)  # Brax: exclude the root's x

    def reset_one(key: PRNGKey) -> tuple[jax.Array, jax.Array]:
        _, k_pos, k_vel = jax.random.split(key, 3)  # Brax's Halfcheetah.reset
        qpos = init_q + jax.random.uniform(k_pos, (nq,), minval=-noise, maxval=noise)
        return qpos, noise * jax.random.normal(k_vel, (nv,))

    def reset(key: PRNGKey, n: int) -> EnvState:
        qpos, qvel = jax.vmap(reset_one)(jax.random.split(key, n))
        x = jax.pure_callback(
            host.torso_x, jax.ShapeDtypeStruct((n,), jnp.float32), qpos,
            vmap_method="broadcast_all",
        )  # fmt: skip
        inner = MujocoState(qpos=qpos, qvel=qvel, qacc_warmstart=jnp.zeros_like(qvel), x=x)
        zeros = jnp.zeros(n)
        return EnvState(inner=inner, obs=obs_of(qpos, qvel), reward=zeros, terminated=zeros)

    def step(state: EnvState, action: jax.Array) -> EnvState:
        s = state.inner
        packed = jnp.concatenate([s.qpos, s.qvel, s.qacc_warmstart, action], axis=-1)
        out = jax.pure_callback(
            host.step,
            jax.ShapeDtypeStruct((*action.shape[:-1], nq + 2 * nv + 1), jnp.float32),
            packed.astype(jnp.float32),
            vmap_method="broadcast_all",
        )
        qpos, qvel = out[..., :nq], out[..., nq : nq + nv]
        warm, x = out[..., nq + nv : nq + 2 * nv], out[..., -1]
        reward = forward_weight * (x - s.x) / dt - ctrl_weight * jnp.sum(jnp.square(action), -1)
        inner = MujocoState(qpos=qpos, qvel=qvel, qacc_warmstart=warm, x=x)
        return EnvState(
            inner=inner,
            obs=obs_of(qpos, qvel),
            reward=reward,
            terminated=jnp.zeros_like(reward),
        )

    return Env(
        reset=reset,
        step=step,
        obs_dim=nq - 1 + nv,
        action_dim=model.nu,
        upside_down=halfcheetah_upside_down,
    )


# A fixed random linear map for the toy env's target action; numpy so it is a compile-time constant.
_TOY_OBS_DIM, _TOY_ACTION_DIM = 4, 2
_TOY_W = np.random.default_rng(0).normal(size=(_TOY_OBS_DIM, _TOY_ACTION_DIM)).astype(np.float32)


def toy_target_action(obs: jax.Array) -> jax.Array:
    """The toy env's best action in state `obs` (the 'expert' of the tests)."""
    return jnp.tanh(2.0 * obs @ _TOY_W)


TOY_FALL_ERROR = 1.8
"""`toy_fall` ends an episode (a "fall") when the squared action error exceeds this."""


def _toy_env(fall_error: float | None = None) -> Env:
    """A seconds-to-compile stand-in with HalfCheetah's interface.

    reward = 1 - e, e = mean_j (a_j - tanh(2 W s)_j)^2, s' = clip(0.9 s + 0.3 [a, -a], -2, 2). The
    best policy earns 1 per step, always acting 0 about 0.4, uniform-random actions about 0.
    With `fall_error` (the `toy_fall` task), a step with e > fall_error terminates the episode: a
    uniform-random policy falls after about 26 steps on average, the target policy never; the terminal step's
    reward is paid and nothing after it (the task's stand-in for Hopper's health rule).
    """

    def reset(key: PRNGKey, n: int) -> EnvState:
        s = jax.random.uniform(key, (n, _TOY_OBS_DIM), minval=-1.0, maxval=1.0)
        return EnvState(inner=s, obs=s, reward=jnp.zeros(n), terminated=jnp.zeros(n))

    def step(state: EnvState, action: jax.Array) -> EnvState:
        s = state.inner
        error = jnp.mean(jnp.square(action - toy_target_action(s)), axis=-1)
        s_next = jnp.clip(0.9 * s + 0.3 * jnp.concatenate([action, -action], axis=-1), -2.0, 2.0)
        fell = jnp.zeros_like(error) if fall_error is None else (error > fall_error)
        return EnvState(
            inner=s_next, obs=s_next, reward=1.0 - error, terminated=fell.astype(jnp.float32)
        )

    return Env(
        reset=reset,
        step=step,
        obs_dim=_TOY_OBS_DIM,
        action_dim=_TOY_ACTION_DIM,
        upside_down=never_upside_down,
        can_terminate=fall_error is not None,
    )
