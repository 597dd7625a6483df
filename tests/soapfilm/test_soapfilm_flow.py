"""Soap-film flow on the sphere (Huang 2022, Ch. 3): the implicit surfactant system, the flow against
closed forms it was not written from, and its input checks.

References (none computed by the code under test):
* App. C's stencil written out by hand (with the A_down misprint fixed by symmetry, spec §0.4.4);
* the gravity equilibrium eta ~ exp(-(g/M) cos theta) (Huang Eq. 3.36), normalised by the volume
  the run actually holds (spec §7.8);
* the linearised system (derived here, not in the thesis): with g = 0 a Y_l perturbation of Gamma
  obeys Gamma'' + Cr Gamma' = M lap Gamma, i.e. it oscillates at omega = sqrt(M l (l + 1) - Cr^2/4)
  and decays at Cr / 2;
* Huang Eq. 3.34: Gamma / eta is constant along trajectories.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.soapfilm import air, bimocq, concentration, flow
from appearance_jax.core.vec import cross
from appearance_jax.soapfilm.advect import advect_scalar
from appearance_jax.soapfilm.grid import SphereGrid, components, point
from appearance_jax.soapfilm.thickness import dimensionless_numbers


def _P2(grid):
    th, _ = grid.centres()
    return 0.5 * (3 * np.cos(th) ** 2 - 1)


# -- SS-4: the linear system -------------------------------------------------------------------
def _random_faces(grid, rng, dt=0.04, M=0.83, Cr=2.1, g=0.49):
    eta = jnp.asarray(rng.uniform(0.3, 2.0, grid.shape))
    gamma = jnp.asarray(rng.uniform(0.3, 2.0, grid.shape))
    ut = jnp.asarray(rng.normal(size=grid.theta_shape))
    up = jnp.asarray(rng.normal(size=grid.shape))
    z_t, z_p = jnp.zeros(grid.theta_shape), jnp.zeros(grid.shape)
    return concentration.face_terms(grid, eta, ut, up, z_t, z_p, M, Cr, g, dt), eta, gamma


def _dense(grid, faces, gamma, dt):
    n = grid.n_theta * grid.n_phi
    cols = jax.vmap(lambda e: concentration.apply(grid, faces, gamma, dt, e.reshape(grid.shape)).ravel())(jnp.eye(n))
    return np.asarray(cols).T


def test_system_is_symmetric_positive_definite_ss4():
    grid = SphereGrid(8, 16)  # the grid of the stencil and CG tests: _dense compiled once
    faces, _, gamma = _random_faces(grid, np.random.default_rng(0))
    A = _dense(grid, faces, gamma, 0.04)
    assert np.max(np.abs(A - A.T)) <= 1e-13 * np.max(np.abs(A))
    x = np.random.default_rng(1).normal(size=(20, A.shape[0]))
    assert np.all(np.einsum("ki,ij,kj->k", x, A, x) > 0)
    assert np.linalg.eigvalsh(A).min() > 0
    np.testing.assert_allclose(np.diag(A), np.asarray(concentration.diagonal(grid, faces, gamma, 0.04)).ravel(),
                               rtol=1e-13)


def test_stencil_matches_appendix_c_by_hand():
    """dtheta = dphi = ds: the row of A for an interior cell is Huang App. C's five entries."""
    grid = SphereGrid(8, 16)
    rng = np.random.default_rng(2)
    dt, M, Cr = 0.05, 0.7, 1.3
    faces, eta, gamma = _random_faces(grid, rng, dt, M, Cr)
    A = _dense(grid, faces, gamma, dt)
    ds = grid.dtheta
    assert math.isclose(ds, grid.dphi)
    e, G = np.asarray(eta), np.asarray(gamma)
    i, j = 3, 5
    th = (i + 0.5) * ds
    st = math.sin(th)

    def face(a, b):  # eta* on a face: mean of the two cells
        return 0.5 * (a + b) + Cr * dt

    left = face(e[i, j - 1], e[i, j])
    right = face(e[i, j], e[i, j + 1])
    up = face(e[i - 1, j], e[i, j])
    down = face(e[i, j], e[i + 1, j])
    c = M * dt / ds**2
    mid = st / (dt * G[i, j]) + c * (1 / st / left + 1 / st / right + math.sin(th + ds / 2) / down
                                     + math.sin(th - ds / 2) / up)
    row = A[i * grid.n_phi + j].reshape(grid.shape)
    assert math.isclose(row[i, j], mid, rel_tol=1e-12)
    assert math.isclose(row[i, j - 1], -c / st / left, rel_tol=1e-12)
    assert math.isclose(row[i, j + 1], -c / st / right, rel_tol=1e-12)
    assert math.isclose(row[i - 1, j], -math.sin(th - ds / 2) * c / up, rel_tol=1e-12)
    # A_down, the misprinted entry: sin(theta + ds/2) and the face below
    assert math.isclose(row[i + 1, j], -math.sin(th + ds / 2) * c / down, rel_tol=1e-12)
    assert np.count_nonzero(np.abs(row) > 0) == 5
    # no coupling across a pole: row 0 has no neighbour above
    assert np.count_nonzero(np.abs(A[0 * grid.n_phi + 3]) > 0) == 4


