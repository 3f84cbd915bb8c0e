"""Other projects' trainers run beside arld_jax's: each in its own virtual environment, as a child
process (`brax_sac.py`, which imports nothing from arld_jax), timed at the same configs
(`section.py`, the benchmark's `peers` section)."""
