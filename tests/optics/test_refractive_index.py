"""Refractive-index models and the refractiveindex.info YAML loader."""

import re
import textwrap
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.data import path as data_path
from appearance_jax.optics.refractive_index import Cauchy, Combined, Constant, Formula, Sellmeier, Tabulated
from appearance_jax.optics.refractiveindex_yaml import (
    available_materials,
    load_material,
    load_refractiveindex_yaml,
    parse_refractiveindex_yaml,
)

# Files with known upstream quirks (see data/refractive_index/PROVENANCE.md)
_WARNS = {"Fe2O3_hematite_Querry-o"}


def _load(name):
    if name in _WARNS:
        with pytest.warns(UserWarning, match="out of wavelength order"):
            return load_material(name)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return load_material(name)


# ------------------------------------------------------------------ shipped files


def test_available_materials_lists_all_data_files():
    folder = data_path("refractive_index")
    stems = sorted(p.name[:-4] for p in folder.iterdir() if p.name.endswith(".yml"))
    names = available_materials()
    assert names == [s for s in stems if not s.endswith("_about")]
    assert len(names) == 23


@pytest.mark.parametrize("name", available_materials())
def test_every_shipped_file_loads_and_evaluates(name):
    m = _load(name)
    lo, hi = m._range_nm()
    assert 0 < lo < hi
    wl = np.linspace(lo, hi, 7)
    n, k = m(wl)
    assert n.shape == k.shape == (7,)
    assert np.all(np.isfinite(n)) and np.all(np.isfinite(k))
    assert np.all(np.asarray(n) > 0)
    # in the visible range where covered: dielectric-like or metal-like, never absurd
    vis = np.clip(np.array([450.0, 550.0, 650.0]), lo, hi)
    n, k = m(vis)
    assert np.all((np.asarray(n) > 0.01) & (np.asarray(n) < 4.0))
    assert np.all((np.asarray(k) >= 0) & (np.asarray(k) < 10.0))


def test_about_file_is_not_a_material():
    with pytest.raises(ValueError, match=r"silk_about\.yml.*no DATA"):
        load_refractiveindex_yaml(data_path("refractive_index", "silk_about.yml"))


def test_unknown_material_lists_the_available_ones():
    with pytest.raises(ValueError, match=r"'Unobtainium'.*Au_Johnson.*water_H2O_Hale"):
        load_material("Unobtainium")


def test_fused_silica_malitson():
    # Malitson 1965: n_d = 1.4585 at the helium d line, 587.56 nm
    m = _load("SiO2_fused_Malitson")
    assert float(m(587.56)[0]) == pytest.approx(1.4585, abs=1e-4)
    assert float(m(587.56)[1]) == 0.0
    # and equals our own Sellmeier model with Malitson's coefficients (its default)
    wl = np.linspace(300.0, 1500.0, 25)
    np.testing.assert_allclose(m(wl)[0], Sellmeier()(wl)[0], rtol=1e-12)


@pytest.mark.parametrize("name, expected", [("water_H2O_Daimon-20.0C", 1.33336), ("water_H2O_Hale", 1.33244),
                                            ("water_H2O_Segelstein", 1.33367)])
def test_water_at_sodium_d_line(name, expected):
    # all three near the textbook 1.333; measured here: Daimon 20 C 1.33336 (their formula),
    # Hale & Querry 25 C 1.33244 and Segelstein 1.33367 (interpolated tables)
    n, k = _load(name)(589.0)
    assert float(n) == pytest.approx(1.333, abs=1e-3)
    assert float(n) == pytest.approx(expected, abs=1e-5)
    assert 0 <= float(k) < 1e-7  # water barely absorbs in the visible


