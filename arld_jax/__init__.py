"""arld_jax: Active Reinforcement Learning from Demonstration (SAC / Noisy SAC) in JAX.

Start at `arld_jax.train.make_train` (the scanned loop) and `arld_jax.config.Config`.
Submodules are imported lazily so that `arld_jax.results` / `arld_jax.plots` load without jax.
"""

__version__ = "0.1.0"
