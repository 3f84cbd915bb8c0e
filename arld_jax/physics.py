"""The physics of a Brax task on two backends, and the batching of an env step.

A task is Brax's env object (`brax.envs.get_environment(name, backend='mjx')`, brax 0.14.2): its
model and options, its reset distribution, observation, reward and health rule (`done`) live in its
`reset` and `step`. Both backends run that same `reset` and `step`:

* 'mjx' (and Brax's own pipelines 'generalized', 'positional', 'spring'): Brax's env as it is,
  vmapped over envs; the physics is MuJoCo-MJX, compiled into the program.
* 'mujoco': the same env object with only its physics swapped: `pipeline_init` and
  `pipeline_step` call MuJoCo's C engine on the host (`jax.pure_callback`, one call per env step
  for every env of every vmapped run) on Brax's own MjModel with MJX's options (`_c_model`), and
  return a small state, `HostPhysicsState`, with the fields of MJX's state that Brax's tasks read:
  q, qd, the bodies' frames x (and their velocities xd where a task reads them, Humanoid; their
  external contact forces cfrc_ext where it observes them, `ant_contact`), plus the solver's warm
  start that MuJoCo's step carries. Brax's own code then computes the observation, reward and
  `done` from it, as it does from MJX's state.

A task that observes contact forces (`TaskSpec.contact_forces`) gets them on MJX from
`rne_postconstraint` after Brax's step, on the C engine from `mj_rnePostConstraint` after
`mj_step`; `contact_terms`, the one place that reads them, adds them to Brax's observation and
their cost to its reward.

Why swap the physics under Brax's step rather than write each task's observation, reward and health
rule again for the C engine: each task is then defined once, by Brax; a task reading a field that
the host does not return fails when the program is traced, not silently. What it costs against a
hand-written C path: the carried state holds every body's frame (HalfCheetah: 76 floats per env
instead of 28) and Brax's reward metrics, a few hundred bytes, and the host returns them; the
callback's fixed cost (tens of microseconds per call) dominates both (benchmarks/env_steps.py).
HalfCheetah's results are bit-identical to its former hand-written C path: the same C steps, the
same float32 rounding between steps, the same formulas (Brax's) in the same order.

The two engines differ only in their arithmetic (float64 in C, float32 in MJX, and MJX's own
solver and collision code); over one step from the same state they agree to float32 drift
(tests/test_envs.py), over many steps they part as any two chaotic trajectories do. One more
difference appears with `Config.contacts` 'all' only: where a capsule touches the floor, the C
engine's contact frame (and so its friction pyramid, Brax's tasks use pyramidal cones) follows the
capsule, MJX's the world's axes. For a capsule along x (Hopper's, Walker2d's feet) the pyramids
coincide; for Ant's diagonal legs one step from the same state can differ by 0.1 in a velocity. On
CPU a C step with its callback costs tens of microseconds, an MJX step of one env about as much as a
SAC update; on a GPU the callback is a device-host round trip per step, so there 'mjx' is the
backend to use.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import io
import os
import queue
import sys
import tempfile
import warnings
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

import flax.struct
import jax
import jax.numpy as jnp
import numpy as np

from arld_jax.tasks.base import Env, EnvState
from arld_jax.types import PRNGKey

if TYPE_CHECKING:
    from arld_jax.tasks.base import TaskSpec

# ---------------------------------------------------------------- building a Brax task


def brax_task_env(
    spec: TaskSpec, backend: str, options: dict[str, int] | None = None, contacts: str = "task"
) -> Env:
    """The batched env of the Brax task `spec` on `backend` (see the module docstring), with
    MuJoCo's options `options` (`opt.*` name -> value, e.g. {'iterations': 100, 'integrator': 1}:
    `config.model_options`) over the task's own and the contacts `contacts` (`Config.contacts`):
    set on Brax's `sys`, which MJX steps and the C engine's model copies (`_c_model`)."""
    brax_env = load_brax_env(spec.brax_name, "mjx" if backend == "mujoco" else backend)
    if options:
        brax_env.sys = brax_env.sys.tree_replace({f"opt.{k}": v for k, v in options.items()})
    if contacts == "all":
        brax_env.sys = all_geoms_touch_floor(brax_env.sys)
    # Brax's health rule is on exactly when its env says so; the loop needs it statically.
    brax_terminates = bool(getattr(brax_env, "_terminate_when_unhealthy", False))
    if brax_terminates != spec.can_terminate:
        raise ValueError(
            f"task {spec.name!r} declares can_terminate={spec.can_terminate}, but Brax's env "
            f"{spec.brax_name!r} has terminate_when_unhealthy={brax_terminates}"
        )
    if backend == "mujoco":
        # Brax keeps the frames per step in a private attribute (brax 0.14.2, pinned).
        host = HostPhysics(
            brax_env.sys, int(brax_env._n_frames), spec.reads_velocities, spec.contact_forces
        )
        # Instance attributes shadow PipelineEnv's methods: Brax's reset and step call these.
        brax_env.pipeline_init = host.pipeline_init
        brax_env.pipeline_step = host.pipeline_step
    elif spec.contact_forces:  # 'mjx': `Config` refuses Brax's own pipelines for such a task
        with_contact_forces(brax_env)
    terms = contact_terms(brax_env) if spec.contact_forces else None

    def wrap(s: Any, stepped: bool) -> EnvState:
        if terms is not None:
            s = jax.vmap(lambda one: terms(one, stepped))(s)
        return EnvState(inner=s, obs=s.obs, reward=s.reward, terminated=s.done)

    def reset(key: PRNGKey, n: int) -> EnvState:
        return wrap(jax.vmap(brax_env.reset)(jax.random.split(key, n)), stepped=False)

    def step(state: EnvState, action: jax.Array) -> EnvState:
        return wrap(jax.vmap(brax_env.step)(state.inner, action), stepped=True)

    # Traced, not run: Brax's `observation_size` runs a whole reset eagerly (minutes for MJX).
    obs_shape = jax.eval_shape(lambda k: reset(k, 1), jax.random.key(0)).obs.shape
    return Env(
        reset=reset,
        step=step,
        obs_dim=obs_shape[-1],
        action_dim=brax_env.action_size,
        upside_down=spec.upside_down,
        can_terminate=spec.can_terminate,
    )


def with_contact_forces(brax_env: Any) -> None:
    """Brax's MJX pipeline made to fill its state's `cfrc_ext` after each init and step (MJX's
    step leaves it at 0, as MuJoCo's does: `rne_postconstraint`, MuJoCo's `mj_rnePostConstraint`,
    computes it from the last forward pass's contact forces). Brax's own pipelines have no such
    field."""
    from mujoco import mjx

    init, step = brax_env.pipeline_init, brax_env.pipeline_step  # PipelineEnv's, bound
    brax_env.pipeline_init = lambda *a, **k: mjx.rne_postconstraint(brax_env.sys, init(*a, **k))
    brax_env.pipeline_step = lambda s, a: mjx.rne_postconstraint(brax_env.sys, step(s, a))


def contact_terms(brax_env: Any) -> Callable[[Any, bool], Any]:
    """(Brax's State of one env, whether it was stepped) -> that state with its contact terms
    (`TaskSpec.contact_forces`): the observation gains the clipped cfrc_ext of every body but the
    world, a step's reward loses the task's contact cost. Weight and range are Brax's env's own
    (brax/envs/ant.py: 5e-4 and [-1, 1], as Gymnasium's Ant-v5)."""
    weight = float(brax_env._contact_cost_weight)
    low, high = (float(v) for v in brax_env._contact_force_range)

    def add(s: Any, stepped: bool) -> Any:
        forces = jnp.clip(s.pipeline_state.cfrc_ext[1:], low, high)
        cost = weight * jnp.sum(jnp.square(forces)) if stepped else 0.0
        return s.replace(obs=jnp.concatenate([s.obs, forces.ravel()]), reward=s.reward - cost)

    return add


def all_geoms_touch_floor(sys: Any) -> Any:
    """Brax's `sys` with every geom of the body able to collide with the floor (`Config.contacts`
    'all'), as in Gymnasium's v5 XMLs: contype 1 on each geom not of the world body, whose
    conaffinity stays 0 (Brax's XMLs), so a body geom meets the floor (conaffinity 1) and not
    another body geom. MJX finds its collision pairs from these arrays when it traces a step;
    MuJoCo's broad phase first asks each body's `body_contype`, the OR of its geoms', set here to
    match."""
    body_of = np.asarray(sys.geom_bodyid)
    contype = np.asarray(sys.geom_contype).copy()
    contype[body_of != 0] = 1
    body_contype = np.zeros_like(np.asarray(sys.body_contype))
    np.bitwise_or.at(body_contype, body_of, contype)
    return sys.tree_replace({"geom_contype": contype, "body_contype": body_contype})


def load_brax_env(name: str, backend: str) -> Any:
    """Brax's env object `name` on `backend`, built without its import-time notices."""
    with without_third_party_noise():
        # Imported lazily: the toy tasks and the unit tests do not need Brax.
        from brax import envs as brax_envs

        return brax_envs.get_environment(name, backend=backend)


# ---------------------------------------------------------------- MuJoCo's C engine ('mujoco')


@flax.struct.dataclass
class HostPhysicsState:
    """What Brax's tasks read of MJX's physics state (`brax.mjx.base.State`), computed by MuJoCo's
    C engine, carried in the loop as float32 (as MJX's). Shapes per env."""

    q: jax.Array  # [nq] qpos
    qd: jax.Array  # [nv] qvel
    qacc_warmstart: jax.Array  # [nv]: the solver's warm start, part of mj_step's state
    x: Any  # brax.base.Transform: pos [nbody - 1, 3], rot [nbody - 1, 4] (world body left out)
    xd: Any = None  # brax.base.Motion [nbody - 1] where the task reads it (`TaskSpec`)
    cfrc_ext: Any = None  # [nbody, 6], the world's row 0, where the task reads it (`TaskSpec`)


def _c_model(sys: Any) -> Any:
    """Brax's MjModel with the options of MJX's `sys.opt` where Brax changed them: it sets some
    tasks' MJX options (Ant, Humanoid: Newton with 1 iteration and 4 line searches, Euler damping
    off) on `sys` only, so the MjModel it was built from still has the XML's. An option equal to
    the model's up to MJX's float32 keeps the model's float64 value (a timestep of 0.01, not
    float32's 0.00999999977). Its geoms collide as `sys`'s do (`all_geoms_touch_floor`)."""
    model = copy.deepcopy(sys.mj_model)
    for f in dataclasses.fields(sys.opt):
        if f.name.startswith("_") or not hasattr(model.opt, f.name):
            continue
        mine, value = getattr(model.opt, f.name), getattr(sys.opt, f.name)
        if isinstance(mine, int):  # flags and enums (MJX's are Python or MuJoCo enums)
            setattr(model.opt, f.name, int(value))
        elif not np.array_equal(np.asarray(mine, np.float32), np.asarray(value, np.float32)):
            if np.ndim(mine):
                mine[:] = np.asarray(value)
            else:
                setattr(model.opt, f.name, float(value))
    collide = ("geom_contype", "geom_conaffinity", "body_contype", "body_conaffinity")
    if any(not np.array_equal(getattr(model, n), np.asarray(getattr(sys, n))) for n in collide):
        for name in collide:
            getattr(model, name)[:] = np.asarray(getattr(sys, name))
        # The model's compiled bounding-volume trees hold only the geoms that could collide when
        # it was compiled; without its mid phase MuJoCo tests every geom pair the arrays allow,
        # which finds the same contacts as a model compiled with these arrays.
        import mujoco

        model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_MIDPHASE
    return model


class HostPhysics:
    """MuJoCo's C step of a batch of envs as a pure function of numpy arrays (any leading shape),
    and Brax's `pipeline_init` / `pipeline_step` made of it.

    State in, state out: each call writes (qpos, qvel, warm start, ctrl) into a scratch MjData and
    takes `n_frames` C steps, so the result depends on its arguments only, as
    `jax.pure_callback` requires (and a checkpoint resumes bit-identically). Each direction is
    packed into one array, because each argument of a host callback costs tens of microseconds."""

    def __init__(self, sys: Any, n_frames: int, velocities: bool, forces: bool = False) -> None:
        self.sys, self.model, self.n_frames = sys, _c_model(sys), n_frames
        self.velocities, self.forces = velocities, forces
        m = self.model
        self.bodies = m.nbody - 1  # Brax leaves out the world body
        # Per body: pos 3, quat 4; with velocities also cvel 6 and its root subtree's com 3; with
        # forces (after those, from `forces_at`) its cfrc_ext 6.
        self.forces_at = self.bodies * (7 + 9 * velocities)
        self.frame_size = self.forces_at + self.bodies * 6 * forces
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

    def _frames(self, d: Any, out: np.ndarray) -> None:
        """The bodies' frames (and velocities) of `d` as computed by its last forward pass."""
        m, b = self.model, self.bodies
        out[: 3 * b] = d.xpos[1:].ravel()
        out[3 * b : 7 * b] = d.xquat[1:].ravel()
        if self.velocities:
            out[7 * b : 13 * b] = d.cvel[1:].ravel()
            out[13 * b : 16 * b] = d.subtree_com[m.body_rootid[1:]].ravel()
        if self.forces:
            import mujoco

            mujoco.mj_rnePostConstraint(m, d)  # fills cfrc_ext (mj_step does not)
            out[self.forces_at :] = d.cfrc_ext[1:].ravel()

    def host_step(self, packed: Any) -> np.ndarray:
        """[..., nq + nv + nv + nu] = (qpos, qvel, warm start, ctrl) -> [..., nq + nv + nv +
        frame_size] = (qpos, qvel, warm start, frames) after `n_frames` C steps; the frames as of
        the last frame's start (before its integration), as MJX's."""
        import mujoco

        m = self.model
        # The callback gets a jax.Array: take a numpy view, or every index below is a JAX dispatch.
        packed = np.asarray(packed)
        lead, flat = packed.shape[:-1], packed.reshape(-1, packed.shape[-1])
        q, v, w = m.nq, m.nq + m.nv, m.nq + 2 * m.nv
        out = np.empty((len(flat), w + self.frame_size), np.float32)
        with self._data() as d:
            for i, row in enumerate(flat):
                d.qpos[:], d.qvel[:], d.qacc_warmstart[:], d.ctrl[:] = (
                    row[:q], row[q:v], row[v:w], row[w:],
                )  # fmt: skip
                mujoco.mj_step(m, d, nstep=self.n_frames)
                out[i, :q], out[i, q:v], out[i, v:w] = d.qpos, d.qvel, d.qacc_warmstart
                self._frames(d, out[i, w:])
        return out.reshape(*lead, w + self.frame_size)

    def host_frames(self, packed: Any) -> np.ndarray:
        """[..., nq + nv] = (qpos, qvel) -> [..., frame_size]: the frames at that state (its contact
        forces need the whole forward pass, with a zero warm start as MJX's `make_data`)."""
        import mujoco

        m = self.model
        packed = np.asarray(packed)
        lead, flat = packed.shape[:-1], packed.reshape(-1, packed.shape[-1])
        out = np.empty((len(flat), self.frame_size), np.float32)
        with self._data() as d:
            for i, row in enumerate(flat):
                d.qpos[:], d.qvel[:] = row[: m.nq], row[m.nq :]
                if self.forces:
                    d.qacc_warmstart[:], d.ctrl[:] = 0.0, 0.0
                    mujoco.mj_forward(m, d)
                else:
                    mujoco.mj_kinematics(m, d)
                if self.velocities and not self.forces:
                    mujoco.mj_comPos(m, d)
                    mujoco.mj_comVel(m, d)
                self._frames(d, out[i])
        return out.reshape(*lead, self.frame_size)

    def _state(self, q: jax.Array, qd: jax.Array, warm: jax.Array, frames: jax.Array) -> Any:
        """A `HostPhysicsState` from the host's flat frames, the fields as Brax's MJX pipeline
        makes them (brax/mjx/pipeline.py: x from xpos and xquat, xd from cvel about each body)."""
        from brax.base import Motion, Transform

        b = self.bodies
        pos = frames[: 3 * b].reshape(b, 3)
        x = Transform(pos=pos, rot=frames[3 * b : 7 * b].reshape(b, 4))
        xd = cfrc_ext = None
        if self.velocities:
            cvel = frames[7 * b : 13 * b].reshape(b, 6)
            offset = Transform.create(pos=pos - frames[13 * b : 16 * b].reshape(b, 3))
            xd = offset.vmap().do(Motion(vel=cvel[:, 3:], ang=cvel[:, :3]))
        if self.forces:
            bodies = frames[self.forces_at :].reshape(b, 6)
            cfrc_ext = jnp.concatenate([jnp.zeros((1, 6), bodies.dtype), bodies])
        return HostPhysicsState(q=q, qd=qd, qacc_warmstart=warm, x=x, xd=xd, cfrc_ext=cfrc_ext)

    def pipeline_init(self, q: jax.Array, qd: jax.Array, act: Any = None, ctrl: Any = None) -> Any:
        """Brax's `PipelineEnv.pipeline_init` (one env): the state at (q, qd), warm start 0 (MJX's
        `make_data` too)."""
        del act, ctrl  # Brax's locomotion tasks have neither activations nor an initial ctrl
        frames = jax.pure_callback(
            self.host_frames,
            jax.ShapeDtypeStruct((self.frame_size,), jnp.float32),
            jnp.concatenate([q, qd]).astype(jnp.float32),
            vmap_method="broadcast_all",
        )
        return self._state(q, qd, jnp.zeros_like(qd), frames)

    def pipeline_step(self, state: Any, action: jax.Array) -> Any:
        """Brax's `PipelineEnv.pipeline_step` (one env): `n_frames` C steps with ctrl = action."""
        m = self.model
        q, v, w = m.nq, m.nq + m.nv, m.nq + 2 * m.nv
        packed = jnp.concatenate([state.q, state.qd, state.qacc_warmstart, action])
        out = jax.pure_callback(
            self.host_step,
            jax.ShapeDtypeStruct((w + self.frame_size,), jnp.float32),
            packed.astype(jnp.float32),
            vmap_method="broadcast_all",
        )
        return self._state(out[:q], out[q:v], out[v:w], out[w:])


# ---------------------------------------------------------------- batching


CPU_ENV_MAX_BATCH = 16
"""`env_max_batch = 0` (auto) means this many on CPU (measured: see `Config.env_max_batch`)."""


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


# ---------------------------------------------------------------- third-party notices


# Third-party messages that every run printed and no user can act on: MuJoCo-MJX's optional Warp
# backend is not installed (printed at import), Brax's notice that its envs are unmaintained (we
# keep Brax's tasks on purpose, docs/design.md), MuJoCo's deprecation of the `settotalmass`
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
    writes there directly) and at Python's level (`sys.stdout` need not be file descriptor 1, e.g.
    under pytest), then re-print every captured line except `_THIRD_PARTY_NOISE`; an exception in
    the block re-prints everything, so nothing that explains an error is lost."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = {fd: os.dup(fd) for fd in (1, 2)}
    python_level = io.StringIO()
    with tempfile.TemporaryFile(mode="w+b") as capture, warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*not actively being maintained.*")
        failed = False
        redirect = contextlib.ExitStack()
        try:
            redirect.enter_context(contextlib.redirect_stdout(python_level))
            redirect.enter_context(contextlib.redirect_stderr(python_level))
            for fd in (1, 2):
                os.dup2(capture.fileno(), fd)
            yield
        except BaseException:
            failed = True
            raise
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            redirect.close()
            for fd, copy_fd in saved.items():
                os.dup2(copy_fd, fd)
                os.close(copy_fd)
            capture.seek(0)
            captured = capture.read().decode(errors="replace") + python_level.getvalue()
            for line in captured.splitlines():
                if line.strip() and (failed or not any(n in line for n in _THIRD_PARTY_NOISE)):
                    print(line, file=sys.stderr)
