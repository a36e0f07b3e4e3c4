"""Camera masks and the extractor factory of the paper's experiment."""

from __future__ import annotations

import numpy as np
import pytest

from localization.workflows.camera_masks import elevation_map, ground_mask
from localization.workflows.extractors import make_extractor


def test_perspective_elevation_rises_up_the_image() -> None:
    el = elevation_map("perspective", 32)
    assert el.shape == (32, 32)
    assert np.all(np.diff(el[:, 16]) < 0)  # row 0 is the top of the image
    assert el[0, 16] > 0 > el[-1, 16]


def test_ground_mask_hides_the_near_ground_only() -> None:
    mask = ground_mask("perspective", 32, 3.0)
    assert mask.dtype == bool
    assert mask[0].all() and not mask[-1].any()
    assert ground_mask("perspective", 32, 30.0).sum() < mask.sum()


def test_unknown_extractor_is_named() -> None:
    with pytest.raises(ValueError, match="sift"):
        make_extractor("sift", "perspective", "route", 8, 32)


def test_pixel_smooth_reaches_both_pixel_pca_rows_only() -> None:
    plain = make_extractor("pixel_pca", "perspective", "route", 8, 32, smooth=0.7)
    masked = make_extractor("pixel_pca_masked", "perspective", "route", 8, 32, smooth=0.7)
    assert plain.smooth == masked.smooth == 0.7
    assert masked.mask is not None
    assert make_extractor("pixel_pca", "perspective", "route", 8, 32).smooth == 0.0
