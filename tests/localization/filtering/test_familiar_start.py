"""BeliefFilter(familiar_novelty=...): a start from an unfamiliar image is checked against the
first familiar one; every other restart waits for a familiar image."""

from __future__ import annotations

import numpy as np
import pytest

from envs.motion_model import UnicycleModel
from localization.filtering import BeliefFilter
from localization.filtering.ekf import FunctionMeasurement
from localization.filtering.familiar_start import start_agrees

P0 = 0.01 * np.eye(3)


class _RatedMaps:
    """A localizer whose image features are [psi* (3), relative novelty]: the "pose" model
    measures psi* with R = 0.01 I, and ``initial_candidate`` rates the image."""

    control_gain_ = np.ones(2)

    def consistency(self, measurement):
        return np.ones(3)

    def measurement_model(self, measurement, alpha=None, **options):
        return FunctionMeasurement(h=lambda x: x, H=lambda x: np.eye(3), R=0.01 * np.eye(3))

    def process_noise(self, pose, alpha=None):
        return 1e-6 * np.eye(3)

    def initial_belief(self, w):
        return np.asarray(w[:3], float), P0.copy()

    def initial_candidate(self, w):
        return np.asarray(w[:3], float), P0.copy(), float(w[3])

    def prior(self):
        return np.zeros(3), np.eye(3)

    def measure(self, w, measurement):
        return np.asarray(w[:3], float)


class _UnratedMaps(_RatedMaps):
    initial_candidate = None


def _image(x, y, novelty):
    return np.array([x, y, 0.0, novelty])


def _belief(**options):
    return BeliefFilter(_RatedMaps(), UnicycleModel(0.1), measurement="pose",
                        inflate_after=None, **options)


def test_an_unfamiliar_start_gives_way_to_a_familiar_image_elsewhere():
    # the first image is a look-alike 8 m away (novelty 13); the next one is familiar
    for option, expected in ((None, [8.0, 0.0]), (3.0, [0.0, 0.0])):
        belief = _belief(familiar_novelty=option)
        assert belief.reset(_image(8.0, 0.0, 13.0)) == "initial"
        np.testing.assert_allclose(belief.x[:2], [8.0, 0.0])
        _, status = belief.step(np.zeros(2), _image(0.0, 0.0, 1.5))
        assert status == ("gated" if option is None else "relocalized")
        np.testing.assert_allclose(belief.x[:2], expected, atol=1e-9)
        if option is not None:
            assert belief.belief_status == "relocalizing"


def test_a_familiar_image_that_agrees_verifies_the_start():
    belief = _belief(familiar_novelty=3.0)
    belief.reset(_image(8.0, 0.0, 13.0))
    assert belief.step(np.zeros(2), _image(8.05, 0.0, 1.5))[1] == "accepted"
    # verified: a later familiar image elsewhere is gated as any other, not a restart
    assert belief.step(np.zeros(2), _image(0.0, 0.0, 1.5))[1] == "gated"
    assert belief.x[0] == pytest.approx(8.0, abs=0.1)


def test_a_familiar_first_image_is_not_checked_again():
    belief = _belief(familiar_novelty=3.0)
    belief.reset(_image(8.0, 0.0, 2.0))
    assert belief.step(np.zeros(2), _image(0.0, 0.0, 1.5))[1] == "gated"


def test_a_restart_after_misses_waits_for_a_familiar_image():
    for option, restart_at in ((None, 2), (3.0, 4)):
        belief = _belief(familiar_novelty=option, relocalize_after=2)
        belief.reset(_image(0.0, 0.0, 1.0))
        statuses = [belief.step(np.zeros(2), _image(5.0, 0.0, 9.0))[1] for _ in range(3)]
        statuses.append(belief.step(np.zeros(2), _image(5.0, 0.0, 2.0))[1])
        assert statuses.index("relocalized") + 1 == restart_at
        assert belief.x[0] == pytest.approx(5.0, abs=1e-9)


def test_start_agrees_is_the_gate_on_psi_and_the_belief():
    P = np.diag([0.04, 0.04, 0.01])
    x = np.array([1.0, 2.0, np.pi - 0.01])
    assert start_agrees(x, P, np.array([1.1, 2.0, -np.pi + 0.01]), P0, 0.997)  # yaw wrapped
    far = np.array([2.0, 2.0, np.pi])  # d^2 = 1 / 0.05 = 20: outside chi2_3(0.997) = 13.9
    assert not start_agrees(x, P, far, P0, 0.997)
    assert start_agrees(x, P, far, P0, 1 - 1e-9)  # chi2_3 = 44
    assert not start_agrees(x, P, far, P0, None)  # no NIS gate: AGREE_PROBABILITY


def test_bad_familiar_novelty_is_named():
    with pytest.raises(ValueError, match="familiar_novelty"):
        _belief(familiar_novelty=0.0)
    with pytest.raises(ValueError, match="familiar_novelty"):
        _belief(familiar_novelty=float("nan"))
    with pytest.raises(TypeError, match="familiar_novelty.*_UnratedMaps"):
        BeliefFilter(_UnratedMaps(), UnicycleModel(0.1), measurement="pose",
                     familiar_novelty=3.0)


def test_a_failed_start_restarts_only_at_a_familiar_image():
    # a start whose next TRIAL_STEPS views are all gated fails its trial; without the option
    # the belief restarts at the current image, with it only if that image is familiar
    from localization.filtering.restart_trial import TRIAL_STEPS

    u = np.array([0.5, 0.0])  # 0.05 m a step: every view counts
    for option, novelty, expected in ((None, 9.0, "relocalized"), (3.0, 9.0, "gated"),
                                      (3.0, 2.0, "relocalized")):
        belief = _belief(familiar_novelty=option)
        belief.reset(_image(0.0, 0.0, 1.0))
        statuses = [belief.step(u, _image(5.0, 0.0, novelty))[1] for _ in range(TRIAL_STEPS)]
        assert statuses[:-1] == ["gated"] * (TRIAL_STEPS - 1)
        assert statuses[-1] == expected
        assert (belief.x[0] > 4.0) == (expected == "relocalized")
