"""Scale uncertainty: how far the metric scale SfM took from the AR poses may be off.

In: the :class:`~volec.sfm.SfmResult` of a capture with metric AR poses and the
:class:`~volec.sfm.SfmConfig` that made it (its AR noise model: per-frame jitter and a random-walk
drift from the first frame). Out: the scale's standard deviation, as a fraction of the scale
(:func:`sfm_scale_std`), and the volume interval that the estimate's space bounds span once
that uncertainty is added (:func:`volume_interval`).

The scale is what the AR centres say it is, and they drift: a drift that happens to point
outwards over the orbit looks like a larger scale, and no image can tell the two apart. SfM
fits the scale by generalised least squares under that noise model
(:func:`volec.sfm.drift_model_alignment`); the same model says how uncertain the fit is. Here
the drift is integrated out rather than solved for: per axis the AR centres are ``lambda * u +
t + eta`` with ``u`` the aligned camera centres less the alignment's translation, ``lambda``
the relative scale (1 at the fit) and ``eta`` Gaussian with covariance ``q**2 min(e_i, e_j) +
j**2 [i = j]`` (``e``: when the frame was taken, as a share of the recording, ``q``: the drift
at its end, ``j``: jitter). The Fisher information of (lambda, t) gives lambda's variance.
This is the same model as the fit, written another way, so a test can check one against the
other by simulation. Volume scales with the cube of the scale, so a length uncertainty of
0.3 % is about 0.9 % of volume.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import solve_triangular

from volec.sfm import TIME_FLOOR, SfmConfig, SfmResult
from volec.space import VolumeBounds


def drift_scale_std(centres_m: np.ndarray, times: np.ndarray, jitter_m: float,
                    drift_m_per_sqrt_time: float) -> float:
    """Standard deviation of the relative scale fitted to AR camera centres (N, 3) that lie at
    ``centres_m`` (relative to the alignment's translation, metres) and were recorded at
    ``times`` (N,), in order, under the AR noise model in the module docstring.

    A capture with the cameras all in one place has no scale to fit: infinity."""
    centres = np.asarray(centres_m, float)
    times = np.maximum(np.asarray(times, float), TIME_FLOOR)  # as the fit pins time 0
    covariance = drift_m_per_sqrt_time**2 * np.minimum.outer(times, times)
    covariance[np.diag_indices_from(covariance)] += jitter_m**2
    # Cholesky solves, not an inverse: the random walk's covariance is badly conditioned
    # over a long capture.
    factor = np.linalg.cholesky(covariance)
    whitened = solve_triangular(factor, np.column_stack([centres, np.ones(len(centres))]),
                                lower=True)
    w_centres, w_ones = whitened[:, :3], whitened[:, 3]
    # The Fisher information of (scale, translation) is [[a, b^T], [b, c I]]; the scale's
    # variance is the inverse of its Schur complement a - b.b / c.
    a = float(np.sum(w_centres * w_centres))
    b = w_centres.T @ w_ones
    complement = a - float(b @ b) / float(w_ones @ w_ones)
    if complement <= 1e-12 * a:
        return math.inf
    return 1.0 / math.sqrt(complement)


def sfm_scale_std(sfm: SfmResult, cfg: SfmConfig) -> float:
    """:func:`drift_scale_std` of the scale ``sfm`` took from the AR poses, with ``cfg``'s AR
    noise model (``ar_jitter_m``, ``ar_drift_m``): the registered frames' refined centres, in
    the world frame less the alignment's translation, at the times the fit used
    (:attr:`~volec.sfm.SfmResult.elapsed_shares`)."""
    registered = np.flatnonzero(sfm.registered)
    centres = sfm.T_world_from_cam[registered, :3, 3] - sfm.world_from_model[:3, 3]
    return drift_scale_std(centres, sfm.elapsed_shares[registered], cfg.ar_jitter_m,
                           cfg.ar_drift_m)


def volume_interval(bounds: VolumeBounds, scale_std: float, sigmas: float
                    ) -> tuple[float, float]:
    """(low, high) mL: ``bounds`` with each end moved outwards by ``sigmas`` standard
    deviations ``scale_std`` (a fraction) of the metric scale, cubed. An unknown scale
    uncertainty (NaN) leaves the bounds as they are."""
    if math.isnan(scale_std):
        return bounds.low_ml, bounds.high_ml
    shrink = max(1.0 - sigmas * scale_std, 0.0) ** 3
    return bounds.low_ml * shrink, bounds.high_ml * (1.0 + sigmas * scale_std) ** 3
