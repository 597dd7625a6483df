"""Shipped tables (installed as ``appearance_jax.data``); each folder has a provenance file."""

from importlib.resources import files


def path(*parts: str):
    """Path of a shipped data file, e.g. ``path("refractive_index", "Au_Johnson.yml")``."""
    p = files(__name__)
    for part in parts:
        p = p / part
    return p
