"""BeliefFilter(heading_check=...): a representation update that turns the heading away from
the image's own psi* is undone; an image without psi* is out of domain."""

from __future__ import annotations

import numpy as np
import pytest

from envs.motion_model import UnicycleModel
from localization.filtering import BeliefFilter
from localization.filtering.ekf import FunctionMeasurement
from localization.filtering.heading_check import check_heading_check, turns_away

A = np.array([[1.0, 0.0, 2.0],  # the representation reads a turn like an along-track offset
              [0.0, 1.0, 0.0],
              [0.0, 0.0, 0.1]])


class _SkewedMaps:
    """A localizer whose representation R*(x) = A x confounds heading with along-track
    position and sees the heading itself only faintly (as R* does where it is poorly
    conditioned), while psi* reads the pose itself.
    An image's features are [r* (3), psi* (3)]."""

    control_gain_ = np.ones(2)

    def consistency(self, measurement):
        return np.ones(3)

    def measurement_model(self, measurement, alpha=None, **options):
        return FunctionMeasurement(h=lambda x: A @ x, H=lambda x: A, R=np.diag([1e-4, 1e-4, 1e-2]))

    def process_noise(self, pose, alpha=None):
        return 1e-6 * np.eye(3)

    def initial_belief(self, w):
        return np.asarray(w[3:6], float), 1e-2 * np.eye(3)

    def prior(self):
        return np.zeros(3), np.eye(3)

    def measure(self, w, measurement):
        return np.asarray(w[:3] if measurement == "representation" else w[3:6], float)


def _one_step(w, **options):
    """Prior at the origin, heading 0 +- 0.5 rad, position +- 0.1 m; one image ``w``."""
    belief = BeliefFilter(_SkewedMaps(), UnicycleModel(0.1), inflate_after=None, **options)
    belief.reset(w, x0=np.zeros(3), P0=np.diag([0.01, 0.01, 0.25]))
    _, status = belief.step(np.zeros(2), w)
    return belief.x, status


def test_an_update_that_turns_away_from_psi_is_undone():
    # the robot is 1 m ahead on the same heading: r* = A [1, 0, 0], psi* = [1, 0, 0]
    w = np.array([1.0, 0.0, 0.0, 1.0, 0.0, 0.0])
    x_plain, status_plain = _one_step(w)
    assert status_plain == "accepted" and abs(x_plain[2]) > 0.3  # read as a turn
    x, status = _one_step(w, heading_check=0.05)
    assert status == "gated"
    np.testing.assert_allclose(x, np.zeros(3), atol=1e-12)  # the prior, unchanged


def test_an_update_towards_psi_stands():
    # the robot turned by 0.2 rad in place: r* = A [0, 0, 0.2], psi* agrees
    w = np.concatenate([A @ [0.0, 0.0, 0.2], [0.0, 0.0, 0.2]])
    x_plain, _ = _one_step(w)
    x, status = _one_step(w, heading_check=0.05)
    assert status == "accepted"
    np.testing.assert_allclose(x, x_plain)
    assert x[2] == pytest.approx(0.2, abs=0.02)


def test_an_image_without_psi_is_out_of_domain():
    w = np.array([0.1, 0.0, 0.0, np.nan, np.nan, np.nan])
    assert _one_step(w)[1] == "accepted"
    x, status = _one_step(w, heading_check=0.05)
    assert status == "out_of_domain"
    np.testing.assert_allclose(x, np.zeros(3), atol=1e-12)


@pytest.mark.parametrize(("before", "after", "psi", "away"), [
    (0.0, 0.2, 0.0, True), (0.2, 0.0, 0.0, False), (0.0, 0.04, 0.0, False),
    (3.1, -3.1, 3.1, True),  # across +-pi: 0.08 rad further, not 6.2
    (3.1, -3.16, 3.1, False)])
def test_turns_away_wraps_the_heading(before, after, psi, away):
    assert turns_away(before, after, psi, 0.05) is away


def test_bad_heading_check_is_named():
    assert check_heading_check(None, "pose") is None
    with pytest.raises(ValueError, match="heading_check"):
        check_heading_check(-0.1, "representation")
    with pytest.raises(ValueError, match="heading_check.*'pose'"):
        BeliefFilter(_SkewedMaps(), UnicycleModel(0.1), measurement="pose", heading_check=0.05)
