"""`python -m arld_jax.human`: see arld_jax/human/cli.py."""

from arld_jax.human.cli import main

if __name__ == "__main__":
    main()