def test_preconditioner_is_the_exact_inverse_for_row_constant_coefficients():
    grid = SphereGrid(8, 16)
    th, _ = grid.centres()
    eta = jnp.asarray(1.0 + 0.5 * np.cos(th))  # varies with theta only
    gamma = jnp.asarray(1.0 + 0.3 * np.cos(th) ** 2)
    z_t, z_p = jnp.zeros(grid.theta_shape), jnp.zeros(grid.shape)
    faces = concentration.face_terms(grid, eta, z_t, z_p, z_t, z_p, 0.83, 2.1, 0.49, 0.04)
    P = concentration.row_mean_preconditioner(grid, faces, gamma, 0.04)
    r = jnp.asarray(np.random.default_rng(3).normal(size=grid.shape))
    np.testing.assert_allclose(concentration.apply(grid, faces, gamma, 0.04, P(r)), r, atol=1e-10)


def test_cg_solves_the_system():
    grid = SphereGrid(8, 16)
    faces, eta, gamma = _random_faces(grid, np.random.default_rng(4))
    A = _dense(grid, faces, gamma, 0.04)
    b = concentration.rhs(grid, faces, 0.04)
    for P in (concentration.row_mean_preconditioner(grid, faces, gamma, 0.04),
              lambda r: r / concentration.diagonal(grid, faces, gamma, 0.04)):
        x, info = concentration.cg(lambda v: concentration.apply(grid, faces, gamma, 0.04, v), b, gamma, P, 1e-12, 500)
        np.testing.assert_allclose(np.asarray(x).ravel(), np.linalg.solve(A, np.asarray(b).ravel()), rtol=1e-9)
        assert 0 < int(info.iterations) < 500 and float(info.residual) <= 1e-12


# -- equilibrium under gravity (Huang Eq. 3.36, SS-2) ------------------------------------------------
GRID = SphereGrid(32, 64)
# _SHARED_RUNS: flow.simulate compiles one program per (grid, static settings, state dtype, number
# of frames), ~15-20 s each on CPU. The runs of this file use GRID with the default settings (one
# program in float64, one in float32) wherever the check does not depend on the grid, including the
# short failure runs below.


def _relax(M, Cr, g, n_steps, dt=0.2, settings=flow.Settings()):
    # the discrete steady state does not depend on dt (u = 0 there), so a long step reaches it
    # sooner: 60 time units (300 steps) for the thin top of the g/M = 2.364 film, less for flatter films
    return flow.simulate(GRID, flow.FlowParams(M, Cr, g), flow.rest_state(GRID), dt, n_steps, settings=settings)


def _volume_normalised(profile_fn):
    th, _ = GRID.centres()
    ref = profile_fn(th)
    return ref * 4 * np.pi / float(np.sum(ref * GRID.cell_areas()))


