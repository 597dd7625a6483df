"""Cross-sections for the flatland tracer: shapes, the interfaces on them, and the media.

A :class:`Section` is a small scene in the (y, z) plane of the fiber frame (x = fiber
axis; :mod:`appearance_jax.core.frame`). It holds

- ``shapes``: :class:`Shape` (an ellipse, an open elliptic arc, or a straight segment) each
  carrying an :class:`Interface` and the ids of the regions on its inner and outer side;
- ``media``: :class:`Medium` per region (region 0 is the exterior): refractive index and
  absorption coefficient per band (1/length, in the section's length unit);
- ``period``: ``None`` for a bounded object, or the spacing along y of an infinite periodic
  row (barbule arrays): every shape is then repeated at ``y + k period``.

All numbers are pytree leaves (differentiable); kinds and topology are static. Lengths are
in the unit of the geometry: for fibers the radius (semi-major axis) is 1, so absorption is
per unit radius (spec seed-001 §1.3.2).

Builders: :func:`fiber` (a circular or elliptical cortex, optional cuticle roughness and
tilt, optional off-centre medulla), :func:`cylinder` (a smooth dielectric cylinder, e.g.
water), :func:`ellipse_row` (a periodic row of ellipses or arcs), :func:`segment` (one straight
segment, e.g. a row of barbules seen edge-on, for a custom :class:`Section`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Optional

import jax
import jax.numpy as jnp
import numpy as np

from ..core.params import check_value, ParamSpec

#: the feather mode's interfaces: a random longitudinal tilt of +-``tilt`` per hit (interfaces.barbule)
BARBULE_KINDS = ("barbule", "saddle_mirror")
INTERFACE_KINDS = ("dielectric", "diffuse", "film", "absorber") + BARBULE_KINDS
DISTRIBUTIONS = ("ggx", "beckmann")
GEOMETRIES = ("ellipse", "segment")


def _f(x):
    return jnp.asarray(x, dtype=jnp.result_type(float))


@jax.tree_util.register_pytree_node_class
@dataclass(frozen=True)
class Interface:
    """What happens where a ray meets a shape.

    kind (static):
      - ``"dielectric"``: Fresnel reflection / refraction between the media on either side
        (Snell in 3D about the in-plane normal, total internal reflection). ``roughness`` > 0
        makes it a rough dielectric: a microfacet normal is sampled (visible normals, Heitz
        2018) about the **mesonormal** tilted by ``tilt`` along the fiber axis (cuticle
        scales, Huang Eq. 4.39), weighted by Smith G1 of the outgoing direction; rays
        whose directions disagree with the macro or meso surface are killed (spec seed-001
        §4.3 item 3).
      - ``"film"``: a smooth dielectric interface coated with a thin film: Airy reflectance
        and transmittance (:func:`optics.thinfilm.airy`) of ``film_nm`` nm of index
        ``film_eta`` at the wavelengths ``wavelength_nm`` (one per band); directions as for a
        smooth dielectric.
      - ``"diffuse"``: an opaque Lambertian surface of reflectance ``albedo`` (per band); the
        ray is reflected into the side it came from, cosine-distributed about the normal
        (a diffuse medulla, Padrón 2025 Ch. 5).
      - ``"absorber"``: an opaque black surface (the ray ends).
      - ``"barbule"``, ``"saddle_mirror"``: a rock-dove barbule (the feather mode,
        :mod:`appearance_jax.flatland.feather`): the normal tilted at random along the axis within
        +-``tilt`` (the half-angle theta_d of the barbule's longitudinal arc), a film-coated
        (``barbule``: Airy R, TRT = one Lambertian bounce on a melanin layer of reflectance
        ``albedo``) or plain mirror (``saddle_mirror``: reflectance ``albedo``) surface, opaque
        (:func:`~appearance_jax.flatland.interfaces.barbule`).
    distribution (static): microfacet distribution of rough dielectrics, ``ggx`` or
      ``beckmann``.

    Fields: roughness (alpha, [0, 1]), tilt (rad, (-pi/2, pi/2); positive tilts the mesonormal
    towards +x), albedo (per band, [0, 1]), film_nm (nm), film_eta, wavelength_nm (nm, per band),
    coverage ([0, 1], default 1).

    ``coverage`` < 1 makes the shape **semi-transparent**: a ray crossing it meets it (and the
    interface acts) with probability ``coverage`` and passes straight on, untouched, otherwise; a
    fresh coin is drawn for every crossing of every copy. This is a shape of which only the
    fraction ``coverage`` is there, such as a row of barbules seen edge-on in a barb's
    cross-section (Padrón's w'_bb, App. B.2.2). The coin is not differentiable in ``coverage``.
    """

    kind: str = "dielectric"
    roughness: jax.Array = 0.0
    tilt: jax.Array = 0.0
    albedo: jax.Array = 1.0
    film_nm: jax.Array = 0.0
    film_eta: jax.Array = 1.33
    wavelength_nm: jax.Array = 550.0
    distribution: str = "ggx"
    coverage: jax.Array = 1.0

    _LEAVES = ("roughness", "tilt", "albedo", "film_nm", "film_eta", "wavelength_nm", "coverage")

    def __post_init__(self):
        # smooth vs rough and solid vs semi-transparent select code paths, so they are static:
        # decided once from the concrete values (a traced value counts as rough / semi-transparent)
        r, c = self.roughness, self.coverage
        rough = True if isinstance(r, jax.core.Tracer) else bool(np.any(np.asarray(r) != 0))
        semi = True if isinstance(c, jax.core.Tracer) else bool(np.any(np.asarray(c) != 1))
        object.__setattr__(self, "_rough", rough)
        object.__setattr__(self, "_semi", semi)

    def tree_flatten(self):
        return (tuple(getattr(self, k) for k in self._LEAVES),
                (self.kind, self.distribution, self._rough, self._semi))

    @classmethod
    def tree_unflatten(cls, aux, leaves):
        obj = object.__new__(cls)
        for k, v in zip(cls._LEAVES, leaves):
            object.__setattr__(obj, k, v)
        object.__setattr__(obj, "kind", aux[0])
        object.__setattr__(obj, "distribution", aux[1])
        object.__setattr__(obj, "_rough", aux[2])
        object.__setattr__(obj, "_semi", aux[3])
        return obj

    @property
    def rough(self) -> bool:
        """Static: False where the roughness was a concrete 0 (smooth interfaces are exact)."""
        return self._rough

    @property
    def semi_transparent(self) -> bool:
        """Static: False where the coverage was a concrete 1 (no coin is drawn)."""
        return self._semi


@jax.tree_util.register_pytree_node_class
@dataclass(frozen=True)
class Shape:
    """An ellipse (or open arc), or a straight segment, in the section plane.

    centre (cy, cz), semi-axes a (along the shape's first axis) and b, rotation psi (rad) of
    the first axis from +y towards +z; ``arc = (lo, span)``: parametric angles kept (None =
    closed ellipse). ``inside``/``outside``: region ids on either side (static); an open arc
    has the same medium on both sides.

    ``geometry = "segment"`` (static): the straight segment of half length ``a`` through the
    centre along the first axis (``b`` is unused; :func:`segment` sets it to ``a``). Its normal
    is the first axis turned by +90 degrees; it is open (``inside == outside``) and a ray meets
    it at most once between events.

    ``present``: None (the shape is there), or a traced bool (or 0/1) that removes the shape as
    data: where it is false no ray meets the shape. One compiled trace then serves sections with
    and without it (a feather's barb with its medulla and its barbules without one); the shape's
    geometry must still be finite where it is absent.
    """

    cy: jax.Array = 0.0
    cz: jax.Array = 0.0
    a: jax.Array = 1.0
    b: jax.Array = 1.0
    psi: jax.Array = 0.0
    interface: Interface = field(default_factory=Interface)
    inside: int = 1
    outside: int = 0
    arc: Optional[tuple] = None
    geometry: str = "ellipse"
    present: Optional[jax.Array] = None

    def tree_flatten(self):
        arc = self.arc_range()
        return ((self.cy, self.cz, self.a, self.b, self.psi, self.interface, arc[0], arc[1], self.present),
                (self.inside, self.outside, self.arc is None, self.geometry))

    @classmethod
    def tree_unflatten(cls, aux, ch):
        obj = object.__new__(cls)
        for k, v in zip(("cy", "cz", "a", "b", "psi", "interface"), ch[:6]):
            object.__setattr__(obj, k, v)
        object.__setattr__(obj, "inside", aux[0])
        object.__setattr__(obj, "outside", aux[1])
        object.__setattr__(obj, "arc", None if aux[2] else (ch[6], ch[7]))
        object.__setattr__(obj, "geometry", aux[3])
        object.__setattr__(obj, "present", ch[8])
        return obj

    @property
    def closed(self) -> bool:
        return self.arc is None and self.geometry == "ellipse"

    @property
    def is_segment(self) -> bool:
        return self.geometry == "segment"

    def arc_range(self):
        return (0.0, 2.0 * math.pi) if self.arc is None else self.arc


@jax.tree_util.register_pytree_node_class
@dataclass(frozen=True)
class Medium:
    """A homogeneous region: refractive index ``eta`` and absorption ``sigma_a`` (1/length,
    per band; Beer-Lambert on the 3D path length, Huang Eq. 4.17)."""

    eta: jax.Array = 1.0
    sigma_a: jax.Array = 0.0

    def tree_flatten(self):
        return (self.eta, self.sigma_a), None

    @classmethod
    def tree_unflatten(cls, aux, ch):
        return cls(*ch)


@jax.tree_util.register_pytree_node_class
@dataclass(frozen=True)
class Section:
    """A cross-section: shapes (with interfaces), media per region, optional period."""

    shapes: tuple
    media: tuple
    period: Optional[jax.Array] = None
    copies: int = 8

    def tree_flatten(self):
        return (self.shapes, self.media, self.period), (self.copies, self.period is None)

    @classmethod
    def tree_unflatten(cls, aux, ch):
        shapes, media, period = ch
        return cls(tuple(shapes), tuple(media), None if aux[1] else period, aux[0])

    @property
    def periodic(self) -> bool:
        return self.period is not None

    def outer(self) -> Shape:
        """The shape bounding the object (the first closed shape facing region 0)."""
        for s in self.shapes:
            if s.closed and s.outside == 0:
                return s
        raise ValueError("flatland.Section: no closed shape borders region 0 (the exterior)")

    def with_media(self, **kw) -> "Section":
        """Copy with region 1's medium fields replaced (e.g. ``sigma_a=...``)."""
        media = list(self.media)
        media[1] = replace(media[1], **kw)
        return replace(self, media=tuple(media))

    def validate(self) -> "Section":
        """Eager checks at the public boundary; returns self."""
        n_regions = len(self.media)
        if n_regions < 1:
            raise ValueError("flatland.Section.media must hold at least the exterior (region 0)")
        for i, s in enumerate(self.shapes):
            lab = f"flatland.Section.shapes[{i}]"
            for r, name in ((s.inside, "inside"), (s.outside, "outside")):
                if not 0 <= r < n_regions:
                    raise ValueError(f"{lab}.{name} = {r} is not a region id; valid range "
                                     f"[0, {n_regions - 1}]")
            if s.geometry not in GEOMETRIES:
                raise ValueError(f"{lab}.geometry = {s.geometry!r}; valid: {GEOMETRIES}")
            if s.is_segment and (s.arc is not None or s.inside != s.outside):
                raise ValueError(f"{lab}: a segment is open: arc must be None and inside == outside "
                                 f"(got arc = {s.arc}, inside = {s.inside}, outside = {s.outside})")
            check_value(f"{lab}.a", s.a, ParamSpec(0.0, math.inf, lo_open=True))
            if s.present is not None and not isinstance(s.present, jax.core.Tracer):
                pv = np.asarray(s.present)
                if pv.dtype != bool and not np.all((pv == 0) | (pv == 1)):
                    raise ValueError(f"{lab}.present = {s.present!r}; valid: None, a bool or 0/1")
            check_value(f"{lab}.b", s.b, ParamSpec(0.0, math.inf, lo_open=True))
            itf = s.interface
            if itf.kind not in INTERFACE_KINDS:
                raise ValueError(f"{lab}.interface.kind = {itf.kind!r}; valid: {INTERFACE_KINDS}")
            if itf.distribution not in DISTRIBUTIONS:
                raise ValueError(f"{lab}.interface.distribution = {itf.distribution!r}; "
                                 f"valid: {DISTRIBUTIONS}")
            check_value(f"{lab}.interface.roughness", itf.roughness, ParamSpec(0.0, 1.0))
            lo_tilt = 0.0 if itf.kind in BARBULE_KINDS else -math.pi / 2  # theta_d > 0 there
            check_value(f"{lab}.interface.tilt", itf.tilt, ParamSpec(lo_tilt, math.pi / 2, True, True, "rad"))
            check_value(f"{lab}.interface.albedo", itf.albedo, ParamSpec(0.0, 1.0))
            check_value(f"{lab}.interface.coverage", itf.coverage, ParamSpec(0.0, 1.0))
            check_value(f"{lab}.interface.film_nm", itf.film_nm, ParamSpec(0.0, math.inf, unit="nm"))
            check_value(f"{lab}.interface.wavelength_nm", itf.wavelength_nm,
                        ParamSpec(0.0, math.inf, lo_open=True, unit="nm"))
            if itf.kind == "dielectric" and s.inside == s.outside and itf.rough:
                raise ValueError(f"{lab}: a rough dielectric needs different media on its sides")
        for j, m in enumerate(self.media):
            check_value(f"flatland.Section.media[{j}].eta", m.eta, ParamSpec(0.0, math.inf, lo_open=True))
            check_value(f"flatland.Section.media[{j}].sigma_a", m.sigma_a, ParamSpec(0.0, math.inf, unit="1/length"))
        if self.period is not None:
            check_value("flatland.Section.period", self.period, ParamSpec(0.0, math.inf, lo_open=True))
        elif not any(s.closed and s.outside == 0 for s in self.shapes):
            raise ValueError("flatland.Section: a bounded section needs a closed shape that "
                             "borders region 0 (the exterior)")
        return self


def _interface(roughness, tilt, distribution, **kw) -> Interface:
    return Interface("dielectric", _f(roughness), _f(tilt), distribution=distribution, **kw)


def fiber(eta=1.55, sigma_a=0.0, *, eccentricity=0.0, rotation=0.0, roughness=0.0, tilt=0.0,
          distribution="ggx", medulla=None, medulla_albedo=1.0, medulla_kind="diffuse",
          medulla_eta=None, medulla_sigma_a=None) -> Section:
    """A hair-like fiber of unit radius: cortex (dielectric, absorbing) + optional medulla.

    Args:
        eta: cortex refractive index relative to the exterior (keratin ~ 1.55).
        sigma_a: cortex absorption per unit radius (scalar or per band).
        eccentricity: e = sqrt(1 - b^2) of the cortex ellipse, whose semi-axis 1 is along z
            and b along y, so its projected half width from azimuth phi is
            D(phi) = sqrt(1 - e^2 sin^2 phi) (Huang Eq. 4.27).
        rotation: rotation (rad) of the cross-section about the fiber axis.
        roughness, tilt, distribution: the cuticle (rough dielectric about the mesonormal
            tilted by ``tilt`` rad, Huang Eq. 4.39); 0 = smooth.
        medulla: None, or ``(cy, cz, a, b)`` of an inner ellipse (unrotated, then rotated with
            the section), e.g. ``(0.0, 0.0, 0.6, 0.6)`` (Padrón Fig. 5.7).
        medulla_kind: ``"diffuse"`` (Lambertian of reflectance ``medulla_albedo``),
            ``"absorber"``, or ``"dielectric"`` (index ``medulla_eta``, absorption
            ``medulla_sigma_a``).
    """
    e = float(eccentricity) if not isinstance(eccentricity, jax.core.Tracer) else eccentricity
    check_value("flatland.fiber.eccentricity", e, ParamSpec(0.0, 1.0, hi_open=True))
    b = jnp.sqrt(1.0 - _f(eccentricity) ** 2)
    rot = _f(rotation)
    cortex = Shape(_f(0.0), _f(0.0), b, _f(1.0), rot,
                   _interface(roughness, tilt, distribution), inside=1, outside=0)
    media = [Medium(_f(1.0), _f(0.0)), Medium(_f(eta), _f(sigma_a))]
    shapes = [cortex]
    if medulla is not None:
        cy, cz, ma, mb = (_f(v) for v in medulla)
        c, s = jnp.cos(rot), jnp.sin(rot)
        if medulla_kind == "dielectric":
            itf = Interface("dielectric")
            media.append(Medium(_f(eta if medulla_eta is None else medulla_eta),
                                _f(0.0 if medulla_sigma_a is None else medulla_sigma_a)))
        else:
            itf = Interface(medulla_kind, albedo=_f(medulla_albedo))
            media.append(Medium(_f(eta), _f(0.0)))
        shapes.append(Shape(c * cy - s * cz, s * cy + c * cz, ma, mb, rot, itf, inside=2, outside=1))
    return Section(tuple(shapes), tuple(media)).validate()


def cylinder(eta, sigma_a=0.0, radius=1.0) -> Section:
    """A smooth dielectric circular cylinder (a water column for rainbows, a glass rod)."""
    r = _f(radius)
    return Section((Shape(_f(0.0), _f(0.0), r, r, _f(0.0), Interface("dielectric")),),
                   (Medium(_f(1.0), _f(0.0)), Medium(_f(eta), _f(sigma_a)))).validate()


def ellipse_row(period, a, b, *, psi=0.0, arc=None, interface=None, copies=8,
                eta=1.0, sigma_a=0.0) -> Section:
    """An infinite row along y of identical ellipses (or open arcs) at ``y = k period``.

    The row lies in the plane z = 0; rays arrive from z > 0. ``interface`` defaults to an
    opaque absorber (a masking reference: which fraction of the rays hits the row, spec
    seed-000 §5.2). ``copies``: how many neighbours on each side a ray is tested against
    per event; rays that would need more are reported as truncated by the tallies.
    """
    itf = interface if interface is not None else Interface("absorber")
    inside = 0 if arc is not None else 1
    shp = Shape(_f(0.0), _f(0.0), _f(a), _f(b), _f(psi), itf, inside=inside, outside=0,
                arc=None if arc is None else (_f(arc[0]), _f(arc[1])))
    media = (Medium(_f(1.0), _f(0.0)),) if inside == 0 else (Medium(_f(1.0), _f(0.0)), Medium(_f(eta), _f(sigma_a)))
    return Section((shp,), media, _f(period), int(copies)).validate()


def segment(p, q, interface=None, *, region: int = 0) -> Shape:
    """The straight segment from ``p`` to ``q`` ((y, z) pairs, p != q) in region ``region`` (the
    same on both sides), carrying ``interface`` (default an opaque absorber). Its normal is
    (q - p) turned by +90 degrees (towards +z for p -> q along +y)."""
    (py, pz), (qy, qz) = ((_f(v[0]), _f(v[1])) for v in (p, q))
    half = 0.5 * jnp.hypot(qy - py, qz - pz)
    check_value("flatland.segment half length |q - p| / 2", half, ParamSpec(0.0, math.inf, lo_open=True))
    itf = interface if interface is not None else Interface("absorber")
    return Shape(0.5 * (py + qy), 0.5 * (pz + qz), half, half, jnp.arctan2(qz - pz, qy - py), itf,
                 inside=int(region), outside=int(region), geometry="segment")
