"""Property-test harness for appearance models (public API).

Run it on any model record with the fields of :class:`appearance_jax.core.model.Model`
(``name``, ``kind``, ``eval``, ``sample``, ``pdf``, ``transmissive``), your own included::

    import jax; jax.config.update("jax_enable_x64", True)
    from appearance_jax import registry, testing
    m = registry.get("lambert"); p = m.Params(reflectance=1.0)
    testing.assert_reciprocity(m, p)
    testing.assert_white_furnace(m, p, lossless=True)
    testing.assert_sampling(m, p)
    testing.assert_chi2(m, p)
    testing.assert_gradients(lambda q: m.eval(q, wi, wo).sum(), p)
    testing.assert_special_directions(m, p, dtype="float32")

Every ``check_*`` returns a result dataclass (numbers, ``passed``, ``message``); the
``assert_*`` twin raises ``AssertionError(message)`` on failure. Estimators are vectorised
and use fixed keys; statistical tolerances follow from standard errors and a family-wise
significance (see :mod:`.properties`, :mod:`.chi2`, :mod:`.gradients`).
"""

from .chi2 import Chi2Result, assert_chi2, chi2_pvalue, chi2_test, pool_cells  # noqa: F401
from .directions import (  # noqa: F401
    call_chunked,
    incident_domain,
    projection_cosine,
    random_directions,
    sample_chunked,
    scattering_domain,
)
from .gradients import GradientResult, assert_gradients, check_gradients  # noqa: F401
from .properties import (  # noqa: F401
    FurnaceResult,
    ReciprocityResult,
    SamplingResult,
    albedo_mc,
    albedo_quadrature,
    assert_reciprocity,
    assert_sampling,
    assert_white_furnace,
    check_reciprocity,
    check_sampling,
    check_white_furnace,
    reciprocity_pairs,
)
from .results import CheckResult, sidak, z_threshold  # noqa: F401
from .special import (  # noqa: F401
    SPECIAL_DIRECTIONS,
    SpecialDirectionsResult,
    assert_special_directions,
    check_special_directions,
    special_pairs,
)

check_chi2 = chi2_test
