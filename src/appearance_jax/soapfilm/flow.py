"""Chemomechanical soap-film flow on a spherical bubble (Huang 2022, Ch. 3, Eqs. 3.17, 3.24-3.26).

The dimensionless thin-film system of Huang Eq. 3.17 on the unit sphere (viscosity and surfactant
diffusion dropped, as in all of the thesis' results, [T:575]):

    Du/Dt     = -(M / eta) grad Gamma + (Cr / eta)(u_air - u) + g
    DGamma/Dt = -Gamma div u
    Deta/Dt   = -eta div u

with eta the film's half thickness (units of eta_0), Gamma the surfactant concentration (units of
Gamma_0), u the in-film velocity (units of U), gravity g = (g sin theta, 0) pulling towards the
bottom (theta = pi; world +z up) and time in units of R / U (:func:`seconds_to_time`).

One :func:`step` (operator splitting, Huang Sec. 3.4):

1. advection D/Dt = 0: u by the great-circle vector scheme, Gamma by scalar semi-Lagrangian
   lookups (:mod:`.advect`, App. B half step by default); eta through BiMocq^2 maps
   (:mod:`.bimocq`) or plain lookups. With the maps, Gamma* = c* eta* where the ratio
   c = Gamma / eta is carried through the same maps: Huang Eq. 3.34 says c is constant along
   trajectories, and separate lookups of a sharp eta (maps) and a blurred Gamma (plain
   semi-Lagrangian, as the thesis does) break that invariant by O(1) where eta has fine
   structure (measured: Gamma/eta off by 0.8 after 500 steps of curl-noise air at 32 x 64);
2. the implicit surfactant solve of Huang Eq. 3.26 by conjugate gradients (:mod:`.concentration`),
   then u and eta from Huang Eqs. 3.24a, c (and Gamma from 3.24b with the new div u);
3. evaporation: eta -= ``evaporation`` dt (Huang Sec. 3.6.4).

:func:`simulate` runs steps in a ``lax.scan``. A step that fails -- the solve did not reach its
tolerance, the state is not finite, or eta <= 0 somewhere -- freezes the state; the host then
raises :class:`FlowError` naming the step (solve, NaN, eta <= 0 without evaporation: a step too
large) or returns with ``stopped`` set (evaporation to zero: the thesis ends its simulation
there, [T:898]).
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import bimocq as _bimocq
from . import concentration as _conc
from .advect import ORDERS, SCHEMES, advect_scalar, advect_velocity
from .air import Still, on_faces
from .grid import SphereGrid
from .thickness import DimensionlessNumbers
from .transport import advect_step

__all__ = ["FlowParams", "State", "Settings", "Carry", "StepInfo", "FlowError", "Result", "rest_state",
           "start", "step", "simulate", "seconds_to_time", "time_to_seconds", "REASONS"]

#: why a run stopped (``Carry.reason``)
REASONS = ("running", "eta <= 0", "solve did not converge", "non-finite state")


class FlowError(RuntimeError):
    """A simulation step failed (unconverged solve or a non-finite state)."""


class FlowParams(NamedTuple):
    """The dimensionless numbers of Huang Table 3.2 used by the flow.

    Fields:
        M: Marangoni number (>= 0; Table 3.2: 0.83).
        Cr: air drag coefficient (>= 0; 2.1).
        g: scaled gravity G R / U^2 (>= 0; 0.49).
        evaporation: thickness lost per unit dimensionless time (>= 0; the thesis gives no value).
        viscosity: 1 / Re of the viscous terms, and ``diffusivity`` D_s: both must be 0 -- the
            thesis drops them in all its results [T:575] and they are not implemented.
    """

    M: float = 0.83
    Cr: float = 2.1
    g: float = 0.49
    evaporation: float = 0.0
    viscosity: float = 0.0
    diffusivity: float = 0.0

    @classmethod
    def from_numbers(cls, numbers: DimensionlessNumbers, evaporation: float = 0.0) -> "FlowParams":
        """From :func:`~appearance_jax.soapfilm.thickness.dimensionless_numbers` (viscosity
        neglected, as in the thesis)."""
        return cls(float(numbers.M), float(numbers.Cr), float(numbers.g), float(evaporation))

    def check(self) -> "FlowParams":
        for name in ("M", "Cr", "g", "evaporation", "viscosity", "diffusivity"):
            v = getattr(self, name)
            if not np.all(np.isfinite(v)):
                raise ValueError(f"{name} = {v!r}: must be finite")
        for name in ("M", "Cr", "evaporation"):
            if np.any(np.asarray(getattr(self, name)) < 0):
                raise ValueError(f"{name} = {getattr(self, name)!r}: must be >= 0")
        for name in ("viscosity", "diffusivity"):
            if np.any(np.asarray(getattr(self, name)) != 0):
                raise NotImplementedError(
                    f"{name} = {getattr(self, name)!r}: the viscous terms and surfactant diffusion are dropped in "
                    "Huang's solver ([T:575]) and not implemented; use 0")
        return self


class State(NamedTuple):
    """The flow fields on a :class:`~appearance_jax.soapfilm.grid.SphereGrid`: ``u_theta``
    (theta faces), ``u_phi`` (phi faces), ``eta`` and ``gamma`` (cell centres)."""

    u_theta: jax.Array
    u_phi: jax.Array
    eta: jax.Array
    gamma: jax.Array


@dataclasses.dataclass(frozen=True)
class Settings:
    """Numerical choices (static).

    Args:
        order: 2 = the half step of Huang App. B (default), 1 = single step.
        scheme: "great_circle" (the thesis') or the "latlong" baseline.
        bimocq: read eta through BiMocq^2 maps (default) or advect it like Gamma.
        error_correction: BiMocq^2's back-and-forth correction (off by default).
        reinit_threshold: map distortion (rad) that triggers a re-initialisation (pi / 128).
        cg_rtol: relative residual at which the solve stops (default: 1e-6 for a float32 state,
            1e-10 for a float64 one, whatever the solve's dtype); a step whose solve ends above it
            fails.
        cg_max_iter: iteration limit of the solve.
        preconditioner: "fft" (exact inverse of the row-averaged operator, default) or "jacobi".
        conserve: rescale eta and Gamma after each step so that their integrals keep the values
            the PDE conserves (less evaporation). The thesis' update (Huang Eqs. 3.24b, c after
            semi-Lagrangian advection) is not in conservation form and drifts where the film has
            grid-scale structure -- measured over 1000 steps of 0.002 s at 32 x 64: -0.09 % under
            gravity alone, +20 % with a blowing "ball of air" and -17 % with curl-noise air
            (BiMocq^2; plain semi-Lagrangian +151 % and +78 %) -- so the default removes it with
            one global factor per field and step. ``False`` runs the thesis' scheme as printed.
            Either way the scheme's own drift is reported (``Carry.drift_log``).
        solve_dtype: precision of the solve and the updates after it: "auto" (float64 when JAX's
            x64 mode is on, else the state's), "state", or "float64" (needs x64). Why: in the pole
            rows the velocity is Gamma's azimuthal difference over sin(theta) dphi ~ dtheta^2, so
            float32 rounding of Gamma (6e-8) becomes velocity noise that grows with the grid: a
            float32 solve blew up at the south pole row in 3 steps at 512 x 1024 (float64 ran),
            and 256 x 512 is the largest float32 grid we ran without it. Advection stays in the
            state's dtype.
    """

    order: int = 2
    scheme: str = "great_circle"
    bimocq: bool = True
    error_correction: bool = False
    reinit_threshold: float = _bimocq.DEFAULT_THRESHOLD
    cg_rtol: float | None = None
    cg_max_iter: int = 2000
    preconditioner: str = "fft"
    conserve: bool = True
    solve_dtype: str = "auto"

    def __post_init__(self):
        if self.order not in ORDERS:
            raise ValueError(f"order = {self.order!r}: must be one of {ORDERS}")
        if self.scheme not in SCHEMES:
            raise ValueError(f"scheme = {self.scheme!r}: must be one of {SCHEMES}")
        if not self.reinit_threshold > 0:
            raise ValueError(f"reinit_threshold = {self.reinit_threshold!r}: must be > 0")
        if self.cg_rtol is not None and not (0 < self.cg_rtol < 1):
            raise ValueError(f"cg_rtol = {self.cg_rtol!r}: must be in (0, 1)")
        if self.solve_dtype not in ("auto", "state", "float64"):
            raise ValueError(f"solve_dtype = {self.solve_dtype!r}: must be 'auto', 'state' or 'float64'")
        if self.preconditioner not in _conc.PRECONDITIONERS:
            raise ValueError(f"preconditioner = {self.preconditioner!r}: must be one of {_conc.PRECONDITIONERS}")
        if int(self.cg_max_iter) < 1:
            raise ValueError(f"cg_max_iter = {self.cg_max_iter!r}: must be >= 1")

    def working_dtype(self, state_dtype):
        """The dtype of the solve and the updates (see ``solve_dtype``)."""
        x64 = bool(jax.config.read("jax_enable_x64"))
        if self.solve_dtype == "float64" or (self.solve_dtype == "auto" and x64):
            if not x64:
                raise ValueError("solve_dtype = 'float64' needs jax_enable_x64 (jax.config.update('jax_enable_x64', True))")
            return jnp.float64
        return jnp.dtype(state_dtype)

    def rtol(self, dtype) -> float:
        if self.cg_rtol is not None:
            return float(self.cg_rtol)
        return 1e-10 if jnp.dtype(dtype) == jnp.float64 else 1e-6


class Carry(NamedTuple):
    """What :func:`step` carries: the state, the BiMocq^2 maps (None without them), the time,
    the step count, and whether/why/when the run stopped."""

    state: State
    maps: object
    t: jax.Array
    n: jax.Array
    reason: jax.Array  # index into REASONS; 0 while running
    stop_step: jax.Array  # the step that failed (-1 while running)
    last: "StepInfo"  # diagnostics of the last step tried (the failing one after a failure)
    drift_log: jax.Array  # (2,): sum of the steps' drift_log: the scheme's own drift of the integrals


class StepInfo(NamedTuple):
    """Diagnostics of a step (in :class:`Result` per frame: the largest iteration count and
    residual over the frame's steps, the distortion and re-initialisation count at its end)."""

    cg_iterations: jax.Array
    cg_residual: jax.Array
    distortion: jax.Array
    n_reinit: jax.Array
    drift_log: jax.Array  # (2,): log of the step's relative change of the integrals of eta and Gamma
    #                       made by the scheme (before ``conserve``'s correction; evaporation excluded)


def rest_state(grid: SphereGrid, eta=1.0, gamma=None, dtype=None) -> State:
    """A film at rest: ``eta`` and ``gamma`` (numbers or cell-centred maps; ``gamma`` defaults to
    ``eta``, i.e. Gamma / eta = 1 as in Huang Eq. 3.35)."""
    dtype = jnp.result_type(float) if dtype is None else dtype
    eta = jnp.broadcast_to(jnp.asarray(eta, dtype), grid.shape)
    gamma = eta if gamma is None else jnp.broadcast_to(jnp.asarray(gamma, dtype), grid.shape)
    return State(jnp.zeros(grid.theta_shape, dtype), jnp.zeros(grid.shape, dtype), eta, gamma)


def check_state(grid: SphereGrid, state: State) -> State:
    """Eager checks of an initial state: shapes, finite values, eta > 0 and Gamma > 0."""
    for name, kind in (("u_theta", "u_theta"), ("u_phi", "u_phi"), ("eta", "centre"), ("gamma", "centre")):
        a = getattr(state, name)
        grid.check_field(name, a, kind)
        v = np.asarray(a)
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{name}: {int(np.sum(~np.isfinite(v)))} non-finite values")
    for name in ("eta", "gamma"):
        v = np.asarray(getattr(state, name))
        if np.any(v <= 0):
            raise ValueError(f"{name}: min {float(v.min()):.4g}: must be > 0 everywhere (the film's "
                             f"{'half thickness' if name == 'eta' else 'surfactant concentration'})")
    return state


def _check_dt(dt):
    try:
        v = float(dt)
    except TypeError:
        raise ValueError(f"dt = {dt!r}: must be a number") from None
    if not np.isfinite(v) or v <= 0:
        raise ValueError(f"dt = {dt!r}: must be finite and > 0 (dimensionless time; seconds_to_time converts)")
    return v


def start(grid: SphereGrid, state: State, settings: Settings = Settings(), t0=0.0) -> Carry:
    """The carry of a run starting at ``state`` (checked eagerly)."""
    check_state(grid, state)
    state = State(*(jnp.asarray(a) for a in state))
    dtype = state.eta.dtype
    maps = _bimocq.init(grid, jnp.stack([state.eta, state.gamma / state.eta])) if settings.bimocq else None
    zero_i, zero_f = jnp.zeros((), jnp.int32), jnp.zeros((), dtype)
    return Carry(state, maps, jnp.asarray(t0, dtype), zero_i, zero_i, jnp.full((), -1, jnp.int32),
                 StepInfo(zero_i, zero_f, zero_f, zero_i, jnp.zeros((2,), dtype)), jnp.zeros((2,), dtype))


def _advance(grid, params, carry: Carry, dt, air, settings: Settings, solve):
    s = carry.state
    o, sch = settings.order, settings.scheme
    maps = carry.maps
    if sch == "great_circle":  # every trajectory in one pass (one compiled copy)
        ut_s, up_s, fields, maps = advect_step(grid, s.u_theta, s.u_phi, jnp.stack([s.eta, s.gamma]), maps, dt, o)
        if maps is None:
            eta_s, gamma_s = fields
    else:  # the latlong baseline
        if maps is not None:
            maps = _bimocq.advance(grid, maps, s.u_theta, s.u_phi, dt, o)
        else:
            eta_s = advect_scalar(grid, s.eta, s.u_theta, s.u_phi, dt, o, sch)
            gamma_s = advect_scalar(grid, s.gamma, s.u_theta, s.u_phi, dt, o, sch)
        ut_s, up_s = advect_velocity(grid, s.u_theta, s.u_phi, dt, o, sch)
    if maps is not None:
        eta_s, ratio_s = _bimocq.values(grid, maps, settings.error_correction)
        gamma_s = ratio_s * eta_s
    state_dtype = s.eta.dtype
    dtype = settings.working_dtype(state_dtype)
    eta_s, gamma_s, ut_s, up_s = (a.astype(dtype) for a in (eta_s, gamma_s, ut_s, up_s))
    air_t, air_p = on_faces(grid, air, carry.t + dt, dtype)
    M, Cr, g = (jnp.asarray(v, dtype) for v in (params.M, params.Cr, params.g))
    faces = _conc.face_terms(grid, eta_s, ut_s, up_s, air_t, air_p, M, Cr, g, dt)
    b = _conc.rhs(grid, faces, dt)
    if settings.preconditioner == "fft":
        precond = _conc.row_mean_preconditioner(grid, faces, gamma_s, dt)
    else:
        inv_diag = 1.0 / _conc.diagonal(grid, faces, gamma_s, dt)
        precond = lambda r: inv_diag * r  # noqa: E731
    gamma_cg, info = _conc.cg(lambda x: _conc.apply(grid, faces, gamma_s, dt, x), b, gamma_s, precond,
                              *solve[:2])
    u_theta, u_phi = _conc.project(grid, faces, gamma_cg)
    shrink = 1.0 - dt * grid.divergence(u_theta, u_phi)
    evaporated = jnp.asarray(params.evaporation, dtype) * dt
    eta = eta_s * shrink - evaporated
    gamma = gamma_s * shrink
    # the update is not in conservation form: the integrals of eta and Gamma, which the PDE
    # conserves (less evaporation's exact loss), drift by the step's discretisation error;
    # measure that, and remove it with one global factor each when asked
    area = grid.integral(jnp.ones_like(eta))
    want = jnp.stack([grid.integral(s.eta.astype(dtype)) - evaporated * area, grid.integral(s.gamma.astype(dtype))])
    have = jnp.stack([grid.integral(eta), grid.integral(gamma)])
    change = have / want
    conserve = solve[2]  # traced: both choices share one program
    eta = jnp.where(conserve, eta / change[0], eta)
    gamma = jnp.where(conserve, gamma / change[1], gamma)
    new = State(*(a.astype(state_dtype) for a in (u_theta, u_phi, eta, gamma)))
    if maps is not None:
        ratio = gamma / eta
        inc = jnp.stack([eta - eta_s, ratio - ratio_s.astype(dtype)]).astype(state_dtype)
        maps = _bimocq.accumulate(grid, maps, inc)
        maps = _bimocq.reinit_if_distorted(grid, maps, jnp.stack([new.eta, new.gamma / new.eta]),
                                           settings.reinit_threshold)
        extra = (maps.last_distortion, maps.n_reinit)
    else:
        extra = (jnp.zeros((), state_dtype), jnp.zeros((), jnp.int32))
    info = StepInfo(info.iterations, info.residual.astype(state_dtype), *extra, jnp.log(change).astype(state_dtype))
    return new, maps, info, solve[0]


def step(grid: SphereGrid, params: FlowParams, carry: Carry, dt, air=Still(), settings: Settings = Settings(),
         solve=None):
    """One time step of ``dt`` (dimensionless). Returns ``(carry, StepInfo)``; a failing step
    leaves the state unchanged and records the reason (see :data:`REASONS`) and the step.
    ``solve = (rtol, max_iter, conserve)`` overrides the settings' (they may be traced)."""
    if solve is None:
        solve = (settings.rtol(carry.state.eta.dtype), int(settings.cg_max_iter),
                 bool(settings.conserve))
    new, maps, info, rtol = _advance(grid, params, carry, dt, air, settings, solve)
    finite = jnp.all(jnp.array([jnp.all(jnp.isfinite(a)) for a in new]))
    solved = info.cg_residual <= rtol
    wet = jnp.min(new.eta) > 0
    reason = jnp.where(~finite, 3, jnp.where(~solved, 2, jnp.where(~wet, 1, 0))).astype(jnp.int32)
    running = carry.reason == 0
    ok = running & (reason == 0)
    keep = lambda a, b: jax.tree_util.tree_map(lambda x, y: jnp.where(ok, x, y), a, b)  # noqa: E731
    out = Carry(keep(new, carry.state), keep(maps, carry.maps) if maps is not None else None,
                jnp.where(ok, carry.t + dt, carry.t), carry.n + ok.astype(jnp.int32),
                jnp.where(running, reason, carry.reason), jnp.where(running & (reason != 0), carry.n, carry.stop_step),
                jax.tree_util.tree_map(lambda x, y: jnp.where(running, x, y), info, carry.last),
                carry.drift_log + jnp.where(ok, info.drift_log, 0.0))
    return out, info


class Result(NamedTuple):
    """What :func:`simulate` returns.

    Fields:
        carry: the final :class:`Carry` (``carry.state`` the fields, ``carry.t`` the time).
        frames: the half thickness eta every ``every`` steps, ``(n_frames, n_theta, n_phi)``.
        frame_times: their dimensionless times.
        info: :class:`StepInfo` per frame (arrays of length ``n_frames``: the largest iteration
            count and residual of the frame's steps, distortion and re-initialisations at its end).
        stopped: None, or a sentence saying why and at which step the run stopped early.
    """

    carry: Carry
    frames: jax.Array
    frame_times: jax.Array
    info: StepInfo
    stopped: str | None


@functools.partial(jax.jit, static_argnames=("grid", "n_frames", "air", "settings"))
def _run(carry, params, dt, every, solve, *, grid, n_frames, air, settings):
    # ``every`` is a traced loop bound (a while loop, not a scan) and the solve's tolerance and
    # iteration limit are traced too: runs of any length with the same number of frames share
    # one compiled program
    def inner(_, c):
        c, it_max, res_max = c
        c, info = step(grid, params, c, dt, air, settings, solve)
        return c, jnp.maximum(it_max, info.cg_iterations), jnp.maximum(res_max, info.cg_residual)

    def outer(c, _):
        zero_i, zero_f = jnp.zeros((), jnp.int32), jnp.zeros((), c.t.dtype)
        c, it_max, res_max = jax.lax.fori_loop(0, every, inner, (c, zero_i, zero_f))
        info = StepInfo(it_max, res_max, c.last.distortion, c.last.n_reinit, c.drift_log)
        return c, (c.state.eta, c.t, info)

    carry, (frames, times, info) = jax.lax.scan(outer, carry, None, length=n_frames)
    return carry, frames, times, info


def simulate(grid: SphereGrid, params: FlowParams, state: State, dt, n_steps: int, *, air=Still(),
             settings: Settings = Settings(), every: int | None = None, carry: Carry | None = None) -> Result:
    """Run ``n_steps`` steps of ``dt`` (dimensionless) from ``state`` (or continue ``carry``).

    Args:
        grid: the :class:`~appearance_jax.soapfilm.grid.SphereGrid`.
        params: :class:`FlowParams` (e.g. ``FlowParams.from_numbers(dimensionless_numbers(...))``).
        state: the initial :class:`State` (eta > 0, Gamma > 0); ignored when ``carry`` is given.
        dt: time step, dimensionless (``seconds_to_time(0.002, R)`` is the thesis' 0.002 s).
        n_steps: number of steps (a multiple of ``every``).
        air: ``air(p, t) -> Vec3`` (hashable; :mod:`~appearance_jax.soapfilm.air`).
        settings: :class:`Settings`.
        every: keep eta every ``every`` steps (default: only the last).

    Raises:
        FlowError: a step's solve did not converge or its state was not finite (the message
            names the step and the residual); the run is not continued.
    """
    params = FlowParams(*params).check()
    dt = _check_dt(dt)
    n_steps = int(n_steps)
    if n_steps < 1:
        raise ValueError(f"n_steps = {n_steps}: must be >= 1")
    every = n_steps if every is None else int(every)
    if every < 1 or n_steps % every:
        raise ValueError(f"every = {every}: must divide n_steps = {n_steps}")
    if carry is None:
        carry = start(grid, state, settings)
    dtype = carry.state.eta.dtype
    if jnp.dtype(settings.working_dtype(dtype)) == jnp.float32 and grid.n_theta > 256:
        warnings.warn(f"a float32 solve on a {grid.n_theta}x{grid.n_phi} grid: float32 rounding in the pole rows "
                      "grows with the grid and a 512 x 1024 run blew up in 3 steps; enable JAX's x64 mode for a "
                      "float64 solve (Settings.solve_dtype)", RuntimeWarning, stacklevel=2)
    wd = settings.working_dtype(dtype)
    solve = (jnp.asarray(settings.rtol(dtype), wd), jnp.asarray(int(settings.cg_max_iter), jnp.int32),
             jnp.asarray(bool(settings.conserve)))
    static = dataclasses.replace(settings, cg_rtol=None, cg_max_iter=1, conserve=True)  # traced above
    carry, frames, times, info = _run(carry, params, jnp.asarray(dt, carry.state.eta.dtype),
                                      jnp.asarray(every, jnp.int32), solve, grid=grid, n_frames=n_steps // every,
                                      air=air, settings=static)
    reason = int(carry.reason)
    stopped = None
    if reason:
        k = int(carry.stop_step)
        where = f"step {k} (t = {float(carry.t):.6g})"
        if reason == 1 and params.evaporation > 0:
            stopped = f"the film evaporated (eta <= 0 somewhere) at {where}; the state is the last one before it"
        elif reason == 1:  # no evaporation: the explicit update eta* (1 - dt div u) crossed zero
            raise FlowError(f"the thickness reached 0 without evaporation at {where}: dt * div u >= 1 somewhere; "
                            "reduce dt (the state was frozen before it)")
        else:
            last = carry.last
            raise FlowError(f"{REASONS[reason]} at {where}: cg residual {float(last.cg_residual):.3g} after "
                            f"{int(last.cg_iterations)} iterations (rtol "
                            f"{settings.rtol(carry.state.eta.dtype):.3g}); the state was "
                            "frozen before it")
    return Result(carry, frames, times, info, stopped)


def seconds_to_time(seconds, R=0.05, U=1.0):
    """Dimensionless time t' = t U / R (0.002 s on a 5 cm bubble = 0.04)."""
    return seconds * U / R


def time_to_seconds(t, R=0.05, U=1.0):
    """Seconds from dimensionless time: t R / U."""
    return t * R / U
