"""The demo's kidnapping stage on the small shared localizer (city 0, 32 x 32)."""

from __future__ import annotations

import numpy as np
import pytest

from localization.workflows.kidnap_demo import kidnap_demo

from ..conftest import make_env


def test_kidnap_stage_writes_the_figure_and_measures_both_filters(localizer, tmp_path):
    env = make_env()
    try:
        out = kidnap_demo(env, localizer, tmp_path, seed=3, steps_before=40, steps_after=60)
    finally:
        env.close()
    assert (tmp_path / "kidnap.png").stat().st_size > 10_000
    assert out["kidnap_step"] == 41
    steps = out["steps_to_recover"]
    assert set(steps) == {"ekf", "ekf_detect", "particles"}
    # measured on this drive: particles 6 steps, the EKF with detection 10, without 46 (its
    # 50-step restart)
    assert steps["particles"] is not None and steps["particles"] <= 10, steps
    assert steps["ekf"] is None or steps["ekf"] > steps["particles"], steps
    assert steps["ekf_detect"] is not None and steps["ekf_detect"] < (steps["ekf"] or 99), steps
    # both filters start at the true pose and track the route lanes they were trained on
    assert all(np.isfinite(r) and r < 1.0 for r in out["rmse_before"].values()), out


def test_appearance_stage_drives_the_route_at_dusk_on_the_daylight_localizer(localizer,
                                                                              tmp_path):
    from localization.workflows.demo import DemoConfig, _appearance

    args = DemoConfig(image_size=32, motion_noise=0.05, steps=60, seed=3, dusk="dusk",
                      dusk_map=False, out=str(tmp_path))
    [row] = _appearance(args, localizer, tmp_path)
    assert (tmp_path / "track_dusk.png").stat().st_size > 10_000
    assert row["measurement"] == "representation, dusk" and row["steps"] == 60
    assert np.isfinite(row["rmse"]) and np.isfinite(row["rmse_dead_reckoning"])
    assert 0.0 <= row["accepted"] <= 1.0


@pytest.mark.filterwarnings("ignore::localization.workflows.quality.LocalizerQualityWarning")
def test_appearance_stage_also_drives_a_patch_normalised_route_map(localizer, tmp_path,
                                                                   monkeypatch):
    from localization.workflows import demo

    small = {"n_train": 800, "lanes": "route", "n_drive": 200,
             "localizer_params": {"features_params": {"n_components": 16,
                                                      "normalize": "patches"}}}
    monkeypatch.setattr(demo, "DUSK_MAP", small)
    args = demo.DemoConfig(image_size=32, motion_noise=0.05, steps=60, seed=3, dusk="night",
                           out=str(tmp_path))
    rows = demo._appearance(args, localizer, tmp_path)
    assert [r["measurement"] for r in rows] == [
        "representation, night",
        "representation, night (a daylight route map, patch-normalised)"]
    assert (tmp_path / "track_night_patches.png").stat().st_size > 10_000
    assert all(r["steps"] == 60 and np.isfinite(r["rmse"]) for r in rows)
