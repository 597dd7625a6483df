"""The property harness (appearance_jax.testing) applied to every registered model.

Every model in ``appearance_jax.registry`` must have a parameter grid here (``GRID``: the
default run, a few cases; ``SLOW_GRID``: a wider sweep, ``-m slow``); the test
``test_every_registered_model_has_a_grid`` fails otherwise. For each case:

- reciprocity, if the model claims it (``Model.reciprocal``);
- white furnace: A(wi) <= 1 by importance sampling and quadrature, and A == 1 for the
  cases marked lossless (Lambert with reflectance 1; phase functions always integrate to
  1). Single-scattering microfacet models lose energy: only A <= 1 is asserted;
- sample/eval/pdf consistency, and importance vs uniform sampling;
- chi-square goodness of fit of the sampler (family-wise significance 1% over the
  suite's chi-square tests, Sidak);
- jax.grad vs central finite differences of a fixed linear functional of eval and pdf.

While a model module listed in the registry does not exist yet, its cases are skipped
and ``test_registry_loads`` fails.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import registry, testing


@dataclass(frozen=True)
class Case:
    id: str
    params: dict  # keyword arguments of model.Params (or {"preset": name})
    lossless: bool = False
    opts: dict = field(default_factory=dict)  # per-check overrides: {"furnace": {...}, "chi2": {...}}


GRID: dict[str, list[Case]] = {
    "lambert": [
        Case("white", dict(reflectance=1.0), lossless=True),
        Case("rgb", dict(reflectance=(0.2, 0.5, 0.9))),
    ],
    "rough_conductor": [
        Case("ggx_gold", dict(alpha=0.3)),
        Case("beckmann_aniso_separable", dict(alpha=0.25, alpha_v=0.5, distribution="beckmann",
                                              shadowing="separable")),
        Case("ggx_rough_white", dict(alpha=0.9, eta=0.2, k=8.0, specular_reflectance=(1.0, 0.8, 0.5))),
    ],
    "rough_dielectric": [
        Case("ggx_glass", dict(alpha=0.3, eta=1.5)),
        Case("beckmann_bubble_separable", dict(alpha=0.4, eta=1 / 1.33, distribution="beckmann",
                                               shadowing="separable")),
    ],
    "rough_plastic": [
        Case("ggx_rgb", dict(alpha=0.3, diffuse_reflectance=(0.2, 0.5, 0.8), eta=1.5)),
        Case("beckmann_white_nonlinear", dict(alpha=0.4, diffuse_reflectance=1.0, eta=1.33,
                                              distribution="beckmann", nonlinear=True)),
    ],
    # sums of lobes (appearance_jax.bsdf.sum): reflectances kept small enough that A <= 1
    "rough_conductor+lambert": [
        Case("ggx_gold_half_rgb_diffuse", dict(alpha=0.3, specular_reflectance=0.5, reflectance=(0.4, 0.2, 0.1))),
        Case("white_diffuse_zero_spec", dict(alpha=0.2, specular_reflectance=0.0, reflectance=1.0), lossless=True),
    ],
    "rough_plastic+lambert": [
        # gradients of a sum are its components' (rough_plastic's and lambert's cases check them)
        Case("ggx_rgb", dict(alpha=0.3, diffuse_reflectance=(0.2, 0.5, 0.8), specular_reflectance=0.5,
                             reflectance=0.1), opts={"skip": ("gradients",)}),
    ],
    # thin films: k_substrate > 0 keeps the central differences off the closed bound k = 0, where
    # the substrate's forward branch flips (autodiff is one-sided there and right)
    "iridescent": [
        Case("ggx_film_on_absorber", dict(alpha=0.3, eta_substrate=1.5, k_substrate=0.1)),
        Case("beckmann_aniso_conductor_cie", dict(alpha=0.2, alpha_v=0.5, distribution="beckmann", thickness=350.0,
                                                  eta_film=1.4, eta_substrate=0.3, k_substrate=3.0, color="cie")),
    ],
    # snake skin: the non-delta part (the mirror lobe is snake.specular). Avoided: underside="airy"
    # with eta2 != eta0 (not reciprocal by construction) and sigma_a = 0 (central differences step
    # below the closed bound)
    "snake": [
        # gradients: rgb_strong covers the same code (and test_snake.py checks every field)
        Case("default", dict(), opts={"skip": ("gradients",)}),
        Case("rgb_strong", dict(kd=(0.9, 0.5, 0.2), sigma_a=(0.05, 0.3, 0.7), eta1=2.0, eta2=1.3)),
    ],
    # rock-dove barbules: a wider longitudinal arc and spacing than the thesis fit (gaps, so T > 0, and
    # a lobe the harness' 128 x 256 furnace quadrature resolves; the thesis fit's 0.08 rad arc needs
    # the finer rule of SLOW_GRID), a brighter melanin; 2 x 1 nodes for rho: every code path, and the
    # properties hold at any quadrature (tests/bsdf/test_rock_dove.py checks the default's accuracy)
    # gradients: forward mode vs differences in tests/bsdf/test_rock_dove.py, reverse mode finite at the
    # special directions; this check's reverse-mode program takes ~30 s to compile (SLOW_GRID runs it)
    # chi2: the pdf is discontinuous along the visibility edges, where the adaptive cell cubature
    # refines to its depth limit without converging; 2 levels instead of 6 change the expected counts
    # by < 2e-4 of the mass and the p-values from 0.446 to 0.450 at a quarter of the pdf calls
    # (1.73 M -> 0.47 M, 63 -> 17 s here); the slow grid keeps the default depth
    "rock_dove": [Case("wide_gappy", dict(theta_d=0.3, H=1.8, mu=-0.6, melanin_reflectance=0.3, n_phi=2, n_theta=1),
                       opts={"skip": ("gradients",), "chi2": dict(max_depth=2)})],
    # SGGX specular microflakes (Eq. 4.10, Padrón 2025); dewy2 (alpha 0.002) is too narrow for the
    # harness quadrature and is checked in tests/phase/test_sggx_flakes.py
    "sggx_flakes": [
        Case("default", dict(), lossless=True),
        Case("tilted_rough", dict(alpha=0.5, theta=0.6), lossless=True),
        Case("matte2", dict(preset="matte2"), lossless=True),
    ],
    # the cosmetic foundation is a Monte Carlo estimator (Model.stochastic): the deterministic checks
    # below do not apply; its statistical versions (reciprocity within 3 sigma, white furnace, gradients
    # with common random numbers vs finite differences) are in tests/bsdf/test_cosmetics.py and
    # tests/layered/test_random_walk.py
    "cosmetics": [Case("dewy1", dict(preset="dewy1"))],
    # deterministic solver: tilted platelets, oriented, under a dielectric over an RGB base
    # 12 Gauss cosines x 8 modes: every code path of the default 24 x 24 at a third of the cost (the
    # properties hold at any quadrature; tests/bsdf/test_cosmetics_ordinates.py checks the default's accuracy)
    "cosmetics_ordinates": [Case("tilted_interface_base", dict(c_d=0.7, alpha=0.3, theta=0.3, thickness=2.0,
                                                               base_reflectance=(0.2, 0.5, 0.9), eta=1.4,
                                                               azimuth="fixed", n_nodes=12, n_modes=8))],
    # Sadeghi's cloth (BRDF form, not reciprocal: cos theta_i(t) / N.w_i; tests/bsdf/test_cloth.py checks
    # f_s, M and P). T = 4 tangent samples keep it cheap (presets: SLOW_GRID); the default energy gate
    # incident_cosine="patch" keeps the albedo <= 1 at grazing incidence (the thesis' formula does not)
    "cloth": [
        Case("random_T4", dict(eta=1.4, albedo=((0.5, 0.2, 0.1), (0.1, 0.3, 0.6)), k_d=(0.2, 0.6),
                               gamma_s=(8.0, 15.0), gamma_v=(16.0, 30.0), coverage=(0.6, 0.4),
                               offsets=((-20.0, -20.0, 20.0, 20.0), (-10.0, 10.0, 10.0, 10.0)),
                               lengths=((1.0, 1.0, 1.0), (1.0, 0.0, 0.0)), rotation=30.0, n_samples=4)),
    ],
    # one-angle weave families for fitting (orientation-averaged cloth): the BRDF form of cloth,
    # not reciprocal; 2 rotations and T = 4 keep it cheap
    "cloth_weave": [
        # gradients: cloth's case covers the kernel, SLOW_GRID the weave families (20 s here)
        Case("twill_T4", dict(weave="twill", alpha=20.0, n_rotations=2, n_samples=4),
             opts={"skip": ("gradients",)}),
    ],
    # Sadeghi's thread BCSDF (fiber frame, x = tangent): reciprocal; not normalised (the Linen
    # thread sends out ~1.8x what it intercepts at normal incidence, docs/cloth.md): no furnace
    "cloth_thread": [Case("linen_rgb", dict(albedo=(0.06, 0.24, 0.3)), opts={"skip": ("furnace",)})],
    # hair (fiber frame; the albedo is int S cos(theta_o) dwo). Chiang: energy conserving (white
    # hair has albedo 1), not reciprocal (A_p and the tilt depend on theta_i, N_p on h)
    "chiang_hair": [
        Case("blond_tilt", dict(sigma_a=(0.07, 0.13, 0.27), beta_m=0.15, beta_n=0.25, alpha=0.05)),
        # gradients: blond_tilt covers them (the default run's budget)
        Case("white", dict(sigma_a=0.0), lossless=True, opts={"skip": ("gradients",)}),
    ],
    # Marschner / Sadeghi: no sampler; Marschner's unit-integral Gaussian in theta_h integrates to 2
    # over theta_o, so the furnace uses longitudinal="half" (tests/bcsdf/test_marschner_hair.py)
    "marschner_hair": [Case("half_longitudinal", dict(longitudinal="half"))],
    # the artist-friendly model is not energy conserving by design (its albedo scales with the
    # lobe intensities, Sadeghi 2011 §4.5): only reciprocity and gradients apply
    "sadeghi_hair": [Case("default", dict(), opts={"skip": ("furnace",)})],
    # Huang's TT/TRT are a Monte Carlo-Simpson estimator (Model.stochastic): its statistical
    # checks (flatland reference, reciprocity within noise, gradients with common random numbers)
    # are in tests/bcsdf/test_huang_hair.py
    "huang_hair": [Case("default", dict())],
    # a Monte Carlo estimator: its statistical checks are in tests/bcsdf/test_feather_fiber.py
    "feather_fiber": [Case("default", dict())],
    # a Monte Carlo estimator: its statistical checks are in tests/bsdf/test_feather.py
    "feather": [Case("default", dict())],
    "henyey_greenstein": [
        Case("isotropic", dict(g=0.0), lossless=True),
        Case("forward", dict(g=0.8), lossless=True),
        Case("rgb_bands", dict(g=(-0.4, 0.2, 0.6)), lossless=True),
    ],
    "hg_mixture": [
        Case("default", dict(), lossless=True),
        Case("matte2", dict(preset="matte2"), lossless=True),
        Case("rgb_bands", dict(w_g=(0.3, 0.6, 0.9), g1=0.7, g2=(-0.6, -0.2, 0.1)), lossless=True),
    ],
    # a phase function integrates to 1 whatever the absorption (soot), hence lossless everywhere
    "mie": [
        Case("haze_rgb", dict(preset="haze"), lossless=True),
        # gradients: haze_rgb covers the series; tests/phase/test_mie.py checks d/d(r, n, k) at k > 0
        Case("soot", dict(preset="soot"), lossless=True, opts={"skip": ("gradients",)}),
    ],
    "tabulated_phase": [
        Case("rayleigh", dict(preset="rayleigh"), lossless=True),
        Case("coarse_random_bands", dict(values=np.random.default_rng(5).uniform(0.1, 2.0, size=(19, 2))),
             lossless=True),
    ],
}

_FINE = {"furnace": dict(n_theta=256, n_phi=512)}  # narrow lobes need a finer quadrature
# |g| = 0.95: a lobe of width ~(1 - |g|)^2 in cos theta about wi needs many nodes in theta;
# HG lobes are symmetric about wi (the rule's pole), so few are needed in phi
_PEAKED = {"furnace": dict(n_theta=512, n_phi=16)}

SLOW_GRID: dict[str, list[Case]] = {
    "lambert": [Case(f"rho{r}", dict(reflectance=r), lossless=r == 1.0) for r in (0.0, 0.3, 1.0)],
    "rough_conductor": [
        Case(f"{d}_{s}_a{a}", dict(alpha=a, distribution=d, shadowing=s), opts=_FINE if a < 0.2 else {})
        for d in ("ggx", "beckmann") for s in ("correlated", "separable") for a in (0.1, 0.5, 1.5)
    ] + [Case("ggx_aniso", dict(alpha=0.1, alpha_v=0.6), opts=_FINE)],
    "rough_dielectric": [
        Case(f"{d}_{s}_a{a}_eta{e:.3g}", dict(alpha=a, eta=e, distribution=d, shadowing=s),
             opts=_FINE if a < 0.2 else {})
        for d in ("ggx", "beckmann") for s in ("correlated", "separable") for a in (0.1, 0.6)
        for e in (1.5, 1 / 1.5)
    ] + [Case("ggx_aniso_diamond", dict(alpha=0.2, alpha_v=0.5, eta=2.42))],
    "rough_plastic": [
        Case(f"{d}_a{a}_nl{nl}", dict(alpha=a, diffuse_reflectance=(0.1, 0.5, 1.0), distribution=d, nonlinear=nl),
             opts=_FINE if a < 0.2 else {})
        for d in ("ggx", "beckmann") for a in (0.1, 0.6) for nl in (False, True)
    ] + [Case("ggx_mitsuba_tables_separable", dict(alpha=0.3, diffuse_reflectance=1.0, specular_reflectance=0.5,
                                                   eta=2.5, tables="mitsuba", shadowing="separable"))],
    "rough_conductor+lambert": [
        Case(f"{d}_a{a}_ks{ks}", dict(alpha=a, distribution=d, specular_reflectance=ks, reflectance=(0.5, 0.3, 0.1)),
             opts=_FINE if a < 0.2 else {})
        for d in ("ggx", "beckmann") for a in (0.1, 0.6) for ks in (0.2, 0.5)
    ] + [Case("beckmann_aniso_separable", dict(alpha=0.15, alpha_v=0.5, distribution="beckmann", shadowing="separable",
                                               eta=0.2, k=8.0, specular_reflectance=0.4, reflectance=0.3), opts=_FINE)],
    "rough_plastic+lambert": [
        Case(f"{d}_a{a}", dict(alpha=a, diffuse_reflectance=0.5, reflectance=(0.3, 0.1, 0.2), distribution=d),
             opts=_FINE if a < 0.2 else {})
        for d in ("ggx", "beckmann") for a in (0.08, 0.5)
    ],
    "iridescent": [
        Case("snake_like_a0.1", dict(alpha=0.1, thickness=900.0, eta_film=1.56, k_substrate=0.01), opts=_FINE),
        Case("keratin_on_melanin", dict(preset="keratin_on_melanin")),
    ],
    "snake": [
        Case("beer_sum_airy_matched", dict(absorption="beer_sum", underside="airy", kd=0.8, sigma_a=0.2, eta1=1.8)),
        Case("thick_film_beer_sum", dict(thickness=2500.0, absorption="beer_sum", kd=(0.7, 0.4, 0.2), sigma_a=0.3,
                                         eta0=1.1, eta2=1.25)),
    ],
    "rock_dove": [Case(name, dict(preset=name), opts=_FINE) for name in ("thesis_fit", "ablation_circular")],
    "sggx_flakes": [Case(f"a{a}_t{t}", dict(alpha=a, theta=t), lossless=True)
                    for a in (1.0, 0.5, 0.3) for t in (0.0, 0.6, 1.4)]
    + [Case(name, dict(preset=name), lossless=True, opts=_FINE) for name in ("dewy1", "matte1")],
    "cosmetics": [Case(name, dict(preset=name)) for name in ("dewy2", "matte1", "matte2")],
    # the presets' eta = 1 is the domain's end: central differences there straddle it and W(eta) has an
    # s^(3/2) term (tests/layered/test_ordinates.py checks the right derivative at 1); matte2 moves inside
    "cosmetics_ordinates": [Case("dewy1", dict(preset="dewy1"), opts={"skip": ("gradients",)}),
                            Case("matte2_eta1.4", dict(preset="matte2", eta=1.4))],
    "cloth": [Case(name, dict(importlib.import_module("appearance_jax.bsdf.cloth.presets").kwargs(name),
                              n_samples=16), opts=_FINE)
              for name in ("linen_plain", "silk_crepe_de_chine", "silk_shot", "polyester_satin_back", "velvet")]
    + [Case("literal_full_eq58", dict(importlib.import_module("appearance_jax.bsdf.cloth.presets").kwargs("linen_plain"),
                                      n_samples=16, theta_d="full", volume_fresnel="eq58"),
            # the literal full theta_d is singular on the specular cone (D-C1): no energy bound, and
            # central differences straddle the singularity
            opts={"skip": ("furnace", "gradients")})],
    "cloth_weave": [Case(f"{w}_T8", dict(weave=w, alpha=a, n_rotations=4, n_samples=8))
                    # satin at Table E.1's a = 32 deg: at 25 deg d/d alpha missed 1e-5 (AD vs FD 3.5e-5; the
                    # satin curve is piecewise linear, its knees move with alpha); 20, 28, 32 deg pass
                    for w, a in (("plain", 30.0), ("satin", 32.0))],
    "cloth_thread": [Case(f"{td}_{vf}", dict(theta_d=td, volume_fresnel=vf, eta=1.6, k_d=0.1, gamma_s=6.0),
                          # the literal full theta_d is singular on the specular cone (D-C1)
                          opts={"skip": ("furnace", "gradients") if td == "full" else ("furnace",)})
                     for td in ("half", "full") for vf in ("longitudinal", "eq58")],
    "chiang_hair": [
        Case("brown", dict()),
        Case("far_black", dict(sigma_a=(3.35, 5.58, 10.96), beta_m=0.6, beta_n=0.8, far_field=True, n_h=8)),
    ],
    "marschner_hair": [Case("eccentric_half", dict(longitudinal="half", axis_ratio=0.8))],
    "sadeghi_hair": [Case("default", dict(), opts={"skip": ("furnace",)})],
    "huang_hair": [Case("ellipse", dict(eccentricity=0.5))],
    "feather_fiber": [Case("default", dict())],  # Monte Carlo: tests/bcsdf/test_feather_fiber.py
    "feather": [Case("default", dict())],  # Monte Carlo: tests/bsdf/test_feather.py
    "henyey_greenstein": [Case(f"g{g}", dict(g=g), lossless=True, opts=_PEAKED if abs(g) > 0.9 else {})
                          for g in (-0.95, -0.5, 0.3, 0.95)],
    "hg_mixture": [Case(name, dict(preset=name), lossless=True) for name in ("dewy1", "dewy2", "matte1")]
    + [Case("opposed", dict(w_g=0.3, g1=0.95, g2=-0.95), lossless=True, opts=_PEAKED)],
    # fog (x up to 40): the phase function ripples in r and lambda, so central differences at the default
    # step carry an h^2 (third derivative) error of 1.2e-4; 6e-7 at step 1e-6 and 7e-9 at 1e-7: AD is right
    "mie": [Case(name, dict(preset=name), lossless=True,
                 opts={**_PEAKED, "gradients": dict(step=1e-6)} if name == "fog" else _PEAKED)
            for name in ("rayleigh", "fog")]
    + [Case("glass_x20", dict(radius_um=2.0, wavelength_nm=600.0, n_particle=1.5), lossless=True, opts=_PEAKED)],
    # narrow lobes (a 0.03 rad bow-like one), symmetric about wi
    "tabulated_phase": [Case("two_lobes_rgb", dict(preset="two_lobes_rgb"), lossless=True,
                             opts={"furnace": dict(n_theta=512, n_phi=16)})],
}


MODELS = {m.name: m for m in registry.models()}


def _cases(grid):
    names = sorted(set(grid) | set(MODELS))
    return [pytest.param(name, case, id=f"{name}-{case.id}") for name in names for case in grid.get(name, [])]


CASES = _cases(GRID)
SLOW_CASES = _cases(SLOW_GRID)
N_CHI2 = len(CASES)  # Sidak correction over the chi-square tests of the default run


# where the Monte Carlo estimators' statistical property tests live (standard-error tolerances)
_MC_TESTS = {"cosmetics": "tests/bsdf/test_cosmetics.py and tests/layered/test_random_walk.py",
             "feather": "tests/bsdf/test_feather.py", "feather_fiber": "tests/bcsdf/test_feather_fiber.py",
             "huang_hair": "tests/bcsdf/test_huang_hair.py and tests/bcsdf/test_huang_sampling.py"}


def _setup(name, case):
    model = MODELS[name]
    if model.stochastic:
        pytest.skip(f"{name} is a Monte Carlo estimator: its statistical property tests live in "
                    f"{_MC_TESTS.get(name, 'its own test file')}")
    kw = dict(case.params)
    if "preset" in kw:  # a preset, with any other fields replaced
        return model, model.presets[kw.pop("preset")].replace(**kw)
    return model, model.Params(**kw)


def test_every_model_the_library_defines_is_registered():
    """Every ``MODEL`` record in a module of the package is listed by the registry."""
    import pkgutil

    import appearance_jax
    from appearance_jax.core.model import Model

    defined = {}
    for info in pkgutil.walk_packages(appearance_jax.__path__, "appearance_jax."):
        if info.name.endswith(("cli", "__main__")):
            continue
        model = getattr(importlib.import_module(info.name), "MODEL", None)
        if isinstance(model, Model):
            defined[model.name] = info.name
    registered = {m.name: m for m in registry.models()}
    assert set(defined) <= set(registered), f"defined but not registered: {set(defined) - set(registered)}"
    for name, module in defined.items():
        assert importlib.import_module(module).MODEL is registered[name]


def test_every_params_field_is_typed():
    """Numeric fields are annotated ``Real`` or ``Bands`` (``| None`` when optional), matching
    their ``bands`` metadata; static fields carry their own type, never ``object``."""
    import dataclasses
    import typing

    from appearance_jax.core.params import Bands, ParamSpec, Real, param_specs

    for name, model in MODELS.items():
        hints = typing.get_type_hints(model.Params)
        for fname, spec in param_specs(model.Params).items():
            t = hints[fname]
            assert t is not object, f"{name}.Params.{fname} is annotated object"
            if isinstance(spec, ParamSpec):
                want = Bands if spec.bands else Real
                optional = model.Params.__dataclass_fields__[fname].default is None
                assert t == (want | None if optional else want), f"{name}.Params.{fname}: {t}"
        assert all(f.name in hints for f in dataclasses.fields(model.Params))


def test_every_registered_model_has_a_grid():
    no_grid = sorted(set(MODELS) - set(GRID))
    no_slow = sorted(set(MODELS) - set(SLOW_GRID))
    assert not no_grid and not no_slow, f"models without a property-test grid: default {no_grid}, slow {no_slow}"
    for name in MODELS:
        assert GRID[name] and SLOW_GRID[name]


# ----------------------------------------------------------------------------------
# the checks


def _reciprocity(model, params, case, scale=1):
    if not model.reciprocal:
        pytest.skip(f"{model.name} is not reciprocal (Model.reciprocal = False)")
    testing.assert_reciprocity(model, params, key=1, n=256 * scale)


def _furnace(model, params, case, scale=1):
    if "furnace" in case.opts.get("skip", ()):
        pytest.skip(f"{model.name}: no energy bound (see the case's comment in GRID)")
    kw = dict(key=2, n_wi=4 * scale, n_samples=2**13 * scale, n_theta=96, n_phi=192, lossless=case.lossless)
    kw.update(case.opts.get("furnace", {}))
    testing.assert_white_furnace(model, params, **kw)


def _sampling(model, params, case, scale=1):
    if model.sample is None:
        pytest.skip(f"{model.name} has no sampler")
    kw = dict(key=3, n_wi=4 * scale, n_samples=2**13 * scale)
    kw.update(case.opts.get("sampling", {}))
    testing.assert_sampling(model, params, **kw)


def _chi2(model, params, case, scale=1, n_tests=N_CHI2):
    if model.sample is None or model.pdf is None:
        pytest.skip(f"{model.name} has no sampler/pdf")
    kw = dict(key=4, n_wi=2 * scale, n_samples=2**16 * scale, n_tests=n_tests)
    kw.update(case.opts.get("chi2", {}))
    testing.assert_chi2(model, params, **kw)


def _gradients(model, params, case, scale=1):
    """d/dparams of a fixed linear functional of eval (and pdf) at 32 pairs, vs FD.

    The pairs mix uniform directions and directions sampled from the model, so the
    functional sees the lobes. Evaluated under jit (parameters traced, no validation),
    so the finite differences may step across a closed bound such as reflectance = 1.
    """
    wi, wo = testing.reciprocity_pairs(model, params, key=5, n=32 * scale)
    f0 = testing.call_chunked(model.eval, params, wi, wo)  # the other checks' compiled eval and pdf
    wi, wo = (w.map(jnp.asarray) for w in (wi, wo))
    c = jax.random.uniform(jax.random.key(6), f0.shape, jnp.float64) / max(float(np.abs(f0).max()), 1e-12)
    has_pdf = model.pdf is not None
    if has_pdf:
        p0 = testing.call_chunked(model.pdf, params, wi, wo)
        d = jax.random.uniform(jax.random.key(7), p0.shape, jnp.float64) / max(float(np.abs(p0).max()), 1e-12)

    def functional(p):
        out = jnp.sum(c * model.eval(p, wi, wo))
        return out + jnp.sum(d * model.pdf(p, wi, wo)) if has_pdf else out

    # one compiled program for the value and the derivatives (jax.grad of a jitted function compiles
    # its forward and backward passes separately), which the finite differences run too: a separate
    # forward program would be a second compile, and the backward pass at 32 pairs costs little
    value_and_grad = jax.jit(jax.value_and_grad(functional))
    testing.assert_gradients(lambda p: value_and_grad(p)[0], params, name=model.name,
                             grad_fn=lambda p: value_and_grad(p)[1], **case.opts.get("gradients", {}))


CHECKS = {"reciprocity": _reciprocity, "furnace": _furnace, "sampling": _sampling, "chi2": _chi2,
          "gradients": _gradients}


def _skip_if_asked(name, case, check):
    """A case's ``opts["skip"]`` (the furnace reports its own skip)."""
    if check != "furnace" and check in case.opts.get("skip", ()):
        pytest.skip(f"{name}/{case.id}: {check} skipped in this case (see its comment in the grid)")


@pytest.mark.parametrize("check", list(CHECKS))
@pytest.mark.parametrize("name,case", CASES)
def test_property(name, case, check):
    _skip_if_asked(name, case, check)
    model, params = _setup(name, case)
    CHECKS[check](model, params, case)


@pytest.mark.slow
@pytest.mark.parametrize("check", list(CHECKS))
@pytest.mark.parametrize("name,case", SLOW_CASES)
def test_property_wide(name, case, check):
    _skip_if_asked(name, case, check)
    model, params = _setup(name, case)
    kw = dict(n_tests=len(SLOW_CASES)) if check == "chi2" else {}
    CHECKS[check](model, params, case, scale=2, **kw)