# ~2x the steps after which each profile stops changing (max relative error after 50 / 100 / 150 /
# 300 steps: g/M 0.590 4.4e-4 / 4.2e-4 / 4.2e-4 / 4.2e-4; 0.473 1.1e-2 / 1.6e-4 / 2.9e-4 / 2.9e-4;
# 2.364 1.8 / 0.72 / 0.45 / 0.028). 2.364 is `slow`: the default cases' code path, a steeper profile.
@pytest.mark.parametrize("M, g, vol_tol, top_tol, n_steps", [
    (0.83, 0.49, 1e-2, 1e-2, 100),  # Huang Table 3.2: g/M = 0.590
    # SS-2: R = 0.02 m, 0.10 m (g/M 0.473, 2.364)
    (0.4146, 0.196, 1e-2, 1e-2, 150), pytest.param(0.4146, 0.98, 5e-2, 4e-2, 300, marks=pytest.mark.slow)])
def test_gravity_relaxes_to_the_equilibrium_profile(M, g, vol_tol, top_tol, n_steps):
    r = _relax(M, 2.1, g, n_steps)
    assert r.stopped is None
    s = r.carry.state
    a = g / M
    ref = _volume_normalised(lambda th: np.exp(-a * np.cos(th)))
    eta = np.asarray(s.eta)
    vol = float(GRID.integral(s.eta)) / (4 * np.pi)
    # against the profile holding the same volume: O(h^2) discretisation (h = 0.098); the thin top
    # of the g/M = 2.364 film drains slowly (its rate scales with eta) and is 1.3e-3 short after
    # 60 time units, hence the absolute term
    np.testing.assert_allclose(eta / vol, ref, rtol=1.5e-2, atol=2e-3)
    assert np.max(np.abs(eta - eta.mean(axis=1, keepdims=True))) < 1e-6  # bands stay horizontal
    # top / bottom ratio of the cell rows next to the poles
    th0 = GRID.theta_centres()[0]
    assert math.isclose(eta[0].mean() / eta[-1].mean(), math.exp(-2 * a * math.cos(th0)), rel_tol=top_tol)
    assert float(jnp.max(jnp.abs(s.u_theta))) < 1e-3  # at rest
    # volume drift while relaxing (measured +0.3 %, +0.2 %, +3.0 %: the strongly stratified
    # film's steep top makes the non-conservative update drift most)
    assert abs(vol - 1) < vol_tol


def test_same_g_over_M_same_equilibrium():
    """Fig. 3.12: equal g / M (equal R / Gamma_0) gives the same profile through other dynamics."""
    # Table 3.2's bubble and one twice as large with twice the surfactant (M 0.83 / 1.66, Cr 2.10 /
    # 2.97, g 0.49 / 0.98; g/M = 0.590 settles fast): the profiles differ by 5.4e-3 / 2.7e-5 /
    # 1.7e-6 / 1.7e-6 after 25 / 50 / 75 / 150 steps (measured), so 100 steps
    a = dimensionless_numbers(R=0.05)
    b = dimensionless_numbers(R=0.10, Gamma0=2 * 1.669e-7)
    assert math.isclose(float(a.g_over_M), float(b.g_over_M), rel_tol=1e-12)
    assert not math.isclose(float(a.Cr), float(b.Cr), rel_tol=1e-2)
    ea, eb = (_relax(float(n.M), float(n.Cr), float(n.g), 100).carry.state.eta for n in (a, b))
    # each normalised by its own volume (the two runs drift differently on the way)
    ea, eb = (np.asarray(e) / float(GRID.integral(e)) for e in (ea, eb))
    np.testing.assert_allclose(ea, eb, rtol=5e-3)


# -- Huang Eq. 3.34 and conservation ------------------------------------------------------------------
def _stirred(grid, amplitude=1.0):
    """A film stirred by an initial curl-noise velocity, with a non-uniform Gamma = eta."""
    from appearance_jax.soapfilm.air import noise, on_faces

    ut, up = on_faces(grid, air.CurlNoise(seed=3, amplitude=amplitude), 0.0, jnp.float64)
    th, ph = (jnp.asarray(a) for a in grid.centres())
    eta = 1.0 + 0.3 * noise(point(th, ph), seed=4, frequency=4.0)
    return flow.State(ut, up, eta, eta)


