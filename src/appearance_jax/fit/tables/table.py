"""A measurement table: directions, values per band, a validity mask and the measured quantity.

:class:`Table` is what every reader returns (CSV gonioreflectometer tables,
:mod:`~appearance_jax.fit.tables.merl` ``.binary`` files, :mod:`~appearance_jax.fit.tables.proxy` Neural-BRDF
proxies) and what the fitters consume. Angles are stored in **radians** (degrees only in files
and on the command line); values keep the quantity they were measured in and are converted
to a BRDF in 1/sr explicitly by :meth:`Table.brdf`:

=========================  ====================  ===========================================
quantity                   stored value          BRDF f [1/sr]
=========================  ====================  ===========================================
``brdf``                   f                     f
``cosine_weighted_brdf``   f |cos theta_o|       value / |cos theta_o|
``reflectance_factor``     R = pi f / rho_w      rho_w R / pi   (rho_w: the white standard's
                                                 reflectance, 0.99 for Spectralon)
=========================  ====================  ===========================================

The reflectance factor is the signal of the sample divided by that of a white Lambertian
standard of reflectance rho_w under the same geometry (Padrón 2025 §4.5: 99 % Spectralon;
spec assumption D11: f = 0.99 R / pi).

Geometry: theta in [0, 90] degrees from the normal, phi in [0, 360). An **in-plane** table
(all directions in the plane of incidence) is addressed by a signed outgoing angle:
theta_o > 0 on the forward (mirror) side, theta_o < 0 on the retro-reflection side, as in
Fig. 4.4 of Padrón 2025 and :func:`appearance_jax.core.frame.in_plane_directions`
(wi at phi_i = 0, wo at phi_o = 180 degrees for theta_o >= 0 and phi_o = 0 for theta_o < 0).

Missing samples are never zeros: ``mask`` is False there and ``masked`` counts them by reason.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

QUANTITIES = ("brdf", "cosine_weighted_brdf", "reflectance_factor")
QUANTITY_UNITS = {"brdf": "1/sr", "cosine_weighted_brdf": "1", "reflectance_factor": "1"}
HORIZON_COS = 1e-12  # a direction with cos theta <= this lies at or below the horizon
PLANE_TOL = 1e-6  # rad: phi_o - phi_i within this of 0 or pi (or theta within this of 0) is in the plane


@dataclass(frozen=True)
class Table:
    """Measured (or proxy) samples of a BRDF-like quantity.

    Attributes (N samples, B bands):
        theta_i, phi_i, theta_o, phi_o: (N,) float64 radians.
        values: (N, B) float64 in ``quantity``; NaN where masked.
        mask: (N, B) bool, True for a valid sample.
        sigma: (N, B) float64 one-standard-deviation uncertainty of ``values`` (same unit), or None.
        quantity: one of ``QUANTITIES``.
        bands: (B,) band names ("R", "G", "B" or wavelengths as text).
        wavelengths: (B,) nm for spectral tables, else None (linear RGB).
        white_reference: reflectance of the white standard (reflectance_factor tables only).
        source: where the table came from (file name, "proxy:white-fabric", ...).
        masked: reason -> number of masked values (band entries), e.g. {"missing": 12}.
    """

    theta_i: np.ndarray
    phi_i: np.ndarray
    theta_o: np.ndarray
    phi_o: np.ndarray
    values: np.ndarray
    mask: np.ndarray
    quantity: str = "brdf"
    bands: tuple = ("R", "G", "B")
    wavelengths: np.ndarray | None = None
    sigma: np.ndarray | None = None
    white_reference: float = 0.99
    source: str = "<memory>"
    masked: dict = field(default_factory=dict)

    def __post_init__(self):
        n = np.shape(self.theta_i)[0] if np.ndim(self.theta_i) else None
        for name in ("theta_i", "phi_i", "theta_o", "phi_o"):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if a.ndim != 1 or a.shape[0] != n:
                raise ValueError(f"Table.{name}: expected shape ({n},), got {a.shape}")
            object.__setattr__(self, name, a)
        v = np.asarray(self.values, dtype=np.float64)
        if v.ndim == 1:
            v = v[:, None]
        if v.ndim != 2 or v.shape[0] != n:
            raise ValueError(f"Table.values: expected shape ({n}, bands), got {v.shape}")
        m = np.broadcast_to(np.asarray(self.mask, dtype=bool), v.shape).copy()
        m &= np.isfinite(v)
        object.__setattr__(self, "values", np.where(m, v, np.nan))
        object.__setattr__(self, "mask", m)
        if self.sigma is not None:
            s = np.broadcast_to(np.asarray(self.sigma, dtype=np.float64), v.shape).copy()
            object.__setattr__(self, "sigma", s)
        if self.quantity not in QUANTITIES:
            raise ValueError(f"Table.quantity = {self.quantity!r}: must be one of {', '.join(QUANTITIES)}")
        if len(self.bands) != v.shape[1]:
            raise ValueError(f"Table.bands has {len(self.bands)} names for {v.shape[1]} value columns")
        object.__setattr__(self, "bands", tuple(str(b) for b in self.bands))
        if self.wavelengths is not None:
            object.__setattr__(self, "wavelengths", np.asarray(self.wavelengths, dtype=np.float64))
        if not (0.0 < self.white_reference <= 1.0):
            raise ValueError(f"Table.white_reference = {self.white_reference:g} is outside the valid range (0, 1]")
        object.__setattr__(self, "masked", dict(self.masked))

    # ------------------------------------------------------------------ construction
    @classmethod
    def in_plane(cls, theta_i, theta_o, values, **kw) -> "Table":
        """A table of in-plane samples from theta_i >= 0 and **signed** theta_o (radians)."""
        ti = np.asarray(theta_i, dtype=np.float64)
        to = np.asarray(theta_o, dtype=np.float64)
        kw.setdefault("mask", np.ones(np.shape(values), dtype=bool) if np.ndim(values) == 2
                      else np.ones((np.size(ti), 1), dtype=bool))
        return cls(theta_i=ti, phi_i=np.zeros_like(ti), theta_o=np.abs(to),
                   phi_o=np.where(to >= 0, np.pi, 0.0), values=values, **kw)

    def replace(self, **kw) -> "Table":
        return dataclasses.replace(self, **kw)

    def select(self, rows) -> "Table":
        """The table restricted to ``rows`` (boolean mask or indices)."""
        r = np.asarray(rows)
        if r.dtype != bool:
            r = r.astype(np.intp)  # select([]) is an empty selection, not a float index
        mask = self.mask[r]
        masked = dict(self.masked)
        n_before, n_after = int((~self.mask).sum()), int((~mask).sum())
        if n_after != n_before:  # reasons are counted per table, not per entry: keep only the total
            masked = {"masked (in the selected rows)": n_after} if n_after else {}
        return self.replace(theta_i=self.theta_i[r], phi_i=self.phi_i[r], theta_o=self.theta_o[r],
                            phi_o=self.phi_o[r], values=self.values[r], mask=mask,
                            sigma=None if self.sigma is None else self.sigma[r], masked=masked)

    # ------------------------------------------------------------------ properties
    @property
    def n_samples(self) -> int:
        return int(self.theta_i.shape[0])

    @property
    def n_bands(self) -> int:
        return int(self.values.shape[1])

    @property
    def n_valid(self) -> int:
        """Number of valid (unmasked) band values."""
        return int(self.mask.sum())

    @property
    def spectral(self) -> bool:
        return self.wavelengths is not None

    def _wo_in_plane(self) -> np.ndarray:
        """(N,) bool: wo in the plane of incidence of wi (phi_o - phi_i = 0 or pi) or on the normal."""
        dphi = np.mod(self.phi_o - self.phi_i, 2 * np.pi)
        tol = PLANE_TOL
        plane = (np.abs(dphi) < tol) | (np.abs(dphi - np.pi) < tol) | (np.abs(dphi - 2 * np.pi) < tol)
        return plane | (self.theta_o < tol)

    @property
    def is_in_plane(self) -> bool:
        """True when every wo lies in the plane of incidence of its wi (|phi_o - phi_i| in {0, pi})."""
        return bool(np.all(self._wo_in_plane() | (self.theta_i < PLANE_TOL)))

    def in_plane_rows(self) -> np.ndarray:
        """(N,) bool: the directions a signed theta_o addresses.

        Every row of an in-plane table (:attr:`is_in_plane`); in any other table the rows whose
        wo lies in the plane of incidence (phi_o - phi_i = 0 or pi within ``PLANE_TOL``) or on
        the normal (theta_o = 0), e.g. the in-plane subset of a gonioreflectometer or MERL grid.
        """
        if self.is_in_plane:
            return np.ones(self.n_samples, bool)
        return self._wo_in_plane()

    def above_horizon(self) -> np.ndarray:
        """(N,) bool: both directions above the horizon (cos theta > ``HORIZON_COS``)."""
        return (np.cos(self.theta_i) > HORIZON_COS) & (np.cos(self.theta_o) > HORIZON_COS)

    def signed_theta_o(self, *, strict: bool = True) -> np.ndarray:
        """Signed theta_o (radians) of an in-plane table: > 0 forward, < 0 retro side.

        ``strict=False`` accepts any table: the rows out of the plane (not :meth:`in_plane_rows`)
        are NaN.
        """
        if strict and not self.is_in_plane:
            raise ValueError(f"{self.source}: signed theta_o needs an in-plane table (wo in the plane of incidence)")
        # wo at phi_i + pi is on the forward (mirror) side, wo at phi_i on the retro side
        signed = np.where(np.cos(self.phi_o - self.phi_i) > 0, -self.theta_o, self.theta_o)
        return signed if strict else np.where(self.in_plane_rows(), signed, np.nan)

    # ------------------------------------------------------------------ geometry / units
    def directions(self, dtype=None, host: bool = False):
        """(wi, wo) as :class:`~appearance_jax.core.vec.Vec3` arrays of shape (N,): device arrays,
        or numpy arrays with ``host=True`` (computed in float64, then cast to ``dtype``)."""
        import jax.numpy as jnp

        from ...core.frame import spherical_direction, spherical_directions
        from ...core.vec import Vec3

        dt = dtype or jnp.result_type(float)
        if host:
            return tuple(Vec3(*(np.asarray(c, dt) for c in spherical_direction(t, p, xp=np)))
                         for t, p in ((self.theta_i, self.phi_i), (self.theta_o, self.phi_o)))
        return spherical_directions(*(np.asarray(a, dt) for a in (self.theta_i, self.phi_i, self.theta_o, self.phi_o)))

    def brdf_factor(self) -> np.ndarray:
        """(N, 1) factor that converts ``values`` (and ``sigma``) to a BRDF in 1/sr."""
        if self.quantity == "brdf":
            return np.ones((self.n_samples, 1))
        if self.quantity == "cosine_weighted_brdf":
            c = np.abs(np.cos(self.theta_o))
            return (1.0 / np.where(c > 0, c, np.nan))[:, None]
        return np.full((self.n_samples, 1), self.white_reference / np.pi)

    def brdf(self) -> tuple[np.ndarray, np.ndarray | None]:
        """(values, sigma) converted to a BRDF in 1/sr (see the module table)."""
        k = self.brdf_factor()
        return self.values * k, None if self.sigma is None else self.sigma * k

    def from_brdf(self, f: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`brdf`: BRDF values (N, B) in this table's quantity."""
        return np.asarray(f) / self.brdf_factor()

    def with_values(self, values, sigma=None) -> "Table":
        """Same angles and quantity, new values (e.g. a fitted model), all valid where finite."""
        return self.replace(values=values, mask=np.isfinite(values), sigma=sigma, masked={})

    def linear_rgb(self, f, illuminant: str = "D65") -> np.ndarray:
        """(N, 3) float64 linear sRGB of per-band values ``f`` (N, B) on this table's bands.

        Spectra are converted as reflectance-like spectra under ``illuminant`` (a flat value v
        maps to (v, v, v)), RGB bands are returned as they are and any other band set as grey
        (the mean over bands). NaN where a band of the row is NaN (its colour is unknown).
        """
        f = np.asarray(f, np.float64)
        if self.spectral:
            from ...core.spectral import spectrum_to_linear_srgb

            ok = np.isfinite(f).all(axis=1, keepdims=True)
            rgb = spectrum_to_linear_srgb(np.where(np.isfinite(f), f, 0.0), self.wavelengths, illuminant)
            return np.where(ok, np.asarray(rgb, np.float64), np.nan)
        if f.shape[1] == 3:
            return f
        return np.repeat(f.mean(axis=1, keepdims=True), 3, axis=1)

    def to_rgb(self, illuminant: str = "D65") -> "Table":
        """A spectral table converted to linear sRGB (reflectance-like spectra under ``illuminant``).

        Values are converted as reflectance spectra: a spectrally flat value v maps to
        RGB = (v, v, v). A band-masked sample is masked in all three channels (its colour is unknown).
        """
        if not self.spectral:
            return self
        from ...core.spectral import spectrum_to_linear_srgb

        ok = self.mask.all(axis=1)
        rgb = self.linear_rgb(self.values, illuminant)
        sigma = None
        if self.sigma is not None:  # linear map: propagate independent band errors
            eye = np.eye(self.n_bands)
            m = np.asarray(spectrum_to_linear_srgb(eye, self.wavelengths, illuminant))  # (B, 3)
            sigma = np.sqrt((np.where(self.mask, self.sigma, 0.0) ** 2) @ (m ** 2))
        masked = dict(self.masked)
        partial = int(((~ok) & self.mask.any(axis=1)).sum())
        if partial:
            masked["incomplete spectrum (rgb conversion)"] = partial
        return self.replace(values=rgb, mask=np.repeat(ok[:, None], 3, axis=1), sigma=sigma,
                            bands=("R", "G", "B"), wavelengths=None, masked=masked)

    def summary(self) -> str:
        """One line: source, size, quantity and what was masked."""
        total = self.values.size
        parts = [f"{self.source}: {self.n_samples} directions x {self.n_bands} bands"
                 f" ({'spectral' if self.spectral else 'RGB' if self.bands == ('R', 'G', 'B') else 'bands'}),"
                 f" quantity {self.quantity}", f"{self.n_valid}/{total} values valid"]
        if self.masked:
            parts.append("masked: " + ", ".join(f"{n} {why}" for why, n in self.masked.items()))
        if self.is_in_plane:
            parts.append("in-plane")
        return "; ".join(parts)
