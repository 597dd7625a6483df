"""``python -m appearance_jax.cli``: the same as the ``appearance-jax`` command."""

import sys

from . import main

sys.exit(main())
