"""How the training programs are compiled: the jit recipe of a chunk, its XLA options, and the
run axis that seeds and sweeps are vmapped over.

`jit_chunk(trainer)` is the one recipe that the driver, the benchmarks and the tests compile a
training chunk with. The loop itself (`arld_jax.train`) knows nothing of it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp

if TYPE_CHECKING:
    from arld_jax.train import Trainer


def compiler_options() -> dict[str, Any]:
    """XLA options for the compiled training programs: `jax.jit(..., compiler_options=...)`.

    On CPU, region-based copy insertion. Without it XLA:CPU copies buffers that nested loops update
    in place: the sum tree twice per iteration (8 seed-vmapped 1M buffers: 24-32 ms per iteration
    instead of 2), and the replay's data under `only_if` (benchmarks/README.md, "Where the
    trainer's 'other' time is not, and one copy per iteration"). It changes which copies are made,
    not what is computed. Other backends: no options.

    Also switches JAX's CPU lowering of the threefry generator to unrolled
    (`unroll_threefry_on_cpu`), so every program built with these options gets it."""
    if jax.default_backend() != "cpu":
        return {}
    unroll_threefry_on_cpu()
    return {"xla_cpu_copy_insertion_use_region_analysis": True}


def unroll_threefry_on_cpu() -> bool:
    """Lower JAX's threefry2x32 PRNG on CPU as straight-line code, as JAX does on GPU, instead of
    the 5-trip rolled loop it uses on CPU to save compile time. The same rounds on the same bits,
    so every random number is unchanged (tested); the update draws at least four times (its
    noises, the replay sample) and ran 1.08x faster with it, at the same compile time
    (benchmarks/README.md, "Brax's SAC trainer against arld_jax, side by side"). It uses JAX
    internals (`jax._src.random.threefry2x32`): when they are not there, nothing changes and it
    returns False. Idempotent; process-wide, so
    it also applies to programs jitted later without `compiler_options`."""
    try:
        from jax._src.interpreters import mlir
        from jax._src.random import threefry2x32 as threefry
    except ImportError:
        return False
    rule = getattr(threefry, "_threefry2x32_lowering_rule", None)  # JAX's unrolled (GPU) rule
    if rule is None or not hasattr(threefry, "threefry2x32_p"):
        return False
    mlir.register_lowering(threefry.threefry2x32_p, rule, platform="cpu")
    return True


def over_runs(fn: Callable[..., Any], vmapped: bool = True, in_axes: Any = 0) -> Callable:
    """`fn` over a leading run axis: `jax.vmap(fn, in_axes)`, or the same signature on a run axis of
    size 1 without vmap: always with `vmapped=False` (an expert with an ordered host callback, a
    person at `arld_jax.human`'s page, cannot be batched, and its `lax.cond` must stay a branch),
    and whenever the run axis has size 1. A single run is then the single-run program that
    `test_vmapped_seed_equals_single_run` compares with a seed of a vmapped sweep (the same
    computation; float rounding differs, as it does between sweeps of different sizes). On
    XLA:CPU it is faster: vmapped over 1, each weight gradient of the update came out transposed
    and was transposed back inside Adam's fusion, 1.12x slower at 1 env (benchmarks/README.md,
    "Where the update's time went, and three changes")."""
    axes = in_axes if isinstance(in_axes, tuple) else None
    mapped = lambda args: [a for i, a in enumerate(args) if axes is None or axes[i] == 0]  # noqa: E731

    def one_run(*args: Any) -> Any:
        args = [
            jax.tree.map(lambda x: x[0], a) if (axes is None or axes[i] == 0) else a
            for i, a in enumerate(args)
        ]
        return jax.tree.map(lambda x: x[None], fn(*args))

    if not vmapped:
        return one_run
    batched = jax.vmap(fn, in_axes=in_axes)

    def runs(*args: Any) -> Any:
        sizes = {jnp.shape(x)[0] for x in jax.tree.leaves(mapped(args))}
        return one_run(*args) if sizes == {1} else batched(*args)

    return runs


def jit_chunk(trainer: Trainer, donate: bool = True, vmapped: bool = True) -> Callable[..., Any]:
    """The one jit recipe of a training chunk, for the driver, the benchmarks and the tests:
    `chunk(states, hps, first_period, num_periods) -> (states, PeriodMetrics)` over runs
    (states and hps with a run axis, `first_period` not, `num_periods` static; `over_runs`), the
    state donated (updated in place across chunks) and `compiler_options()`."""
    return jax.jit(
        over_runs(trainer.run_periods, vmapped, in_axes=(0, 0, None, None)),
        static_argnums=3,
        donate_argnums=0 if donate else (),
        compiler_options=compiler_options(),
    )