@pytest.mark.parametrize("bimocq_on", [True, pytest.param(False, marks=pytest.mark.slow)])
def test_gamma_over_eta_stays_one(bimocq_on):
    """Huang Eq. 3.34 from Gamma = eta (not uniform) in a stirred film, 100 steps: the film moves
    early (max |eta - eta0| 0.80 / 0.85 / 0.86 after 50 / 100 / 500 steps) and Gamma / eta stayed
    exactly 1 at every 50th step up to 500 (both settings, measured)."""
    st = flow.Settings(bimocq=bimocq_on)
    s0 = _stirred(GRID)
    assert float(jnp.min(s0.eta)) > 0.2
    r = flow.simulate(GRID, flow.FlowParams(), s0, 0.04, 100, settings=st)
    s = r.carry.state
    assert float(jnp.max(jnp.abs(s.eta - s0.eta))) > 0.05  # the film did move
    np.testing.assert_allclose(np.asarray(s.gamma / s.eta), 1.0, atol=1e-3)


def test_volume_drift_is_bounded_and_reported():
    """The PDE conserves the integrals of eta and Gamma; the thesis' non-conservative update does so
    only up to discretisation error. Measured drift per 1000 steps (dt = 0.04 = 0.002 s, 32 x 64,
    gravity only): -0.094 % with BiMocq^2; the bound is twice that. ``conserve`` (the default)
    removes it and reports what it removed. The drift is the transient of the first steps from
    rest (measured -0.0886 % after 100 steps, -0.0942 % after 150, -0.0946 % after 250, -0.0952 %
    after 500, -0.0936 % after 1000), so 150 steps test the same bound at a seventh of the run time."""
    runs = {c: flow.simulate(GRID, flow.FlowParams(), flow.rest_state(GRID), 0.04, 150,
                             settings=flow.Settings(conserve=c)) for c in (False, True)}
    raw = runs[False].carry
    for f in (raw.state.eta, raw.state.gamma):
        drift = float(GRID.integral(f)) / (4 * np.pi) - 1
        assert 1e-5 < abs(drift) < 2e-3
    # the reported drift is the drift
    np.testing.assert_allclose(np.expm1(np.asarray(raw.drift_log)), float(GRID.integral(raw.state.eta)) / (4 * np.pi) - 1,
                               rtol=1e-6)
    fixed = runs[True].carry
    for f in (fixed.state.eta, fixed.state.gamma):
        assert abs(float(GRID.integral(f)) / (4 * np.pi) - 1) < 1e-12
    np.testing.assert_allclose(np.asarray(fixed.drift_log), np.asarray(raw.drift_log), rtol=0.05)


