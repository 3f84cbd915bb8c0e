"""How fast XLA:CPU multiplies in each operand layout a Dense layer's forward and backward use.

    python -m benchmarks.dot_layouts [--rounds 9] [--dots 200]

A Dense layer y = x @ w (x [B, I], w [I, O]) makes three products per update: the forward x @ w, the
input gradient g @ wᵀ and the weight gradient xᵀ @ g, which contracts the batch axis, the leading
axis of both operands. At the hidden layers' size (B = I = O = 256) each is timed as a scanned
chain of `--dots` products, each product's output the next one's left operand, and so is the
weight gradient with xᵀ written out first (`lax.optimization_barrier` keeps XLA from folding the
transpose back into the dot), the form `networks.head_matmul` uses for the actor's heads. Printed
per form: whether XLA handed the dot to YNNPACK (a `__ynn_fusion` in the optimized HLO) or to its
generic dot kernel, microseconds per product and GFLOP/s. The forms are timed round by round in a
rotating order (the VM's speed drifts, benchmarks/README.md); medians over the rounds.
"""

from __future__ import annotations

import argparse
import statistics
from collections.abc import Callable

import jax

from arld_jax.compile import compiler_options
from benchmarks.harness import time_rounds

SIZE = 256  # B = I = O: every operand and product is SIZE x SIZE

# name -> the product of the carried operand a and a fixed one m, in a Dense layer's roles
FORMS: dict[str, Callable[[jax.Array, jax.Array], jax.Array]] = {
    "forward x @ w": lambda a, m: a @ m,  # a: x, m: w
    "input gradient g @ w.T": lambda a, m: a @ m.T,  # a: g, m: w
    "weight gradient x.T @ g": lambda a, m: a.T @ m,  # a: x, m: g
    "weight gradient, x.T written out": lambda a, m: jax.lax.optimization_barrier(a.T) @ m,
}


def chain(form: Callable[[jax.Array, jax.Array], jax.Array], num_dots: int) -> Callable:
    """A jitted scan of `num_dots` products of `form`, each output (scaled down, to stay finite)
    the next product's carried operand."""

    def run(a: jax.Array, m: jax.Array) -> jax.Array:
        body = lambda a, _: (form(a, m) * (1.0 / SIZE), None)  # noqa: E731
        return jax.lax.scan(body, a, None, length=num_dots)[0]

    return jax.jit(run, compiler_options=compiler_options())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=9, help="timed calls per form")
    parser.add_argument("--dots", type=int, default=200, help="products per call")
    args = parser.parse_args()

    ka, km = jax.random.split(jax.random.key(0))
    a, m = jax.random.normal(ka, (SIZE, SIZE)), jax.random.normal(km, (SIZE, SIZE))
    calls, ynn = {}, {}
    for name, form in FORMS.items():
        compiled = chain(form, args.dots).lower(a, m).compile()
        ynn[name] = "__ynn_fusion" in compiled.as_text()
        calls[name] = (lambda c: lambda: c(a, m))(compiled)
        jax.block_until_ready(calls[name]())  # warm-up
    times = time_rounds(calls, args.rounds)

    print(f"{SIZE}x{SIZE} @ {SIZE}x{SIZE}; {args.dots} products per call, median of {args.rounds}")
    print(f"{'product':34s} {'kernel':>8s} {'us each':>8s} {'GFLOP/s':>8s}")
    for name in calls:
        seconds = statistics.median(times[name]) / args.dots
        kernel = "YNNPACK" if ynn[name] else "generic"
        print(f"{name:34s} {kernel:>8s} {seconds * 1e6:8.1f} {2 * SIZE**3 / seconds / 1e9:8.1f}")


if __name__ == "__main__":
    main()
