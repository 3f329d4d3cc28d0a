import math
from dataclasses import replace

import numpy as np
import pytest

from volec.geometry import make_transform, rotvec_to_matrix
from volec.scale_uncertainty import drift_scale_std, sfm_scale_std, volume_interval
from volec.sfm import SfmConfig, SfmResult, drift_model_alignment
from volec.space import VolumeBounds

JITTER_M, DRIFT_M = 0.0003, 0.005  # DRIFT_M: the drift's deviation at the recording's end


def _orbit(n: int, radius_m: float) -> np.ndarray:
    t = np.arange(n) / n
    return np.stack([radius_m * np.cos(2 * np.pi * t), radius_m * np.sin(2 * np.pi * t),
                     0.12 + 0.03 * np.sin(3 * np.pi * t)], axis=1)


def _fitted_scale_spread(truth: np.ndarray, kept: np.ndarray, draws: int, seed: int
                         ) -> list[float]:
    """Relative scale errors of ``drift_model_alignment`` over ``draws`` simulated AR drifts of
    a recording of ``len(truth)`` frames (a random walk from its first frame plus jitter), fitted
    on the frames ``kept`` at their times in the recording."""
    rng = np.random.default_rng(seed)
    n = len(truth)
    shares = np.arange(n) / (n - 1)
    R = rotvec_to_matrix(np.array([0.3, -0.2, 0.4]))
    model = truth[kept] @ R / 0.07  # the model frame: rotated, 1/0.07 units per metre
    ratios = []
    for _ in range(draws):
        steps = rng.normal(size=(n, 3)) * DRIFT_M * np.sqrt(np.diff(shares, prepend=0.0))[:, None]
        ar = truth + np.cumsum(steps, axis=0) + rng.normal(scale=JITTER_M, size=(n, 3))
        s, _, _ = drift_model_alignment(model, ar[kept], shares[kept], R, JITTER_M, DRIFT_M)
        ratios.append(s / 0.07 - 1)
    return ratios


@pytest.mark.parametrize("n, radius_m, rule", [(60, 0.25, "all"), (30, 0.15, "all"),
                                               (90, 0.2, "every third"),
                                               (90, 0.2, "first half")])
def test_the_scale_std_is_the_spread_of_the_drift_models_fitted_scale(n, radius_m, rule):
    # AR centres drawn from the model itself around a known orbit: the generalised least
    # squares fit of volec.sfm scatters its scale by the standard deviation predicted here, by
    # integrating the drift out instead; on a subset of the frames too, at their times in the
    # recording.
    truth = _orbit(n, radius_m)
    kept = {"all": np.arange(n), "every third": np.arange(0, n, 3),
            "first half": np.arange(n // 2)}[rule]
    ratios = _fitted_scale_spread(truth, kept, draws=150, seed=11)
    predicted = drift_scale_std(truth[kept], kept / (n - 1), JITTER_M, DRIFT_M)
    assert 0.0005 < predicted < 0.02
    assert np.std(ratios) == pytest.approx(predicted, rel=0.2)  # 150 draws: about 6 %
    assert abs(np.mean(ratios)) < 3 * predicted / np.sqrt(150)  # and it is unbiased


def test_a_subset_renumbered_as_a_recording_of_its_own_misjudges_the_drift():
    # The first half of an orbit spans half the recording's drift: timed as if it were a
    # whole recording, the same fit's scale is predicted to scatter far more than it does.
    n = 90
    truth = _orbit(n, 0.2)
    kept = np.arange(n // 2)
    spread = np.std(_fitted_scale_spread(truth, kept, draws=150, seed=12))
    renumbered = drift_scale_std(truth[kept], kept / (len(kept) - 1), JITTER_M, DRIFT_M)
    assert renumbered > 1.25 * spread  # 1.42 times


def test_the_scale_is_as_uncertain_as_the_orbit_is_small_and_unknowable_without_one():
    frames = np.arange(60) / 59
    wide = drift_scale_std(_orbit(60, 0.3), frames, JITTER_M, DRIFT_M)
    narrow = drift_scale_std(_orbit(60, 0.15), frames, JITTER_M, DRIFT_M)
    # the drift is the same in metres, so half the orbit's size doubles the relative error
    # (within the part the orbit's height adds)
    assert 1.6 * wide < narrow < 2.1 * wide
    assert drift_scale_std(np.zeros((10, 3)), np.arange(10) / 9, JITTER_M, DRIFT_M) == math.inf


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
    expected = drift_scale_std(truth[kept], kept / (n - 1), SfmConfig().ar_jitter_m,
                               SfmConfig().ar_drift_m)
    assert sfm_scale_std(sfm, SfmConfig()) == pytest.approx(expected, rel=1e-12)
    # a subset of a recording: the times the fit used, which its summary records
    shares = np.linspace(0.2, 0.6, n)
    timed = replace(sfm, summary={"frame_elapsed_shares": shares.tolist()})
    assert sfm_scale_std(timed, SfmConfig()) == pytest.approx(
        drift_scale_std(truth[kept], shares[kept], SfmConfig().ar_jitter_m,
                        SfmConfig().ar_drift_m), rel=1e-12)


def test_the_volume_interval_widens_the_bounds_by_the_cube_of_the_scale():
    bounds = VolumeBounds(90.0, 110.0, unknown_share=0.1, empty_share=0.0, high_open=False)
    low, high = volume_interval(bounds, 0.01, 2.0)
    assert low == pytest.approx(90.0 * 0.98**3) and high == pytest.approx(110.0 * 1.02**3)
    assert volume_interval(bounds, math.nan, 2.0) == (90.0, 110.0)
    assert volume_interval(bounds, 0.7, 2.0)[0] == 0.0  # never below nothing
    assert volume_interval(bounds, math.inf, 2.0) == (0.0, math.inf)