def test_gold_johnson_equals_table_at_tabulated_wavelengths():
    # rows of the file, parsed here independently of the loader: um, n, k
    text = data_path("refractive_index", "Au_Johnson.yml").read_text()
    rows = {}
    for line in text.splitlines():
        parts = line.split()
        if len(parts) == 3:
            try:
                rows[float(parts[0])] = (float(parts[1]), float(parts[2]))
            except ValueError:
                pass
    gold = _load("Au_Johnson")
    for um in (0.4959, 0.5486, 0.5821):
        n, k = gold(um * 1000.0)
        assert float(n) == pytest.approx(rows[um][0], abs=1e-12)
        assert float(k) == pytest.approx(rows[um][1], abs=1e-12)
    # between two rows: linear interpolation
    n, _ = gold(0.5 * (548.6 + 582.1))
    assert float(n) == pytest.approx(0.5 * (0.43 + 0.29), abs=1e-12)
    assert complex(gold.complex(548.6)) == pytest.approx(0.43 + 2.455j, abs=1e-12)


def test_silk_combines_formula_n_and_tabulated_k():
    silk = _load("silk_Bombyx-mori_Perotto")
    assert isinstance(silk, Combined)
    n, k = silk(500.0)
    # formula 5 (Cauchy): 1.551 + 0.0026 / l^2 + 2.4e-4 / l^4, l in um; k tabulated 3.762740e-4
    assert float(n) == pytest.approx(1.551 + 0.0026 / 0.25 + 2.4e-4 / 0.0625, abs=1e-12)
    assert float(k) == pytest.approx(3.762740e-4, abs=1e-12)


def test_birefringent_pairs_differ():
    # calcite: n_o > n_e; rutile: n_e > n_o (Ghosh 1999, Devore 1951)
    ne, no = _load("CaCO3_calcite_Ghosh-e")(589.0)[0], _load("CaCO3_calcite_Ghosh-o")(589.0)[0]
    assert float(no) == pytest.approx(1.6584, abs=5e-4) and float(ne) == pytest.approx(1.4864, abs=5e-4)
    ne, no = _load("TiO2_rutile_Devore-e")(589.0)[0], _load("TiO2_rutile_Devore-o")(589.0)[0]
    assert float(no) == pytest.approx(2.613, abs=2e-3) and float(ne) == pytest.approx(2.909, abs=2e-3)


# ------------------------------------------------------------------ formulas 1-9


def _f_numpy(kind, c, lam):
    """Independent (loop-based) evaluation of the refractiveindex.info formulas, lam in um."""
    c = list(c)
    if kind == 1:
        s = 1 + c[0]
        for i in range(1, len(c), 2):
            s += c[i] * lam**2 / (lam**2 - c[i + 1] ** 2)
        return np.sqrt(s)
    if kind == 2:
        s = 1 + c[0]
        for i in range(1, len(c), 2):
            s += c[i] * lam**2 / (lam**2 - c[i + 1])
        return np.sqrt(s)
    if kind in (3, 5):
        s = c[0]
        for i in range(1, len(c), 2):
            s += c[i] * lam ** c[i + 1]
        return np.sqrt(s) if kind == 3 else s
    if kind == 4:
        s = c[0] + c[1] * lam ** c[2] / (lam**2 - c[3] ** c[4]) + c[5] * lam ** c[6] / (lam**2 - c[7] ** c[8])
        for i in range(9, len(c), 2):
            s += c[i] * lam ** c[i + 1]
        return np.sqrt(s)
    if kind == 6:
        s = 1 + c[0]
        for i in range(1, len(c), 2):
            s += c[i] / (c[i + 1] - lam**-2)
        return s
    if kind == 7:
        L = 1 / (lam**2 - 0.028)
        return c[0] + c[1] * L + c[2] * L**2 + c[3] * lam**2 + c[4] * lam**4 + c[5] * lam**6
    if kind == 8:
        r = c[0] + c[1] * lam**2 / (lam**2 - c[2]) + c[3] * lam**2
        return np.sqrt((1 + 2 * r) / (1 - r))
    if kind == 9:
        return np.sqrt(c[0] + c[1] / (lam**2 - c[2]) + c[3] * (lam - c[4]) / ((lam - c[4]) ** 2 + c[5]))
    raise AssertionError(kind)