# -- the linearised system ------------------------------------------------------------------------
# Cr = 0 is `slow`: the same program and checks as Cr = 1, which also sees the drag's decay rate
@pytest.mark.parametrize("Cr", [pytest.param(0.0, marks=pytest.mark.slow), 1.0])
def test_small_oscillation_period_and_decay(Cr):
    # On GRID, sampled by carrying the run on frame after frame: every call is the default
    # program of the runs above (_SHARED_RUNS), where `every` would compile one of its own (the
    # frames of `every` are run by the README's flow example, tests/test_readme.py). Measured
    # half-period errors 0.3 % / 1.3 % (Cr = 0 / 1; 0.1 % / 1.1 % at 64 x 128, where this test
    # ran before: the time step, not the grid, dominates at Cr = 1) against the 2 % asserted;
    # decay rates within 3 % / 1 % of the expected.
    grid = GRID
    M, dt, eps = 0.83, 0.02, 1e-3
    P2 = _P2(grid)
    omega = math.sqrt(M * 6 - Cr**2 / 4)
    n_frames = 96
    every = math.ceil(1.6 * 2 * math.pi / omega / dt / n_frames)
    carry, frames, times = flow.start(grid, flow.rest_state(grid, 1.0, 1 + eps * P2)), [], []
    for _ in range(n_frames):
        carry = flow.simulate(grid, flow.FlowParams(M, Cr, 0.0), None, dt, every, carry=carry).carry
        frames.append(np.asarray(carry.state.eta))
        times.append(float(carry.t))
    np.testing.assert_allclose(times, dt * every * np.arange(1, n_frames + 1), rtol=1e-12)
    A = grid.cell_areas()
    # Gamma / eta = 1 + eps P2 is carried with the fluid, which barely moves: eta = Gamma / (1 + eps P2)
    # oscillates about 1 - eps P2, so eta - 1 + eps P2 is the oscillating part
    c = np.einsum("kij,ij->k", (np.stack(frames) - 1) * P2, A) / np.sum(P2 * P2 * A) + eps
    t = np.asarray(times)
    z = np.nonzero(np.sign(c[1:]) != np.sign(c[:-1]))[0]
    tz = t[z] - c[z] * (t[z + 1] - t[z]) / (c[z + 1] - c[z])
    assert len(tz) >= 3
    half = np.diff(tz)
    np.testing.assert_allclose(half, math.pi / omega, rtol=0.02)
    # decay: |extremum| ratio over a half period = exp(-(Cr/2 + numerical) T/2); backward Euler
    # adds omega^2 dt / 2 to the decay rate
    ext = [np.max(np.abs(c[z[k] + 1:z[k + 1] + 1])) for k in range(len(z) - 1)]
    rate = -np.log(ext[1] / ext[0]) / (math.pi / omega)
    expected = Cr / 2 + omega**2 * dt / 2
    assert abs(rate - expected) < 0.25 * expected + 0.02


# -- SS-7: thin regions rise ------------------------------------------------------------------------
def test_thin_patch_rises_ss7():
    grid = GRID
    th, ph = grid.centres()
    p = point(jnp.asarray(th), jnp.asarray(ph))
    centre = point(jnp.asarray(0.75 * np.pi), jnp.asarray(0.0))
    d2 = np.asarray((p.x - centre.x) ** 2 + (p.y - centre.y) ** 2 + (p.z - centre.z) ** 2)
    bump = np.exp(-d2 / 0.05)
    eta0 = 1.0 - 0.5 * bump
    r1 = flow.simulate(grid, flow.FlowParams(), flow.rest_state(grid, eta0), 0.04, 50)
    r2 = flow.simulate(grid, flow.FlowParams(), None, 0.04, 50, carry=r1.carry)  # continues: same program
    assert math.isclose(float(r2.carry.t), 4.0)
    frames = np.concatenate([np.asarray(r1.frames), np.asarray(r2.frames)])
    deficit = np.maximum(1.0 - frames, 0) * grid.cell_areas()

    def centroid(w):
        return float(np.sum(w * th) / np.sum(w))

    start = float(np.sum(bump * grid.cell_areas() * th) / np.sum(bump * grid.cell_areas()))
    # the thin patch's centroid moves up (theta decreases) frame after frame
    assert centroid(deficit[0]) < start - 0.02
    assert centroid(deficit[1]) < centroid(deficit[0])


