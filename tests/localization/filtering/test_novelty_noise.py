"""R scaled by the image's novelty: the scale, its settings, the reference a localizer keeps
from its noise drive, and a belief that trusts unfamiliar images less."""

from __future__ import annotations

import io

import numpy as np
import pytest

from localization.filtering.adaptive_noise import ScaledMeasurement
from localization.filtering.belief import BeliefFilter
from localization.filtering.ekf import PoseMeasurement
from localization.filtering.novelty_noise import NoveltyNoise, novelty_noise
from localization.localizer import AppearanceLocalizer

from ..conftest import make_env


class NormMap:
    """A stand-in localizer whose manifold is the origin (the novelty of w is |w|), made
    from frames of median novelty ``ref``."""

    def __init__(self, ref: float | None = 2.0) -> None:
        self.regressor_ = self
        self.novelty_ref_ = ref

    @staticmethod
    def novelty(W: np.ndarray) -> np.ndarray:
        return np.linalg.norm(W, axis=1)


def test_scale_is_the_squared_novelty_ratio_above_one_within_the_cap():
    noise, m = NoveltyNoise(), NormMap(ref=2.0)
    assert noise.scale_of(m, [1.0, 0.0]) == 1.0  # more familiar than the drive: R kept
    assert noise.scale_of(m, [2.0, 0.0]) == 1.0
    assert noise.scale_of(m, [0.0, 6.0]) == pytest.approx(9.0)  # (6 / 2) ** 2
    assert noise.scale_of(m, [100.0, 0.0]) == 100.0  # (50 ** 2) capped
    assert noise.scale_of(m, [np.nan, 0.0]) == 1.0  # out of the domain: no measurement anyway
    assert NoveltyNoise(power=1.0, max_scale=5.0).scale_of(m, [0.0, 6.0]) == pytest.approx(3.0)
    wrapped = noise.wrap(PoseMeasurement(np.eye(3)), m, [8.0, 0.0])
    assert isinstance(wrapped, ScaledMeasurement) and wrapped.scale == noise.scale == 16.0
    np.testing.assert_allclose(wrapped.R, 16.0 * np.eye(3))
    np.testing.assert_allclose(wrapped.gate_R(np.zeros(3)), np.eye(3))  # the gate: unscaled


def test_option_and_settings_are_checked():
    assert novelty_noise(False, object()) is None
    assert novelty_noise({"power": 1.5}, NormMap()).power == 1.5
    for bad in ({"power": 0.0}, {"power": -1.0}, {"max_scale": 0.5}):
        with pytest.raises(ValueError, match="power|max_scale"):
            novelty_noise(bad, NormMap())
    with pytest.raises(TypeError, match="novelty_noise"):
        novelty_noise({"bogus": 1}, NormMap())
    with pytest.raises(TypeError, match="novelty_noise"):
        novelty_noise("yes", NormMap())
    for ref in (None, 0.0, float("nan")):
        with pytest.raises(ValueError, match="novelty_ref_.*fit_noise"):
            novelty_noise(True, NormMap(ref))
    several = NormMap()
    several.local = lambda pose, w=None: NormMap()
    with pytest.raises(TypeError, match="novelty_noise needs a localizer of one map"):
        novelty_noise(True, several)


def test_the_noise_drive_sets_the_reference_and_a_file_keeps_it(localizer, features):
    W = features[0]
    u = localizer.regressor_.novelty(W)
    assert localizer.novelty_ref_ == pytest.approx(float(np.nanmedian(u)))
    buf = io.BytesIO()
    localizer.save(buf)
    buf.seek(0)
    assert AppearanceLocalizer.load(buf).novelty_ref_ == localizer.novelty_ref_


def test_a_belief_trusts_darker_images_less(localizer, drive):
    """On the drive's own frames about half keep R (the reference is their median); on the
    same frames a little darker the images are novel, and over the first 20 of them the
    belief with the option ends less certain than the plain filter."""
    images, poses, controls = drive
    motion = make_env().unwrapped.motion_model
    own = NoveltyNoise()
    scales = [own.scale_of(localizer, w) for w in localizer.transform(images)]
    assert 0.3 <= np.mean(np.array(scales) == 1.0) <= 0.7
    dark = localizer.transform((images[:21] * 0.9).astype(np.uint8))
    assert np.median([own.scale_of(localizer, w) for w in dark]) > 1.5
    P = {}
    for option in (False, True):
        belief = BeliefFilter(localizer, motion, novelty_noise=option, relocalize_after=None)
        _, covs, status = belief.run(dark, controls[:20], x0=poses[0],
                                     P0=np.diag([0.01, 0.01, 0.001]))
        assert status.count("accepted") >= 10
        P[option] = covs[-1]
    assert np.trace(P[True][:2, :2]) > 1.1 * np.trace(P[False][:2, :2])