FORMULA_CASES = {
    1: "0 0.6961663 0.0684043 0.4079426 0.1162414 0.8974794 9.896161",
    2: "0.2 5.684027565E-1 5.101829712E-3 1.726177391E-1 1.821153936E-2",
    3: "2.25 0.012 -2 -0.004 2 1e-4 -4",
    4: "2.0 0.5 2 0.1 2 0.3 1.5 3.0 2 0.01 -2 -0.002 2",
    5: "1.551 0.0026 -2 2.4e-4 -4",
    6: "0 0.05792105 238.0185 0.00167917 57.362",
    7: "1.5 0.005 0.0001 -0.001 1e-5 -1e-7",
    8: "0.25 0.02 0.015 -0.001",
    9: "2.2 0.02 0.03 0.05 0.3 0.01",
}


def _yaml(kind_line, body):
    return textwrap.dedent(
        f"""\
        REFERENCES: synthetic
        DATA:
          - type: {kind_line}
        """
    ) + textwrap.indent(textwrap.dedent(body), "    ")


@pytest.mark.parametrize("kind", sorted(FORMULA_CASES))
def test_formula_matches_independent_numpy(kind, tmp_path):
    coeffs = FORMULA_CASES[kind]
    f = tmp_path / f"formula{kind}.yml"
    f.write_text(_yaml(f"formula {kind}", f"wavelength_range: 0.4 1.0\ncoefficients: {coeffs}\n"))
    m = load_refractiveindex_yaml(f)
    assert isinstance(m, Formula) and m.kind == kind
    assert m._range_nm() == pytest.approx((400.0, 1000.0))
    wl = np.linspace(400.0, 1000.0, 31)
    ref = _f_numpy(kind, [float(x) for x in coeffs.split()], wl / 1000.0)
    assert np.all(np.isfinite(ref)) and np.all((ref > 1.0) & (ref < 3.0))
    n, k = m(wl)
    np.testing.assert_allclose(n, ref, rtol=1e-12)
    np.testing.assert_allclose(k, 0.0)


def test_formula_gradients_finite_and_match_fd():
    # d n / d lambda and d n / d coefficients, for the formula with exponents (4)
    c = jnp.array([float(x) for x in FORMULA_CASES[4].split()])
    wl = 600.0

    def n_of(c_, wl_):
        return Formula(kind=4, coefficients=c_, wavelength_range_nm=(400.0, 1000.0))(wl_)[0]

    r = testing.assert_gradients(lambda w: n_of(c, w), wl, step=1e-3 / wl, rtol=1e-6, name="dn/dlambda")
    assert r.ad[0][0] < 0  # normal dispersion
    gc = jax.grad(n_of)(c, wl)
    assert np.all(np.isfinite(np.asarray(gc)))
    # formula 4 with zero placeholders (the Devore rutile files): 0 ** 0 terms stay finite
    dev = jnp.array([5.913, 0.2441, 0.0, 0.0803, 1.0, 0.0, 0.0, 0.0, 1.0])
    g = jax.grad(n_of)(dev, 1000.0)  # lambda = 1 um: lambda^2 - 0^1 would be 1 - 0
    assert np.all(np.isfinite(np.asarray(g)))