# -- BiMocq^2 keeps detail that repeated lookups blur ---------------------------------------------------
def test_bimocq_beats_plain_semi_lagrangian_on_a_rotated_bell():
    """Williamson et al. test 1 style: a cosine bell carried around the sphere over the poles by a
    fixed rigid rotation; the maps read the initial field once per step, plain SL re-interpolates."""
    grid = SphereGrid(32, 64)
    th, ph = (jnp.asarray(a) for a in grid.centres())
    p = point(th, ph)
    bell_c = point(jnp.asarray(0.5 * np.pi), jnp.asarray(0.0))
    ang = jnp.arccos(jnp.clip(p.x * bell_c.x + p.y * bell_c.y + p.z * bell_c.z, -1, 1))
    f0 = jnp.where(ang < 1 / 3, 0.5 * (1 + jnp.cos(3 * np.pi * ang)), 0.0) + 1.0
    axis = point(jnp.asarray(0.5 * np.pi), jnp.asarray(0.5 * np.pi))  # +y: the bell passes over the poles

    def rot(pt):
        th_, ph_ = (jnp.asarray(a) for a in pt)
        return components(cross(axis, point(th_, ph_)), th_, ph_)

    ut = rot(grid.u_theta_points())[0]
    up = rot(grid.u_phi_points())[1]
    n, dt = 100, 2 * np.pi / 100

    def sl(f):
        return jax.lax.fori_loop(0, n, lambda i, f: advect_scalar(grid, f, ut, up, dt), f)

    def maps(f):
        m0 = bimocq.init(grid, f)

        def body(i, m):
            m = bimocq.advance(grid, m, ut, up, dt)
            v = bimocq.thickness(grid, m)
            return bimocq.reinit_if_distorted(grid, m, v)

        m = jax.lax.fori_loop(0, n, body, m0)
        return bimocq.thickness(grid, m), m.n_reinit

    e_sl = float(jnp.sqrt(grid.integral((jax.jit(sl)(f0) - f0) ** 2) / grid.integral((f0 - 1) ** 2)))
    fm, n_re = jax.jit(maps)(f0)
    e_m = float(jnp.sqrt(grid.integral((fm - f0) ** 2) / grid.integral((f0 - 1) ** 2)))
    assert e_m < 0.7 * e_sl, (e_m, e_sl, int(n_re))


# -- failures and bad input --------------------------------------------------------------------------
def test_evaporation_stops_cleanly_and_reports_the_step():
    grid = GRID  # (the grid of the runs above: their compiled program, see _SHARED_RUNS)
    r = flow.simulate(grid, flow.FlowParams(evaporation=2.0), flow.rest_state(grid, 0.5), 0.1, 10)
    assert r.stopped is not None and "evaporated" in r.stopped and "step 2" in r.stopped
    assert int(r.carry.stop_step) == 2 and int(r.carry.n) == 2
    assert float(jnp.min(r.carry.state.eta)) > 0  # the last state before the film broke


def test_thickness_reaching_zero_without_evaporation_raises():
    grid = GRID  # (the grid of the runs above: their compiled program, see _SHARED_RUNS)
    carry = flow.start(grid, flow.rest_state(grid))
    # a strongly converging-diverging velocity and a huge step: dt div u >= 1 somewhere
    ut = carry.state.u_theta.at[3].set(50.0)
    carry = carry._replace(state=carry.state._replace(u_theta=ut))
    with pytest.raises(flow.FlowError, match="thickness reached 0 without evaporation at step 0"):
        flow.simulate(grid, flow.FlowParams(), None, 0.1, 5, carry=carry)


def test_unconverged_solve_raises():
    grid = GRID  # (the grid of the runs above: their compiled program, see _SHARED_RUNS)
    st = flow.Settings(cg_max_iter=1, cg_rtol=1e-300)  # unreachable
    with pytest.raises(flow.FlowError, match="did not converge at step 0"):
        flow.simulate(grid, flow.FlowParams(), flow.rest_state(grid), 0.04, 4, settings=st)


def test_non_finite_state_raises():
    grid = GRID  # (the grid of the runs above: their compiled program, see _SHARED_RUNS)
    carry = flow.start(grid, flow.rest_state(grid))
    bad = carry.state.u_phi.at[3, 5].set(jnp.nan)  # past the eager checks of start()
    carry = carry._replace(state=carry.state._replace(u_phi=bad))
    with pytest.raises(flow.FlowError, match="non-finite state at step 0"):
        flow.simulate(grid, flow.FlowParams(), None, 0.1, 5, carry=carry)


