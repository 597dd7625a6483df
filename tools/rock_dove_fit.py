"""Issue 22's fitting stand-in: recover rock_dove's 7 shape and film parameters from synthetic maps.

    python3 tools/rock_dove_fit.py [--noise 0.02] [--seed 0] [--starts 3] [--quick] [--color cie]
                                   [--omni] [--scale 1.7]

Huang hand-fitted 7 parameters (b, phi0, phi1, H, d, theta_d, mu) to uncalibrated scatterograms
[T:1744-1746] and released no data. The stand-in: hemispherical maps of ``rock_dove.eval`` of the
``thesis_fit`` preset (the deterministic evaluator, rho on 4 x 2 nodes) at several incidences -- across
the barbules (phi_i = 0, three elevations) and along them (phi_i = 90 deg) -- times (1 + noise * N(0, 1))
with a 1-sigma column of noise x value (floor: 1e-3 of the largest value), fitted from a perturbed start
with ``appearance_jax.fit.fit`` (Levenberg-Marquardt, forward-mode Jacobian, absolute sigmas). The film
thickness d is multi-started over one period of the film's optical thickness at normal incidence,
lambda / (2 eta) = 164 nm at 510 nm (the fit's other parameters start from the same perturbed values).
eta_keratin and the melanin reflectance are held at their true values.

Options closer to Huang's scatterograms: ``--color cie`` (linear sRGB of the CIE-integrated spectrum
instead of three wavelengths), ``--omni`` (add a map under uniform light from the whole upper
hemisphere, omni(w_o) = integral of S(w_i, w_o) <w_i, n> dw_i on a 4 x 8 rule in (cos theta_i, phi_i),
the same rule for the data and the model; its rows are marked by theta_i = 0, which the directional
maps do not use), ``--scale K`` (the maps are uncalibrated: the data are multiplied by K and the fit
frees a global colour scale, a field of the stand-in's model, started at 1).

Prints the truth, the start, the fit with its 1-sigma and the fit's warnings (flat directions,
correlations), and the times. Not a test (tests/bsdf/test_rock_dove_fit.py runs the --quick case).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

FREE = ("b", "phi0", "phi1", "H", "thickness", "theta_d", "mu")
FIX = ("eta_keratin", "melanin_reflectance")
# a start away from the truth in every free parameter (thesis_fit: 0.25, -0.37, 2.64, 1.25, 590, 0.0785, -0.35)
START = dict(b=0.32, phi0=-0.28, phi1=2.52, H=1.38, thickness=560.0, theta_d=0.1, mu=-0.27)


OMNI_RULE = (4, 8)  # nodes in cos(theta_i) (Gauss-Legendre) x phi_i (uniform) of the omnidirectional map


def stand_in_model(n_omni=0):
    """rock_dove times a global colour scale ``scale``; the ``n_omni`` rows whose w_i is exactly the
    barb-plane normal (theta_i = 0) are the omnidirectional map instead (module docstring)."""
    import math

    import jax.numpy as jnp

    from appearance_jax.bsdf import rock_dove as rd
    from appearance_jax.core.model import Model, boundary
    from appearance_jax.core.params import Real, param, params_class
    from appearance_jax.core.quadrature import gauss_legendre
    from appearance_jax.core.vec import Vec3

    @params_class
    class Params(rd.Params):
        scale: Real = param(1.0, lo=0.0, hi=1e3, lo_open=True, unit="1", doc="global colour scale of the maps")

    def _eval(p, wi, wo):
        f = rd.eval.kernel(p, wi, wo)
        if n_omni:
            rows = jnp.nonzero(wi.z == 1.0, size=n_omni)[0]  # a static count: only these rows pay the rule
            wo = Vec3(*(v[rows] for v in wo))
            nt, nphi = OMNI_RULE
            x, w = (jnp.asarray(v) for v in gauss_legendre(nt, 0.0, 1.0))  # cos theta_i
            phi = (jnp.arange(nphi) + 0.5) * (2 * math.pi / nphi)
            c, ph = jnp.repeat(x, nphi), jnp.tile(phi, nt)
            wq = jnp.repeat(w, nphi) * (2 * math.pi / nphi) * c  # dw_i <w_i, n>
            s = jnp.sqrt(1.0 - c * c)
            node = Vec3(s * jnp.cos(ph), s * jnp.sin(ph), c)
            wn = Vec3(*(jnp.broadcast_to(v[None, :], wo.x.shape + c.shape) for v in node))
            wb = Vec3(*(jnp.broadcast_to(v[:, None], wo.x.shape + c.shape) for v in wo))
            om = jnp.einsum("nkb,k->nb", rd.eval.kernel(p, wn, wb), wq)
            f = f.at[rows].set(om)
        return p.scale * f

    return Model(name="rock_dove_stand_in", kind="bsdf", Params=Params, eval=boundary(_eval, Params), sample=None,
                 pdf=None, summary="rock_dove x a colour scale (+ an omnidirectional map)", source="Huang 2022 Ch. 5",
                 reciprocal=False)


def scatterogram_table(params, noise=0.02, seed=0, quick=False, omni=False, scale=1.0):
    """A synthetic Table of rock_dove values (BRDF, RGB) on hemispherical grids of w_o (times ``scale``;
    ``omni``: plus the omnidirectional map, rows at theta_i = 0)."""
    import jax.numpy as jnp

    from appearance_jax.core.vec import Vec3
    from appearance_jax.fit.tables.table import Table

    incid = ((20.0, 0.0), (45.0, 0.0), (65.0, 0.0), (45.0, 90.0))  # (theta_i, phi_i) in degrees
    incid = incid + (((0.0, 0.0),) if omni else ())
    th_o = np.arange(5.0, 86.0, 20.0 if quick else 10.0)
    ph_o = np.arange(0.0, 360.0, 30.0 if quick else 15.0)
    T, P = np.meshgrid(th_o, ph_o, indexing="ij")
    rows = [(ti, pi, t, p) for ti, pi in incid for t, p in zip(T.ravel(), P.ravel())]
    ti, pi, to, po = (np.radians(np.array(c)) for c in zip(*rows))

    def vec(t, p):
        return Vec3(*(jnp.asarray(c) for c in (np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t))))

    model = stand_in_model(int(np.sum(ti == 0.0)))
    truth = model.Params(**{k: getattr(params, k) for k in params.__dataclass_fields__}, scale=scale)
    f = np.asarray(model.eval(truth, vec(ti, pi), vec(to, po)))
    rng = np.random.default_rng(seed)
    values = f * (1.0 + noise * rng.standard_normal(f.shape))
    sigma = np.maximum(noise * np.abs(f), 1e-3 * f.max())
    return Table(theta_i=ti, phi_i=pi, theta_o=to, phi_o=po, values=values, mask=np.ones(f.shape, bool),
                 sigma=sigma, quantity="brdf", source=f"synthetic rock_dove thesis_fit, {noise:.0%} noise")


def run(noise=0.02, seed=0, starts=3, quick=False, verbose=True, color="rgb3", omni=False, scale=None):
    """Fit the stand-in; returns (truth Params, FitResult, seconds). ``scale``: None = calibrated maps
    (rock_dove itself is fitted), else the data's colour scale (the fit frees one)."""
    from appearance_jax.bsdf import rock_dove as rd
    from appearance_jax.fit import fit

    truth = rd.PRESETS["thesis_fit"].replace(n_phi=4, color=color)
    table = scatterogram_table(truth, noise, seed, quick, omni, 1.0 if scale is None else scale)
    period = 510.0 / (2.0 * float(truth.eta_keratin))
    inits = [truth.replace(**{**START, "thickness": START["thickness"] + k * period / starts}) for k in range(starts)]
    model, fix = rd.MODEL, list(FIX)
    if omni or scale is not None:
        model = stand_in_model(int(np.sum(table.theta_i == 0.0)))
        inits = [model.Params(**{k: getattr(q, k) for k in q.__dataclass_fields__}) for q in inits]
        if scale is None:
            fix.append("scale")
    t0 = time.perf_counter()
    res = fit(model, table, init=inits, fix=fix, metric="l2", max_theta_deg=None, max_steps=200)
    dt = time.perf_counter() - t0
    if verbose:
        print(f"table: {table.values.shape[0]} directions x 3 bands, {noise:.0%} noise; {starts} start(s) in d "
              f"spaced {period / starts:.0f} nm; fit {dt:.1f} s (compilation included)")
        print(res.summary())
        print(f"{'parameter':>10s} {'truth':>10s} {'start':>10s} {'fit':>10s} {'sigma':>10s} {'(fit-truth)/sigma':>18s}")
        x = dict(zip(res.labels, np.asarray(res.x).reshape(-1, len(res.labels))[0]))
        s = dict(zip(res.labels, np.asarray(res.sigma).reshape(-1, len(res.labels))[0]))
        truth_of = dict({k: float(getattr(truth, k)) for k in FREE}, scale=scale)
        for name in FREE + (("scale",) if scale is not None else ()):
            tv = truth_of[name]
            print(f"{name:>10s} {tv:10.4f} {START.get(name, 1.0):10.4f} {x[name]:10.4f} {s[name]:10.2g} "
                  f"{(x[name] - tv) / s[name]:18.2f}")
    return truth, res, dt


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise", type=float, default=0.02)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--starts", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="coarser w_o grids (the test's case)")
    ap.add_argument("--color", default="rgb3", choices=("rgb3", "cie"), help="bands of the maps")
    ap.add_argument("--omni", action="store_true", help="add the omnidirectional map")
    ap.add_argument("--scale", type=float, default=None, help="uncalibrated maps: data x SCALE, scale fitted")
    a = ap.parse_args()
    import jax

    jax.config.update("jax_enable_x64", True)
    run(a.noise, a.seed, a.starts, a.quick, color=a.color, omni=a.omni, scale=a.scale)


if __name__ == "__main__":
    main()
