"""The solve: residuals in a metric, parameter spaces, solvers, uncertainties and batched fits.

Modules: ``residuals`` (metrics and error summaries), ``transforms`` (bounded <-> unconstrained
parameter spaces), ``problem`` (a fit's data and residuals),
``solvers`` (:func:`fit`, the solvers, multi-start), ``result`` (:class:`FitResult`),
``uncertainty`` (iid, sandwich and bootstrap sigmas, degeneracies) and ``batch``
(:func:`fit_batch`: many tables at once with vmap and sharding).
"""

from .batch import BatchFitResult, fit_batch
from .problem import Problem, build_problem, entry_arrays
from .result import FitDiverged, FitResult, finish
from .uncertainty import covariance, covariances
from .solvers import SOLVERS, fit, solve_z

__all__ = ["fit", "FitResult", "FitDiverged", "fit_batch", "BatchFitResult", "build_problem", "entry_arrays", "solve_z",
           "covariance", "covariances", "finish", "Problem", "SOLVERS"]