@pytest.mark.parametrize("kw, match", [
    (dict(dt=0.0), "dt = 0.0"), (dict(dt=float("nan")), "dt = nan"), (dict(dt=-1.0), "dt = -1.0"),
    (dict(eta=0.0), "eta: min 0"), (dict(gamma=-1.0), "gamma: min -1"),
    (dict(params=flow.FlowParams(M=-1.0)), "M = -1.0"), (dict(params=flow.FlowParams(Cr=-0.5)), "Cr = -0.5"),
    (dict(shape=(8, 15)), r"eta: shape \(8, 15\), expected \(8, 16\)"),
])
def test_bad_input_is_named(kw, match):
    grid = SphereGrid(8, 16)
    state = flow.rest_state(grid, kw.get("eta", 1.0), kw.get("gamma"))
    if "shape" in kw:
        state = state._replace(eta=jnp.ones(kw["shape"]))
    with pytest.raises(ValueError, match=match):
        flow.simulate(grid, kw.get("params", flow.FlowParams()), state, kw.get("dt", 0.1), 2)


def test_viscosity_and_diffusion_are_not_implemented():
    grid = SphereGrid(8, 16)
    for kw in (dict(viscosity=1.0 / 5.6e4), dict(diffusivity=1e-3)):
        with pytest.raises(NotImplementedError, match=next(iter(kw))):
            flow.simulate(grid, flow.FlowParams(**kw), flow.rest_state(grid), 0.1, 1)


def test_time_units():
    assert math.isclose(flow.seconds_to_time(0.002, R=0.05), 0.04)
    assert math.isclose(flow.time_to_seconds(0.04, R=0.05), 0.002)


def test_float32_runs():
    # 100 steps (10 time units): max relative difference from the profile 1.2e-3 / 4.4e-4 / 4.2e-4
    # after 50 / 100 / 300 steps (measured)
    r = flow.simulate(GRID, flow.FlowParams(), flow.rest_state(GRID, dtype=jnp.float32), 0.1, 100)
    eta = np.asarray(r.carry.state.eta)
    assert eta.dtype == np.float32 and np.all(np.isfinite(eta))
    ref = _volume_normalised(lambda th: np.exp(-0.49 / 0.83 * np.cos(th)))
    np.testing.assert_allclose(eta, ref, rtol=2e-2)


def test_fused_transport_equals_the_separate_advection_calls():
    """transport.advect_step traces all point sets in one pass; it must equal advect_velocity,
    advect_scalar and bimocq.advance called one by one."""
    from appearance_jax.soapfilm.advect import advect_velocity
    from appearance_jax.soapfilm.transport import advect_step

    grid = SphereGrid(8, 16)
    rng = np.random.default_rng(5)
    ut = jnp.asarray(rng.normal(size=grid.theta_shape)) * 0.5
    up = jnp.asarray(rng.normal(size=grid.shape)) * 0.5
    f = jnp.asarray(rng.uniform(0.5, 1.5, size=(2,) + grid.shape))
    order = 2  # order 1 is the first half of the same code path
    # a non-identity forward map Y: the centres turned by 0.05 rad about a tilted axis, in numpy (an
    # advance() inside `both` compiled two more copies of the trajectory code)
    m = bimocq.init(grid, f)
    axis, ang = np.array([0.36, 0.48, 0.8]), 0.05
    p = np.stack([np.asarray(c) for c in m.forward])
    turned = (p * math.cos(ang) + np.cross(axis, p, axisa=0, axisb=0, axisc=0) * math.sin(ang)
              + axis[:, None, None] * np.einsum("k,kij->ij", axis, p) * (1 - math.cos(ang)))
    m = m._replace(forward=type(m.forward)(*(jnp.asarray(c) for c in turned)))

    @jax.jit
    def both(ut, up, f, m):
        fused = advect_step(grid, ut, up, f, None, 0.07, order)[:3]
        # the fields one by one: vmap traces the departure points (field-independent) once
        separate = (*advect_velocity(grid, ut, up, 0.07, order),
                    jax.vmap(lambda fk: advect_scalar(grid, fk, ut, up, 0.07, order))(f))
        m1 = advect_step(grid, ut, up, None, m, 0.07, order)[3]
        m2 = bimocq.advance(grid, m, ut, up, 0.07, order)
        return fused, separate, [*m1.backward, *m1.forward], [*m2.backward, *m2.forward]

    assert float(np.abs(turned - p).max()) > 0.01  # Y is not the identity
    fused, separate, m1, m2 = both(ut, up, f, m)
    for a, b in zip([*fused, *m1], [*separate, *m2]):
        np.testing.assert_allclose(a, b, atol=1e-13)


