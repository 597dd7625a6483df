"""Refractive index of liquid water for rainbow simulation (Sadeghi 2011 §3.4.2, Table 3.2).

Sadeghi 2011 uses no dispersion formula: it tabulates the index eta of water at the 33
wavelengths 380, 390, ..., 700 nm (Table 3.2, "derived from" Hale & Querry 1973) and renders
rainbows at exactly those wavelengths (L1296's "between 380 and 720 nm" is a typo for 700:
33 samples 10 nm apart; spec decision D-R2). Table 3.2 is the linear interpolation of Hale &
Querry's 25 nm, three-decimal table (``data/refractive_index/water_H2O_Hale.yml``), so it has
plateaus (1.333 at 550-570 nm, 1.331 at 650-700 nm) and a staircase derivative: do not
differentiate it with respect to wavelength; use a Cauchy fit for that.

| model       | formula (lambda in um)                                    | max abs residual vs Table 3.2 |
|-------------|-----------------------------------------------------------|-------------------------------|
| ``table``   | linear interpolation of Table 3.2 (default, D-R1)         | 0                             |
| ``cauchy3`` | 1.325598 + 2.56461e-3 / lambda^2 - 5.96636e-5 / lambda^4  | 4.2e-4                        |
| ``cauchy2`` | 1.326544 + 2.05782e-3 / lambda^2                          | 4.1e-4                        |

The Cauchy fits are least-squares fits to Table 3.2 (seed-002 spec §1.1.5, not in the thesis);
they are :class:`~appearance_jax.optics.refractive_index.Cauchy` models whose coefficients are
in um powers (B in um^2, C in um^4), valid on 380-700 nm like the table they fit. All three
models raise a ``ValueError`` for a concrete wavelength outside 380-700 nm and clamp inside
``jit``. Water's absorption (k <= 3.5e-8 in the visible) is neglected: k = 0.

The thesis text (§3.2.1, L1057-1062) quotes other values than its table: eta = 1.3314 at
700 nm and 1.3445 at 400 nm (:data:`ETA_TEXT_700NM`, :data:`ETA_TEXT_400NM`); its quoted
rainbow angles (137.7 and 129.5 deg red, 139.6 and 126.1 deg violet) follow from those.

Example::

    from appearance_jax.optics import water
    eta = water.water_ior(water.WAVELENGTHS_NM)            # (33,), Table 3.2
    eta_smooth = water.water_ior(532.0, model="cauchy3")   # differentiable in lambda
    m = water.water_model("table")                         # a refractive_index.Tabulated
"""

from __future__ import annotations

import jax
import numpy as np

from .refractive_index import Cauchy, Tabulated

#: The 33 rainbow wavelengths of Sadeghi 2011 (380-700 nm every 10 nm; spec D-R2), in nm.
WAVELENGTHS_NM = np.arange(380.0, 701.0, 10.0)

#: Sadeghi 2011 Table 3.2: eta of water at :data:`WAVELENGTHS_NM` (from Hale & Querry 1973).
TABLE_3_2_ETA = np.array([
    1.3406, 1.3398, 1.3390, 1.3386, 1.3382, 1.3378, 1.3374, 1.3370, 1.3366, 1.3362, 1.3358,  # 380-480
    1.3354, 1.3350, 1.3346, 1.3342, 1.3338, 1.3334, 1.3330, 1.3330, 1.3330, 1.3328, 1.3324,  # 490-590
    1.3320, 1.3320, 1.3320, 1.3318, 1.3314, 1.3310, 1.3310, 1.3310, 1.3310, 1.3310, 1.3310,  # 600-700
])

#: The thesis text's eta of water at 700 nm (§3.2.1, L1057; Table 3.2 gives 1.331).
ETA_TEXT_700NM = 1.3314
#: The thesis text's eta of water at 400 nm (§3.2.1, L1061; Table 3.2 gives 1.339).
ETA_TEXT_400NM = 1.3445

#: Cauchy coefficients (A, B [um^2], C [um^4]) of the least-squares fits to Table 3.2 (spec §1.1.5).
CAUCHY3_COEFFICIENTS = (1.325598, 2.56461e-3, -5.96636e-5)
CAUCHY2_COEFFICIENTS = (1.326544, 2.05782e-3)

MODELS = ("table", "cauchy3", "cauchy2")
_RANGE_NM = (float(WAVELENGTHS_NM[0]), float(WAVELENGTHS_NM[-1]))


def water_model(model: str = "table") -> Tabulated | Cauchy:
    """The water index as a :mod:`~appearance_jax.optics.refractive_index` model.

    ``model``: ``"table"`` (Table 3.2, linear interpolation; the default, D-R1),
    ``"cauchy3"`` or ``"cauchy2"`` (the Cauchy fits of the module docstring). Calling the
    result on wavelengths in nm returns ``(n, k)`` with k = 0; its coefficients are pytree
    leaves, so they can be fitted or differentiated.
    """
    # Built eagerly even when called inside jit (the table is a constant, and Tabulated's
    # construction checks need concrete values).
    with jax.ensure_compile_time_eval():
        return _build(model)


def _build(model: str):
    if model == "table":
        return Tabulated(wavelength_nm=WAVELENGTHS_NM, n=TABLE_3_2_ETA,
                         name="water (Sadeghi 2011 Table 3.2)")
    if model == "cauchy3":
        a, b, c = CAUCHY3_COEFFICIENTS
        return Cauchy(A=a, B=b, C=c, name="water (Cauchy3 fit to Sadeghi Table 3.2)",
                      wavelength_range_nm=_RANGE_NM)
    if model == "cauchy2":
        a, b = CAUCHY2_COEFFICIENTS
        return Cauchy(A=a, B=b, name="water (Cauchy2 fit to Sadeghi Table 3.2)",
                      wavelength_range_nm=_RANGE_NM)
    raise ValueError(f"water model {model!r} is unknown; choose one of {', '.join(map(repr, MODELS))}")


def water_ior(wavelength_nm, model: str = "table"):
    """Real refractive index eta of water at ``wavelength_nm`` (nm, any shape, 380-700).

    ``model`` as in :func:`water_model` (default ``"table"``: Sadeghi Table 3.2). Returns an
    array of the wavelengths' shape. Raises ``ValueError`` for a concrete wavelength outside
    380-700 nm; inside ``jit`` the wavelength is clamped to that range.
    """
    return water_model(model)(wavelength_nm)[0]


__all__ = [
    "WAVELENGTHS_NM",
    "TABLE_3_2_ETA",
    "ETA_TEXT_700NM",
    "ETA_TEXT_400NM",
    "CAUCHY3_COEFFICIENTS",
    "CAUCHY2_COEFFICIENTS",
    "MODELS",
    "water_model",
    "water_ior",
]
