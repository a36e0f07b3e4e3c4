"""Test-time turns (localization.turned_views): the shifted views, the median position, and
``predict(turns=...)`` on the shared test localizer."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from localization.turned_views import (
    check_turn_camera,
    median_position,
    turned_prediction,
    turned_view,
)


def _images() -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.integers(0, 256, (2, 4, 6, 3), dtype=np.uint8)


def test_turned_view_shifts_columns_and_repeats_the_edge():
    im = _images()
    right = turned_view(im, 2)
    assert right.shape == im.shape and right.dtype == np.uint8
    assert np.array_equal(right[:, :, 2:], im[:, :, :-2])
    assert np.array_equal(right[:, :, 0], im[:, :, 0]) and np.array_equal(right[:, :, 1], im[:, :, 0])
    left = turned_view(im, -1)
    assert np.array_equal(left[:, :, :-1], im[:, :, 1:])
    assert np.array_equal(left[:, :, -1], im[:, :, -1])
    assert turned_view(im, 0) is im


def test_turned_view_rejects_bad_shifts():
    with pytest.raises(ValueError, match="pixels"):
        turned_view(_images(), 6)
    with pytest.raises(TypeError, match="pixels"):
        turned_view(_images(), 1.5)


def test_median_position_ignores_views_out_of_the_domain():
    views = np.array([[[0.0, 0.0, 0.1], [np.nan, np.nan, np.nan]],
                      [[1.0, 2.0, 0.2], [np.nan, np.nan, np.nan]],
                      [[np.nan, np.nan, np.nan], [np.nan, np.nan, np.nan]],
                      [[3.0, -2.0, 0.3], [np.nan, np.nan, np.nan]]])
    out = median_position(views)
    assert np.allclose(out[0], [1.0, 0.0])
    assert np.all(np.isnan(out[1]))


def test_turned_prediction_keeps_the_heading_and_the_domain():
    """A fake psi*: the position is the image's mean brightness, so turned views move it;
    the result is the median over the views, the heading the unshifted image's."""
    im = _images()

    def predict(views: np.ndarray) -> np.ndarray:
        m = views.reshape(len(views), -1).mean(axis=1)
        out = np.column_stack([m, -m, np.full(len(m), 0.5)])
        out[1] = np.nan  # the second image is out of the domain
        return out

    got = turned_prediction(predict, im, 1)
    views = np.stack([predict(im), predict(turned_view(im, -1)), predict(turned_view(im, 1))])
    assert np.allclose(got[0, :2], np.median(views[:, 0, :2], axis=0))
    assert got[0, 2] == 0.5
    assert np.all(np.isnan(got[1]))
    assert np.array_equal(turned_prediction(predict, im, 0), predict(im), equal_nan=True)


def test_turns_need_a_perspective_camera():
    check_turn_camera("perspective")
    check_turn_camera(None)
    with pytest.raises(ValueError, match="turns"):
        check_turn_camera("fisheye")


def test_predict_with_turns(localizer, lane_data):
    images = lane_data[0][:40]
    plain = localizer.predict(images)
    turned = localizer.predict(images, turns=1)
    assert np.array_equal(np.isnan(plain), np.isnan(turned))
    assert np.array_equal(plain[:, 2], turned[:, 2], equal_nan=True)
    live = np.isfinite(plain).all(axis=1)
    views = np.stack([plain] + [localizer.predict(turned_view(images, s)) for s in (-1, 1)])
    want = np.nanmedian(views[:, live, :2], axis=0)
    assert np.allclose(turned[live, :2], want)
    assert not np.allclose(turned[live, :2], plain[live, :2])  # the views do move it
    with pytest.raises(ValueError, match="turns"):
        localizer.predict(images, turns=-1)
    fisheye = copy.copy(localizer)
    fisheye.camera_ = "fisheye"
    with pytest.raises(ValueError, match="turns"):
        fisheye.predict(images, turns=1)