def test_tabulated_n_and_combined_formula_with_tabulated_k(tmp_path):
    f = tmp_path / "mix.yml"
    f.write_text(textwrap.dedent("""\
        DATA:
          - type: formula 2
            wavelength_range: 0.3 0.9
            coefficients: 0 1.1819 0.011313
          - type: tabulated k
            data: |
                0.40 1.0e-3
                0.60 3.0e-3
                1.00 5.0e-3
        """))
    m = load_refractiveindex_yaml(f)
    assert isinstance(m, Combined)
    assert m._range_nm() == pytest.approx((400.0, 900.0))  # intersection of n and k ranges
    n, k = m(np.array([400.0, 500.0, 600.0]))
    np.testing.assert_allclose(k, [1e-3, 2e-3, 3e-3], rtol=1e-12)
    np.testing.assert_allclose(n, _f_numpy(2, [0, 1.1819, 0.011313], np.array([0.4, 0.5, 0.6])), rtol=1e-12)
    with pytest.raises(ValueError, match=r"'mix'.*950.*\[400, 900\] nm"):
        m(950.0)

    g = tmp_path / "tabn.yml"
    g.write_text("DATA:\n  - type: tabulated n\n    data: |\n        0.5 1.40\n        0.7 1.38\n")
    t = load_refractiveindex_yaml(g)
    n, k = t(600.0)
    assert float(n) == pytest.approx(1.39, abs=1e-12) and float(k) == 0.0


def test_old_range_key_and_duplicate_rows(tmp_path):
    f = tmp_path / "old.yml"
    f.write_text("DATA:\n  - type: formula 5\n    range: 0.4 0.8\n    coefficients: 1.5 0.004 -2\n")
    assert load_refractiveindex_yaml(f)._range_nm() == pytest.approx((400.0, 800.0))
    g = tmp_path / "dup.yml"
    rows = "        0.5 1.4 0\n        0.5 1.4 0\n        0.7 1.3 0\n"  # a repeated identical row
    g.write_text("DATA:\n  - type: tabulated nk\n    data: |\n" + rows)
    assert float(load_refractiveindex_yaml(g)(600.0)[0]) == pytest.approx(1.35, abs=1e-12)


# ------------------------------------------------------------------ malformed files

