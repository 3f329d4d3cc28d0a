import math

import numpy as np
import pytest

from volec.geometry import make_transform, rotvec_to_matrix
from volec.scale_uncertainty import drift_scale_std, sfm_scale_std, volume_interval
from volec.sfm import SfmConfig, SfmResult, drift_model_alignment
from volec.space import VolumeBounds

JITTER_M, DRIFT_M = 0.0003, 0.0005


def _orbit(n: int, radius_m: float) -> np.ndarray:
    t = np.arange(n) / n
    return np.stack([radius_m * np.cos(2 * np.pi * t), radius_m * np.sin(2 * np.pi * t),
                     0.12 + 0.03 * np.sin(3 * np.pi * t)], axis=1)


@pytest.mark.parametrize("n, radius_m", [(60, 0.25), (30, 0.15)])
def test_the_scale_std_is_the_spread_of_the_drift_models_fitted_scale(n, radius_m):
    # AR centres drawn from the model itself (a random walk from frame 0 plus jitter) around
    # a known orbit: the generalised least squares fit of volec.sfm scatters its scale by
    # the standard deviation predicted here, by integrating the drift out instead.
    rng = np.random.default_rng(11)
    truth = _orbit(n, radius_m)
    R = rotvec_to_matrix(np.array([0.3, -0.2, 0.4]))
    model = truth @ R / 0.07  # the model frame: rotated, 1/0.07 units per metre
    ratios = []
    for _ in range(150):
        walk = np.cumsum(rng.normal(scale=DRIFT_M, size=(n, 3)), axis=0)
        walk[0] = rng.normal(scale=DRIFT_M * 1e-3, size=3)
        ar = truth + walk + rng.normal(scale=JITTER_M, size=(n, 3))
        s, _, _ = drift_model_alignment(model, ar, np.arange(n), R, JITTER_M, DRIFT_M)
        ratios.append(s / 0.07 - 1)
    predicted = drift_scale_std(truth, np.arange(n), JITTER_M, DRIFT_M)
    assert 0.0005 < predicted < 0.02
    assert np.std(ratios) == pytest.approx(predicted, rel=0.2)  # 150 draws: about 6 %
    assert abs(np.mean(ratios)) < 3 * predicted / np.sqrt(150)  # and it is unbiased


def test_the_scale_is_as_uncertain_as_the_orbit_is_small_and_unknowable_without_one():
    frames = np.arange(60)
    wide = drift_scale_std(_orbit(60, 0.3), frames, JITTER_M, DRIFT_M)
    narrow = drift_scale_std(_orbit(60, 0.15), frames, JITTER_M, DRIFT_M)
    # the drift is the same in metres, so half the orbit's size doubles the relative error
    # (within the part the orbit's height adds)
    assert 1.6 * wide < narrow < 2.1 * wide
    assert drift_scale_std(np.zeros((10, 3)), np.arange(10), JITTER_M, DRIFT_M) == math.inf


def test_sfm_scale_std_takes_the_registered_centres_less_the_alignments_translation():
    n = 50
    truth = _orbit(n, 0.2)
    translation = np.array([1.0, -2.0, 0.5])
    poses = np.stack([make_transform(np.eye(3), c + translation) for c in truth])
    registered = np.ones(n, bool)
    registered[[3, 17]] = False
    world_from_model = make_transform(0.05 * np.eye(3), translation)
    sfm = SfmResult([f"f{i}" for i in range(n)], poses, registered, np.zeros((0, 3)),
                    np.zeros((0, 3), np.uint8), world_from_model)
    kept = np.flatnonzero(registered)
    assert sfm_scale_std(sfm, SfmConfig()) == pytest.approx(
        drift_scale_std(truth[kept], kept, SfmConfig().ar_jitter_m,
                        SfmConfig().ar_drift_m_per_sqrt_frame), rel=1e-12)


def test_the_volume_interval_widens_the_bounds_by_the_cube_of_the_scale():
    bounds = VolumeBounds(90.0, 110.0, unknown_share=0.1, empty_share=0.0, high_open=False)
    low, high = volume_interval(bounds, 0.01, 2.0)
    assert low == pytest.approx(90.0 * 0.98**3) and high == pytest.approx(110.0 * 1.02**3)
    assert volume_interval(bounds, math.nan, 2.0) == (90.0, 110.0)
    assert volume_interval(bounds, 0.7, 2.0)[0] == 0.0  # never below nothing
    assert volume_interval(bounds, math.inf, 2.0) == (0.0, math.inf)
