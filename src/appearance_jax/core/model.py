"""The model protocol: what every BSDF, BCSDF and phase function module exposes.

A model module defines pure kernels ``_eval(params, wi, wo)``, ``_sample(params, wi, u)``
and ``_pdf(params, wi, wo)`` and publishes them through :func:`boundary`, which validates
the parameters eagerly and then calls the jitted kernel. The module ends with a
:class:`Model` record that the registry (``appearance_jax.registry``) lists.

Signatures (directions are unit :class:`~appearance_jax.core.vec.Vec3` pointing away from
the scattering point, in the local frame of :mod:`appearance_jax.core.frame`, z = normal):

- ``eval(params, wi, wo) -> f``: shape ``wi.shape + (n_bands,)``, in 1/sr.
- ``sample(params, wi, u_or_key) -> (wo, weight, pdf)``: ``weight = f |cos theta_o| / pdf``
  (bands axis; for phase functions ``f / pdf``), ``pdf`` in 1/sr (shape ``wi.shape``).
  Failed samples have ``weight = 0`` and ``pdf = 0``.
- ``pdf(params, wi, wo) -> pdf``: shape ``wi.shape``.

Inputs at the boundary (eager, i.e. on concrete values; traced calls inside a user's
``jit`` skip them and the kernels never branch on them):

- ``params`` must be an instance of the model's ``Params`` whose values passed the checks of
  :mod:`appearance_jax.core.params` (at construction, or here for rebuilt pytrees);
- every kernel argument named ``wi`` or ``wo`` goes through
  :func:`~appearance_jax.core.vec.as_direction`: a ``Vec3`` is passed on unchanged (results
  are bit-identical), an ``(..., 3)`` array or a tuple of 3 numbers is converted, other types
  raise ``TypeError``; non-finite, zero-length or non-unit vectors (|norm - 1| > 1e-3) raise
  ``ValueError`` naming the argument. Directions below the horizon or at grazing are valid
  (reflection models return 0 there).

Under ``jit``, :func:`~appearance_jax.core.params.checked` /
:func:`~appearance_jax.core.params.check_traced` check parameter ranges with ``checkify``.
"""

from __future__ import annotations

import collections.abc
import dataclasses
import functools
import inspect
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import jax
import jax.numpy as jnp

from .params import validate
from .vec import as_direction, check_directions

#: kernel arguments that are directions (checked by :func:`boundary`)
DIRECTION_ARGS = ("wi", "wo")


def boundary(kernel: Callable, params_cls: type, static_argnames: tuple[str, ...] = ()) -> Callable:
    """Public entry point of a kernel: eager validation of ``params`` and directions + one ``jit``.

    Inside a user's own ``jit``/``grad`` the parameters are traced and the checks are
    skipped; the kernel itself never branches on parameter values. The kernel's arguments
    named in :data:`DIRECTION_ARGS` are directions (module docstring).
    """
    jitted = jax.jit(kernel, static_argnames=static_argnames)
    names = list(inspect.signature(kernel).parameters)
    directions = tuple((n, names.index(n) - 1) for n in DIRECTION_ARGS if n in names[1:])

    @functools.wraps(kernel)
    def public(params, *args, **kwargs):
        validate(params, params_cls)
        if directions:
            args, named = list(args), {}
            for n, i in directions:
                if i < len(args):
                    if args[i] is not None:
                        args[i] = named[n] = as_direction(n, args[i], check=False)
                elif kwargs.get(n) is not None:
                    kwargs[n] = named[n] = as_direction(n, kwargs[n], check=False)
            check_directions(named)
        return jitted(params, *args, **kwargs)

    public.kernel = kernel  # the unvalidated, unjitted kernel, for composition
    return public


def with_bands(x) -> jax.Array:
    """Give a per-direction array a trailing singleton bands axis to broadcast against bands."""
    return jnp.asarray(x)[..., None]


def as_bands(v) -> jax.Array:
    """A band-valued parameter with at least one trailing axis."""
    return jnp.atleast_1d(jnp.asarray(v))


def estimate_of(out):
    """The value of a model evaluation: ``out`` itself, or the estimate of a stochastic model's
    ``(estimate, standard_error)`` pair (:attr:`Model.stochastic`)."""
    return out[0] if isinstance(out, tuple) else out


class LazyPresets(collections.abc.Mapping):
    """Named presets built on first access (then kept): ``LazyPresets(names, build)``.

    For models whose presets cost XLA work to build (arrays stacked and padded per preset):
    importing the registry, which every command does, must not pay for presets nobody asked
    for. Iteration, ``len`` and ``in`` need only the names.
    """

    def __init__(self, names, build: Callable[[str], Any]):
        self._names = tuple(names)
        self._build = build
        self._built: dict[str, Any] = {}

    def __getitem__(self, name):
        if name not in self._names:
            raise KeyError(name)
        if name not in self._built:
            self._built[name] = self._build(name)
        return self._built[name]

    def __contains__(self, name):  # Mapping's would build the preset
        return name in self._names

    def __iter__(self):
        return iter(self._names)

    def __len__(self):
        return len(self._names)

    def __repr__(self):
        return f"LazyPresets({list(self._names)!r})"


@dataclass(frozen=True)
class Model:
    """Registry record of a model. ``eval``/``sample``/``pdf`` are the validated public functions."""

    name: str
    kind: str  # "bsdf" | "phase" | "bcsdf"
    Params: type
    eval: Callable
    sample: Callable | None
    pdf: Callable | None
    summary: str
    source: str
    reciprocal: bool = True
    # True when wo ranges over the whole sphere (transmission / phase functions)
    transmissive: bool = False
    presets: Mapping[str, Any] = field(default_factory=dict)
    # True for Monte Carlo evaluators: eval(params, wi, wo, key=...) returns (estimate, stderr)
    stochastic: bool = False
    # physically known parameters that ``appearance-jax fit`` holds fixed unless ``--free NAME``:
    # name -> (value, reason), e.g. {"eta": (1.5, "coat index of common polymers")}; only where
    # physics (not the data) fixes the value, or the field is degenerate with another
    fit_fixed: Mapping[str, tuple[Any, str]] = field(default_factory=dict)
    # fields that enter f only after the model's costly per-parameter work (band albedos and scales
    # applied to finished lobes): a fit takes their Jacobian columns in a forward pass of their own,
    # whose tangents then skip that work (fit.solve.problem.Problem.jacobian_z). A speed hint only:
    # the Jacobian is the same either way
    jacobian_apart: tuple[str, ...] = ()
    # True when output band b depends on a band field with one entry per output band only through its
    # entry b (the bands are never mixed): a fit then takes all of such a field's Jacobian columns from
    # one tangent (fit.solve.problem.Problem.jacobian_z); checked for every model that declares it
    # (tests/fit/solve/test_solve.py)
    band_separable: bool = False

    def __post_init__(self):
        if self.kind not in ("bsdf", "phase", "bcsdf"):
            raise ValueError(f"Model.kind = {self.kind!r}: must be 'bsdf', 'phase' or 'bcsdf'")
        names = {f.name for f in dataclasses.fields(self.Params)} if dataclasses.is_dataclass(self.Params) else set()
        unknown = [n for n in self.jacobian_apart if n not in names]
        if unknown:
            raise ValueError(f"Model {self.name!r}: jacobian_apart names {unknown}, which are not fields of its "
                             f"Params ({', '.join(sorted(names))})")
