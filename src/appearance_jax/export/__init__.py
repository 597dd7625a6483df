"""Bridges from fitted parameters to renderers.

:mod:`~appearance_jax.export.mitsuba` writes a model's parameters (or a fit's ``params.json``)
as a Mitsuba 3 BSDF, a ``mitsuba.load_dict`` dict or an XML element, for the models Mitsuba
has (``lambert``, ``rough_conductor``, ``rough_dielectric``, ``rough_plastic``, their sums and
``chiang_hair``); the parameter mapping is documented in ``docs/export.md``.
:mod:`~appearance_jax.export.cli` is the ``appearance-jax export`` subcommand.

The layer sits above the registry and the fitters (it reads the records they write).
"""

__all__ = ["EXPORTABLE", "ExportError", "differences", "from_params_json", "to_mitsuba", "to_mitsuba_xml"]


def __getattr__(name):
    # lazy: the command line imports export.cli for its parser without loading the models
    if name in __all__:
        from . import mitsuba

        return getattr(mitsuba, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
