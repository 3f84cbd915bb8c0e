"""Other projects' trainers run beside arld_jax's, each in its own virtual environment, as a child
process that imports nothing from arld_jax: Brax's SAC (`brax_sac.py`), timed at the same configs
(`section.py`, the benchmark's `peers` section), and sbx's SAC on Gymnasium's v5 tasks
(`sbx_sac.py`), the learning-curve peer of the `sac_300k` parity runs, optionally on another model
(e.g. Brax's), which `same_model.py` checks step by step against arld_jax's task. `vs_sbx.py` reads our
runs against sbx's seeds with Welch's interval."""
