"""Residuals and error metrics between a model and a table (BRDF values in 1/sr).

``metric`` chooses the residual r per valid (direction, band) entry:

==============  ===============================================  ===================================
metric          r                                                use
==============  ===============================================  ===================================
``l2``          f_model - f_data                                 linear-RGB L2, the choice of
                                                                 Padrón 2025 §4.5 (Eq. 4.11)
``cos_log``     log(1 + f_model cos th_i) - log(1 + f_data       cosine-weighted log (Löw et al.
                cos th_i)                                        2012): tames highlights and
                                                                 grazing angles; the loss the MERL
                                                                 Neural-BRDF proxies were trained on
``relative``    (f_model - f_data) / (|f_data| + floor)          every sample counts by its ratio;
                                                                 ``floor`` keeps dark samples finite
==============  ===============================================  ===================================

With per-value uncertainties sigma (1 s.d., in the table) the residual is divided by sigma
carried through the metric (sigma, sigma cos/(1 + f cos), sigma/(|f| + floor)), so that the
sum of squares is a chi-square and the parameter covariance is absolute. Sample weights w
multiply r by sqrt(w). Masked entries contribute exactly 0 and are not counted.
"""

from __future__ import annotations

import numpy as np

from ...core.arrays import namespace

METRICS = ("l2", "cos_log", "relative")

# 1/sr: the BRDF floor of the relative metric, (f_model - f_data) / (|f_data| + FLOOR), and of the
# log errors, ln(f + FLOOR): it keeps black samples finite. One value for the fit, its error
# summaries and the report's residuals and log-ratio maps.
FLOOR = 1e-3


def check_metric(metric: str) -> str:
    if metric not in METRICS:
        raise ValueError(f"metric = {metric!r}: must be one of {', '.join(METRICS)}")
    return metric


def residual(f_model, f_data, cos_i, metric: str, *, floor=FLOOR):
    """Unweighted residual of ``metric``; ``cos_i`` broadcasts against the bands axis ((N, 1)).
    numpy inputs give numpy (the report's residual table), jax arrays jax arrays."""
    xp = namespace(f_model, f_data, cos_i)
    if metric == "l2":
        return f_model - f_data
    if metric == "cos_log":
        # data can be slightly negative from noise near black: clamp so the log stays defined
        return xp.log1p(xp.maximum(f_model, 0.0) * cos_i) - xp.log1p(xp.maximum(f_data, 0.0) * cos_i)
    if metric == "relative":
        return (f_model - f_data) / (xp.abs(f_data) + floor)
    raise ValueError(f"metric = {metric!r}: must be one of {', '.join(METRICS)}")


def residual_scale(f_data, sigma, cos_i, metric: str, *, floor=FLOOR):
    """sigma of the residual (first-order propagation of the data's sigma through the metric)."""
    xp = namespace(f_data, sigma, cos_i)
    if metric == "l2":
        return sigma
    if metric == "cos_log":
        return sigma * cos_i / (1.0 + xp.maximum(f_data, 0.0) * cos_i)
    return sigma / (xp.abs(f_data) + floor)


def error_metrics(f_model, f_data, mask, cos_i, *, eps: float = FLOOR) -> dict:
    """Summary errors over the valid entries (numpy floats), for reports and recipe tables.

    - ``rmse``: sqrt(mean (f_model - f_data)^2) [1/sr];
    - ``cos_log_rmse``: sqrt(mean r_cos_log^2), the cosine-weighted log error (Löw et al. 2012);
    - ``log_rmse``: sqrt(mean (ln(f_model + eps) - ln(f_data + eps))^2), eps = FLOOR = 1e-3 1/sr
      (the log-RMSE of BRDF-fitting papers; eps keeps black samples finite);
    - ``rel_rmse``: sqrt(mean ((f_model - f_data) / (|f_data| + eps))^2).
    """
    fm = np.asarray(f_model, np.float64)
    fd = np.asarray(f_data, np.float64)
    m = np.asarray(mask, bool)
    c = np.broadcast_to(np.asarray(cos_i, np.float64), fd.shape)
    if not m.any():
        return dict(rmse=np.nan, cos_log_rmse=np.nan, log_rmse=np.nan, rel_rmse=np.nan, n=0)
    fm, fd, c = fm[m], fd[m], c[m]
    lc = np.log1p(np.maximum(fm, 0) * c) - np.log1p(np.maximum(fd, 0) * c)
    ll = np.log(np.maximum(fm, 0) + eps) - np.log(np.maximum(fd, 0) + eps)
    rel = (fm - fd) / (np.abs(fd) + eps)
    rms = lambda a: float(np.sqrt(np.mean(a * a)))  # noqa: E731
    return dict(rmse=rms(fm - fd), cos_log_rmse=rms(lc), log_rmse=rms(ll), rel_rmse=rms(rel), n=int(m.sum()))
