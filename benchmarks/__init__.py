"""Throughput, scaling and memory benchmarks of arld_jax, run from the repository root as modules:
`python -m benchmarks.bench` (the sections, README.md), `python -m benchmarks.profile_update`,
`python -m benchmarks.ab_xla_options` and `python -m benchmarks.dot_layouts`.

Importing the package imports nothing else (no jax), so a script can set `XLA_FLAGS` first.
"""