def test_map_distortion_is_measured_in_grid_cells():
    """Near a pole a small angle on the sphere spans many cells of a row; the re-initialisation
    test must see the cells (measured on the sphere, a stopped blowing scene went unstable)."""
    grid = SphereGrid(32, 64)
    m = bimocq.init(grid, jnp.ones(grid.shape))
    th, ph = (jnp.asarray(a) for a in grid.centres())
    shift = jnp.where(jnp.arange(grid.n_theta)[:, None] == 0, 3 * grid.dphi, 0.0)  # 3 cells along row 0
    moved = point(th, ph + shift)
    on_sphere = float(jnp.max(jnp.arccos(jnp.clip(moved.x * m.forward.x + moved.y * m.forward.y
                                                     + moved.z * m.forward.z, -1, 1))))
    assert on_sphere < bimocq.DEFAULT_THRESHOLD  # ... a small angle on the sphere
    d = float(bimocq.distortion(grid, m._replace(forward=moved)))
    assert math.isclose(d, 3 * grid.dtheta, rel_tol=0.05)  # ... but three cells
    assert d > bimocq.DEFAULT_THRESHOLD


@pytest.mark.slow
def test_blowing_then_stopping_stays_stable_at_the_poles():
    from appearance_jax.soapfilm import scenes

    grid = SphereGrid(64, 128)
    a = scenes.air_field("blow", blow_start=0.25, blow_stop=0.75)
    carry, worst = None, 0.0
    for _ in range(11):  # 0.1 s chunks, the same program
        carry = flow.simulate(grid, flow.FlowParams(), flow.rest_state(grid), 0.04, 50, air=a, carry=carry).carry
        div = np.abs(np.asarray(grid.divergence(carry.state.u_theta, carry.state.u_phi)))
        worst = max(worst, div[[0, -1]].max())
    # measured: max |div u| in the pole rows 0.19 (9.9 with the distortion measured on the sphere)
    assert worst < 1.0


def test_solve_precision_setting():
    """float32 state, float64 solve (x64 is on in the tests): see Settings.solve_dtype."""
    assert flow.Settings().working_dtype(jnp.float32) == jnp.float64
    assert flow.Settings(solve_dtype="state").working_dtype(jnp.float32) == jnp.float32
    with pytest.raises(ValueError, match="solve_dtype = 'half'"):
        flow.Settings(solve_dtype="half")
    grid = GRID  # (the grid of the runs above: their compiled program, see _SHARED_RUNS)
    r = flow.simulate(grid, flow.FlowParams(), flow.rest_state(grid, dtype=jnp.float32), 0.1, 3)
    s = r.carry.state
    assert all(a.dtype == jnp.float32 for a in s)  # the state keeps its dtype
    assert float(r.carry.last.cg_residual) <= 1e-6  # the float32 state's tolerance


@pytest.mark.slow
def test_forward_mode_derivative_through_steps_matches_finite_differences():
    """d(mean top-row thickness after 20 steps)/dM by jax.jvp through step() (CG while loop
    included) against central differences (measured: agree to 2e-9 relative)."""
    grid = SphereGrid(8, 16)
    c0 = flow.start(grid, flow.rest_state(grid))

    @jax.jit
    def top(M):
        p = flow.FlowParams(M=M, Cr=2.1, g=0.49)
        c = jax.lax.fori_loop(0, 20, lambda i, c: flow.step(grid, p, c, 0.1)[0], c0)
        return c.state.eta[0].mean()

    _, d = jax.jvp(top, (0.83,), (1.0,))
    h = 1e-5
    fd = (top(0.83 + h) - top(0.83 - h)) / (2 * h)
    assert abs(float(d)) > 0.01
    np.testing.assert_allclose(float(d), float(fd), rtol=1e-6)
