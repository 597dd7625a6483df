"""Snake skin: a smooth iridescent thin film over an absorbing diffuse layer (Padrón 2025, Ch. 3).

``appearance_jax.bsdf.snake`` is the import path of the model: ``MODEL``, ``Params``,
``eval`` (the non-delta part f_d, 1/sr), ``sample``, ``pdf``, ``specular`` (the mirror
lobe's weight), ``albedo``, ``components``, ``sample_full``, ``eval_mc``, ``PRESETS``,
``ABSORPTION_FORMS``, ``UNDERSIDE_MODES``.

Modules:

- :mod:`.model`: the model (Padrón Eqs. 3.4-3.6 and the spec's composition, M26), its
  parameters and conventions;
- :mod:`.solver`: the film's Airy reflectance, the absorbing layer f_1 and the Nyström
  solve (spec M38);
- :mod:`.mc`: the whole-BSDF sampler for a path tracer and the position-free random walk.

Measured accuracy, the decisions (D14, Q-S5) and their history: ``docs/thin_films.md``.
"""

from .mc import eval_mc, sample_full
from .model import (
    ABSORPTION_FORMS,
    MODEL,
    PRESETS,
    UNDERSIDE_MODES,
    Params,
    albedo,
    components,
    eval,
    pdf,
    sample,
    specular,
)

__all__ = ["Params", "eval", "pdf", "sample", "sample_full", "components", "specular", "albedo", "eval_mc",
           "MODEL", "PRESETS", "ABSORPTION_FORMS", "UNDERSIDE_MODES"]