MALFORMED = {
    "no_data": ("REFERENCES: nothing here\n", r"no DATA"),
    "empty_data": ("DATA: []\n", r"non-empty list"),
    "not_yaml": ("DATA: [unclosed\n", r"not valid YAML"),
    "no_type": ("DATA:\n  - coefficients: 1 2 3\n", r"entry 1 has no 'type'"),
    "unknown_type": ("DATA:\n  - type: tabulated xyz\n    data: |\n        0.5 1 2 3\n",
                     r"unsupported type 'tabulated xyz'"),
    "formula_10": ("DATA:\n  - type: formula 10\n    wavelength_range: 0.4 0.8\n    coefficients: 1\n",
                   r"unsupported type 'formula 10'"),
    "bad_count": ("DATA:\n  - type: formula 1\n    wavelength_range: 0.4 0.8\n    coefficients: 0 1.0\n",
                  r"formula 1.*2 coefficients; expected an odd number"),
    "bad_count_4": ("DATA:\n  - type: formula 4\n    wavelength_range: 0.4 0.8\n    coefficients: 1 2 3\n",
                    r"3 coefficients"),
    "bad_count_9": ("DATA:\n  - type: formula 9\n    wavelength_range: 0.4 0.8\n"
                    "    coefficients: 1 2 3 4 5 6 7\n", r"7 coefficients"),
    "no_coefficients": ("DATA:\n  - type: formula 2\n    wavelength_range: 0.4 0.8\n", r"no 'coefficients'"),
    "text_coefficients": ("DATA:\n  - type: formula 2\n    wavelength_range: 0.4 0.8\n    coefficients: 0 one 2\n",
                          r"non-numeric value 'one'"),
    "no_range": ("DATA:\n  - type: formula 2\n    coefficients: 0 1 0.01\n", r"no 'wavelength_range'"),
    "bad_range": ("DATA:\n  - type: formula 2\n    wavelength_range: 0.8 0.4\n    coefficients: 0 1 0.01\n",
                  r"invalid wavelength_range"),
    "text_row": ("DATA:\n  - type: tabulated nk\n    data: |\n        0.5 1.4 0.1\n        0.6 abc 0.1\n",
                 r"row 2 '0.6 abc 0.1' is not numeric"),
    "short_row": ("DATA:\n  - type: tabulated nk\n    data: |\n        0.5 1.4 0.1\n        0.6 1.4\n",
                  r"row 2.*expected 3 numbers, got 2"),
    "empty_table": ("DATA:\n  - type: tabulated nk\n    data: |\n        \n", r"empty table"),
    "conflicting_rows": ("DATA:\n  - type: tabulated n\n    data: |\n        0.5 1.4\n        0.5 1.5\n",
                         r"two different values at 0.5 um"),
    "only_k": ("DATA:\n  - type: tabulated k\n    data: |\n        0.5 0.1\n        0.6 0.1\n", r"no entry giving"),
    "two_n": ("DATA:\n  - type: formula 5\n    wavelength_range: 0.4 0.8\n    coefficients: 1.5\n"
              "  - type: tabulated n\n    data: |\n        0.5 1.4\n        0.6 1.4\n",
              r"entries 1 and 2 both give n"),
    "disjoint": ("DATA:\n  - type: formula 5\n    wavelength_range: 0.4 0.8\n    coefficients: 1.5\n"
                 "  - type: tabulated k\n    data: |\n        1.5 0.1\n        1.6 0.1\n", r"do not overlap"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_files_raise_naming_the_file(case, tmp_path):
    text, pattern = MALFORMED[case]
    f = tmp_path / f"bad_{case}.yml"
    f.write_text(text)
    with pytest.raises(ValueError) as err:
        load_refractiveindex_yaml(f)
    msg = str(err.value)
    assert f"bad_{case}.yml" in msg
    assert re.search(pattern, msg), msg


def test_missing_file_raises_value_error(tmp_path):
    with pytest.raises(ValueError, match="nope.yml.*cannot be read"):
        load_refractiveindex_yaml(tmp_path / "nope.yml")


def test_parse_from_string_names_source():
    with pytest.raises(ValueError, match="<my text>"):
        parse_refractiveindex_yaml("foo: 1\n", source="<my text>")


# ------------------------------------------------------------------ wavelength ranges


def test_out_of_range_wavelength_raises_naming_material_and_range():
    gold = _load("Au_Johnson")
    with pytest.raises(ValueError, match=r"'Au_Johnson'.*2500 nm.*\[187\.9, 1937\] nm"):
        gold(np.array([500.0, 2500.0]))
    silica = _load("SiO2_fused_Malitson")
    with pytest.raises(ValueError, match=r"'SiO2_fused_Malitson'.*150 nm.*\[210, 6700\] nm"):
        silica(150.0)
    with pytest.raises(ValueError, match="nan"):
        silica(np.nan)
    # the end points themselves are fine (micrometre -> nm conversion slack)
    silica(210.0), silica(6700.0), gold(187.9), gold(1937.0)


def test_inside_jit_wavelengths_are_clamped():
    gold = _load("Au_Johnson")
    silica = _load("SiO2_fused_Malitson")
    f = jax.jit(lambda wl: (gold(wl)[0], silica(wl)[0]))
    n_gold, n_si = f(jnp.array([100.0, 3000.0, 8000.0]))
    np.testing.assert_allclose(n_gold, [gold(187.9)[0], gold(1937.0)[0], gold(1937.0)[0]], rtol=1e-12)
    np.testing.assert_allclose(n_si, [silica(210.0)[0], silica(3000.0)[0], silica(6700.0)[0]], rtol=1e-12)


def test_models_are_pytrees_usable_inside_jit():
    gold = _load("Au_Johnson")
    f = jax.jit(lambda m, wl: m.complex(wl))
    z = f(gold, jnp.array([548.6]))
    assert complex(z[0]) == pytest.approx(0.43 + 2.455j, abs=1e-12)
    # vmapped over a batch of Cauchy models
    n = jax.vmap(lambda A, B: Cauchy(A=A, B=B)(500.0)[0])(jnp.array([1.5, 1.6]), jnp.array([0.004, 0.006]))
    np.testing.assert_allclose(n, [1.5 + 0.004 / 0.25, 1.6 + 0.006 / 0.25], rtol=1e-12)


# ------------------------------------------------------------------ analytic models


def test_constant():
    m = Constant(n=1.33, k=0.01)
    n, k = m(np.array([400.0, 700.0]))
    np.testing.assert_allclose(n, 1.33)
    np.testing.assert_allclose(k, 0.01)
    assert m.complex(500.0) == pytest.approx(1.33 + 0.01j)
    with pytest.raises(ValueError, match=r"Constant\.n = -1"):
        Constant(n=-1.0)(500.0)
    with pytest.raises(ValueError, match=r"Constant\.k = -0\.1"):
        Constant(k=-0.1)(500.0)


def test_cauchy_keratin_of_huang():
    # keratin n = 1.532 + 5890 / lambda^2 (lambda in nm) = 1.549 at 589 nm (seed 001 spec §0.4-11)
    keratin = Cauchy(A=1.532, B=5.89e-3)
    assert float(keratin(589.0)[0]) == pytest.approx(1.532 + 5890 / 589.0**2, rel=1e-12)
    assert float(keratin(589.0)[0]) == pytest.approx(1.549, abs=5e-4)
    m = Cauchy(A=1.5, B=0.01, C=0.001, D=1e-4, k=0.02)
    lam = 0.5
    assert float(m(500.0)[0]) == pytest.approx(1.5 + 0.01 / lam**2 + 0.001 / lam**4 + 1e-4 / lam**6, rel=1e-12)
    assert float(m(500.0)[1]) == 0.02


def test_sellmeier_and_gradients():
    m = Sellmeier(B=(1.0, 0.2), C=(0.01, 100.0))
    lam = 0.6
    expected = np.sqrt(1 + 1.0 * lam**2 / (lam**2 - 0.01) + 0.2 * lam**2 / (lam**2 - 100.0))
    assert float(m(600.0)[0]) == pytest.approx(expected, rel=1e-12)

    def n_of(B):
        return Sellmeier(B=B, C=jnp.array([0.01, 100.0]))(600.0)[0]

    B = jnp.array([1.0, 0.2])
    testing.assert_gradients(n_of, B, step=1e-6, rtol=1e-6, elementwise=True, name="dn/dB")
    with pytest.raises(ValueError, match="same number of terms"):
        Sellmeier(B=(1.0, 0.2), C=(0.01,))(600.0)


def test_tabulated_model():
    t = Tabulated(wavelength_nm=(400.0, 500.0, 700.0), n=(1.5, 1.4, 1.2), k=(0.0, 0.1, 0.3), name="test")
    n, k = t(np.array([450.0, 600.0]))
    np.testing.assert_allclose(n, [1.45, 1.3], rtol=1e-12)
    np.testing.assert_allclose(k, [0.05, 0.2], rtol=1e-12)
    with pytest.raises(ValueError, match=r"'test'.*399 nm.*\[400, 700\] nm"):
        t(399.0)
    with pytest.raises(ValueError, match="strictly increasing"):
        Tabulated(wavelength_nm=(400.0, 400.0), n=(1.5, 1.4))(400.0)
    with pytest.raises(ValueError, match="same shape"):
        Tabulated(wavelength_nm=(400.0, 500.0), n=(1.5, 1.4, 1.3))(450.0)
    # differentiable with respect to the table values (fitting a measured dispersion)
    g = jax.grad(lambda nn: Tabulated(wavelength_nm=jnp.array([400.0, 500.0]), n=nn)(425.0)[0])(
        jnp.array([1.5, 1.4]))
    np.testing.assert_allclose(g, [0.75, 0.25], rtol=1e-12)
