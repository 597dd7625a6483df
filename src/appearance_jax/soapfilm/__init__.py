"""Soap films on spherical bubbles: film-thickness fields and thin-film bubble shading (Huang 2022, Ch. 3).

* :mod:`.bubble`: the real-time bubble shading of Huang Sec. 3.5 -- per-path Airy weights
  (Huang Eq. 3.29, per polarisation then averaged), the direction recursion through the sphere
  (Huang Eq. 3.30), spectral-to-RGB shading of a point (Huang Eq. 3.32) and an orthographic
  :func:`render`.
* :mod:`.thickness`: thickness fields -- the gravity equilibrium (Huang Eq. 3.36), Huang Table 3.2's
  dimensionless numbers, equirectangular maps, and field callables for the shader.
* the film flow of Huang Secs. 3.3-3.4 (docs/soapfilm_flow.md): :mod:`.grid` (the staggered
  spherical grid), :mod:`.advect` (great-circle semi-Lagrangian advection), :mod:`.bimocq`
  (BiMocq^2 maps), :mod:`.concentration` (the implicit surfactant solve, App. C), :mod:`.air`
  (air velocities, noise), :mod:`.transport` (one step's advection in one pass) and :mod:`.flow`
  (``simulate``).

Units: film thicknesses passed to the shader are the **full** thickness d = 2 eta in nm
(the thesis' eta is the half thickness); wavelengths in nm; world +z is up.
"""

from .bubble import (  # noqa: F401
    PathDirections,
    PathWeights,
    camera_basis,
    image_plane,
    path_colors,
    path_directions,
    path_weights,
    render,
    shade,
)
from .thickness import (  # noqa: F401
    TABLE_3_1,
    Constants,
    DimensionlessNumbers,
    dimensionless_numbers,
    equilibrium_field,
    equilibrium_thickness,
    gamma0_for_marangoni,
    latlong_field,
    latlong_grid,
    latlong_thickness,
    uniform_field,
)
from .air import CurlNoise, Rotating, Still  # noqa: F401
from .flow import (  # noqa: F401
    FlowError,
    FlowParams,
    Settings,
    State,
    rest_state,
    seconds_to_time,
    simulate,
    time_to_seconds,
)
from .grid import SphereGrid  # noqa: F401
