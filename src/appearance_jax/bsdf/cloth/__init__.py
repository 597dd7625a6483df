"""Sadeghi's practical cloth model (Sadeghi 2011 Ch. 5 and App. E; Sadeghi et al. 2013).

``appearance_jax.bsdf.cloth`` is the import path of the model (:mod:`.model`): ``MODEL``,
``Params``, ``eval`` (the BRDF R / N.w_i, 1/sr), ``radiance_response`` (the thesis' R),
``sample``, ``pdf``, ``from_weave``, ``thesis_form``, ``preset``, ``velvet``, ``PRESETS``.

Modules:

- :mod:`.model`: the model (Sadeghi Eqs. 5.12-5.20), its parameters and conventions;
- :mod:`.weave`: tangent curves (App. E), masking (Eqs. 5.14-5.16), reweighting (Eqs. 5.18-5.19);
- :mod:`.energy`: the thread energy cap (this library's decision D-C10);
- :mod:`.presets`: the fabrics of Tables 5.2 / E.1 as data, with their OCR repairs;
- :mod:`.weaves`: the one-angle weave families for fitting (model ``cloth_weave``).

Measured tables and the history of this library's decisions: ``docs/cloth.md``.
"""

from . import energy, model, presets, weave, weaves
from .model import (
    DEG,
    FLOOR_RAMP,
    FLOORS,
    MODEL,
    P_DIFFUSE,
    PRESETS,
    TANGENT_FLOOR,
    Params,
    eval,
    from_weave,
    pdf,
    preset,
    radiance_response,
    sample,
    thesis_form,
    velvet,
)

__all__ = [
    "DEG", "FLOOR_RAMP", "FLOORS", "MODEL", "P_DIFFUSE", "PRESETS", "TANGENT_FLOOR", "Params", "eval",
    "from_weave", "pdf", "preset", "radiance_response", "sample", "thesis_form", "velvet",
    "energy", "model", "presets", "weave", "weaves",
]
