"""``python -m appearance_jax.cli``: the same as the ``appearance-jax`` command."""

from . import console

console()
