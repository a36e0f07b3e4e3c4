"""The appearance benchmark: its scores on hand-made inputs, its options, a quick run."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from localization.cli._args import UsageError
from localization.cli.bench import Args, check
from localization.workflows.benchmarks import BENCHMARKS, benchmark
from localization.workflows.benchmarks.appearance import (
    AppearanceBenchConfig,
    localizer_params,
    run_appearance_bench,
    single_image_scores,
    training_looks,
)
from localization.workflows.benchmarks.appearance_report import single_target


class Fixed:
    """A 'localizer' whose psi* returns given poses."""

    def __init__(self, pred):
        self.pred = np.asarray(pred, dtype=float)

    def predict(self, images, verify=0, verify_margin=3.0, turns=0):
        return self.pred


def test_single_image_scores_use_both_thresholds_and_count_misses():
    truth = np.zeros((5, 3))
    pred = np.array([[0.2, 0, np.radians(1.0)],   # within all three
                     [0.2, 0, np.radians(3.0)],   # heading too far for (0.25 m, 2 deg)
                     [0.4, 0, 0.0],               # (0.5 m, 5 deg) and (5 m, 10 deg)
                     [4.0, 0, np.radians(9.0)],   # (5 m, 10 deg) only
                     [np.nan, np.nan, np.nan]])   # outside the domain: a miss
    s = single_image_scores(Fixed(pred), None, truth)
    assert s["within"] == pytest.approx([0.2, 0.6, 0.8])
    assert math.isinf(s["pos_err"][4])


def test_only_the_randomised_map_follows_randomised_map():
    """(map looks, noise-drive looks): the noise of the randomised localizer is always learnt
    under randomised conditions, the daylight one never leaves daylight."""
    assert training_looks("daylight", "random") == ("default", "default")
    assert training_looks("randomised", "default") == ("default", "random")
    assert training_looks("randomised", "random") == ("random", "random")
    assert training_looks("randomised", "experiences") == ("experiences", "random")


@pytest.mark.parametrize("flag", [False, True])
def test_calibrate_on_belief_reaches_the_fit(monkeypatch, flag):
    """--appearance-calibrate-on-belief is what fit_city_localizer gets (default off)."""
    from localization.workflows.benchmarks import appearance

    seen = {}

    class Env:
        def close(self):
            pass

    def fake_fit(env, **kwargs):
        seen.update(kwargs)
        return "loc", {}

    monkeypatch.setattr(appearance, "fit_city_localizer", fake_fit)
    assert AppearanceBenchConfig().calibrate_on_belief is False
    args = AppearanceBenchConfig(calibrate_on_belief=flag)
    monkeypatch.setattr(appearance, "make_env", lambda args, city, c: Env())
    assert appearance.fit(args, 11, "daylight") == "loc"
    assert seen["calibrate_on_belief"] is flag


def test_heteroscedastic_noise_fits_the_folds_and_reaches_the_drives(monkeypatch):
    """--appearance-noise heteroscedastic: the localizers get K-fold residuals (R(theta, w)
    needs them) and the closed loop's belief uses that R."""
    from localization.workflows.benchmarks import appearance
    from localization.wrappers import FILTER_OPTIONS

    assert "noise_folds" not in localizer_params(AppearanceBenchConfig())  # the global R
    assert AppearanceBenchConfig().noise_of("randomised") == ("global", False, False)
    daylight = AppearanceBenchConfig(noise="heteroscedastic", measurement_bias=True,
                                     noise_trainings="daylight")
    assert localizer_params(daylight, "daylight")["noise_folds"] == 5
    assert "noise_folds" not in localizer_params(daylight, "randomised")
    assert daylight.noise_of("daylight") == ("heteroscedastic", False, True)
    assert daylight.noise_of("randomised") == ("global", False, False)
    both = AppearanceBenchConfig(noise="heteroscedastic", adaptive_noise=True,
                                 measurement_bias=True)
    assert both.noise_of("randomised") == ("heteroscedastic", True, True)
    assert AppearanceBenchConfig(noise="heteroscedastic", noise_trainings="").noise_of(
        "daylight") == ("global", False, False)
    with pytest.raises(ValueError, match="noise_trainings.*daylght"):
        AppearanceBenchConfig(noise_trainings="daylght").noise_of("randomised")
    assert "noise_folds" not in localizer_params(AppearanceBenchConfig(noise="global"))
    args = AppearanceBenchConfig(noise="heteroscedastic")
    assert localizer_params(args)["noise_folds"] == 5
    seen = {}

    def fake_track(env, loc, measurement, steps, **kwargs):
        seen.update(kwargs)
        raise RuntimeError("stop here")

    monkeypatch.setattr(appearance, "track_route", fake_track)
    with pytest.raises(RuntimeError, match="stop here"):
        appearance.closed_loop(None, None, "route", 10, 0, 1, args.noise)
    assert seen["filter_options"] == {"noise": "heteroscedastic", "adaptive_noise": False,
                                      "measurement_bias": False, "novelty_noise": False}
    assert set(seen["filter_options"]) <= set(FILTER_OPTIONS["ekf"])  # the wrapper takes it
    with pytest.raises(RuntimeError, match="stop here"):  # --appearance-adaptive-noise
        appearance.closed_loop(None, None, "route", 10, 0, 1, "global", True)
    assert seen["filter_options"] == {"noise": "global", "adaptive_noise": True,
                                      "measurement_bias": False, "novelty_noise": False}
    with pytest.raises(RuntimeError, match="stop here"):  # --appearance-measurement-bias
        appearance.closed_loop(None, None, "route", 10, 0, 1, "global", False, True)
    assert seen["filter_options"]["measurement_bias"] is True
    assert "familiar_novelty" not in seen["filter_options"]  # 0: off
    with pytest.raises(RuntimeError, match="stop here"):  # --appearance-familiar-novelty
        appearance.closed_loop(None, None, "route", 10, 0, 1, "global", False, False, 3.0)
    assert seen["filter_options"]["familiar_novelty"] == 3.0
    assert set(seen["filter_options"]) <= set(FILTER_OPTIONS["ekf"])
    with pytest.raises(RuntimeError, match="stop here"):  # --appearance-novelty-noise
        appearance.closed_loop(None, None, "route", 10, 0, 1, "global", novelty=True)
    assert seen["filter_options"]["novelty_noise"] is True
    assert AppearanceBenchConfig(novelty_noise="daylight").novelty_trainings() == ["daylight"]
    assert AppearanceBenchConfig().novelty_trainings() == []
    with pytest.raises(ValueError, match="novelty_noise.*randomised"):
        AppearanceBenchConfig(novelty_noise="daylight,randomised").novelty_trainings()


def test_experience_maps_are_daylight_and_a_draw_of_each_other_family():
    from localization.workflows.benchmarks.appearance import map_conditions

    assert map_conditions("default", 21) == ["default"]
    looks = map_conditions("experiences", 21)
    assert [c.name for c in looks] == ["default", "random:dusk", "random:night",
                                       "random:overcast", "random:fog"]
    assert looks == map_conditions("experiences", 21) != map_conditions("experiences", 22)


def test_targets_are_the_issues():
    assert single_target("daylight", "dusk") == (0.75, 0.90, 0.99)
    assert single_target("daylight", "night") == (0.50, 0.75, 0.95)
    assert single_target("daylight", "fog") is None
    assert single_target("randomised", "fog") == (0.80, 0.92, 0.99)


@pytest.mark.parametrize("field, value, option", [
    ("conditions", "default,dawn", "--appearance-conditions"),
    ("trainings", "daylight,nightly", "--appearance-trainings"),
    ("normalize", "gamma", "--appearance-normalize"),
    ("features", "resnet", "--appearance-features"),
    ("randomised_map", "dusk", "--appearance-randomised-map"),
    ("cities", "31,x", "--appearance-cities"),
    ("n_test", 0, "--appearance-n-test"),
    ("first_order", "backward", "--appearance-first-order"),
    ("forward_ridge", -0.1, "--appearance-forward-ridge"),
    ("noise", "robust", "--appearance-noise"),
    ("verify", -1, "--appearance-verify"),
    ("verify_margin", 0.5, "--appearance-verify-margin"),
    ("patch_floor", 0.0, "--appearance-patch-floor"),
    ("smooth", -1.0, "--appearance-smooth"),
    ("smooth_trainings", "nightly", "--appearance-smooth-trainings"),
    ("smooth", float("inf"), "--appearance-smooth"),
    ("map_camera", "lens", "--appearance-map-camera"),
    ("familiar_novelty", -1.0, "--appearance-familiar-novelty"),
    ("noise_trainings", "nightly", "--appearance-noise-trainings"),
    ("novelty_noise", "randomised", "--appearance-novelty-noise"),
])
def test_bad_options_are_named(field, value, option):
    args = Args(only="appearance", appearance=AppearanceBenchConfig(**{field: value}))
    with pytest.raises(UsageError, match=option):
        check(args)


def test_smooth_with_the_small_cnn_is_refused_not_ignored():
    args = Args(only="appearance",
                appearance=AppearanceBenchConfig(smooth=0.7, features="small_cnn"))
    with pytest.raises(UsageError, match="--appearance-smooth.*PixelPCA"):
        check(args)
    check(Args(only="appearance", appearance=AppearanceBenchConfig(smooth=0.7)))


def test_registered_for_bench_only_appearance():
    config, run = benchmark("appearance")
    assert "appearance" in BENCHMARKS
    assert config is AppearanceBenchConfig and run is run_appearance_bench


def test_quick_run_end_to_end(tmp_path: Path):
    run_appearance_bench(AppearanceBenchConfig(quick=True, conditions="default,traffic",
                                               out_dir=str(tmp_path)))
    saved = json.loads((tmp_path / "bench_appearance.json").read_text())
    table = (tmp_path / "bench_appearance.md").read_text()
    assert saved["trainings"] == ["daylight", "randomised"]
    assert saved["args"]["randomised_map"] == "experiences"  # one map per look (stop 66)
    assert "map images per look" in saved["setup"]
    assert saved["versions"]["numpy"] == np.__version__  # the result names its libraries
    for t in saved["trainings"]:
        for c in ("default", "traffic"):
            s = saved["summary"][t][c]
            assert s["n_images"] == 30 and s["drives"] == 1
            assert all(0.0 <= v <= 1.0 for v in s["within"])
            assert s["within"] == sorted(s["within"])  # looser thresholds, more images
            assert math.isfinite(s["rmse"]) and s["rmse"] > 0
            assert f"| {t} | {c} |" in table
        assert saved["summary"][t]["default"]["occluded_frames"] == 0.0
        assert saved["summary"][t]["traffic"]["occluded_frames"] > 0.0  # movers were seen
    assert "Aachen Day-Night" in table


def test_quick_run_on_the_condition_randomised_small_cnn(tmp_path: Path):
    run_appearance_bench(AppearanceBenchConfig(quick=True, trainings="daylight",
                                               features="small_cnn", out_dir=str(tmp_path)))
    saved = json.loads((tmp_path / "bench_appearance.json").read_text())
    assert "SmallCNN (condition-randomised" in saved["setup"]
    s = saved["summary"]["daylight"]["default"]
    assert s["n_images"] == 30 and s["within"] == sorted(s["within"])
    assert math.isfinite(s["rmse"]) and s["rmse"] > 0


def test_quick_run_on_the_heteroscedastic_noise(tmp_path: Path):
    """The K-fold noise model is fitted and the drives run on R(theta, w)."""
    result = run_appearance_bench(AppearanceBenchConfig(
        quick=True, trainings="daylight", noise="heteroscedastic", out_dir=str(tmp_path)))
    assert result["fit_failures"] == {}
    assert "heteroscedastic R" in result["setup"]
    for c in result["conditions"]:
        s = result["summary"]["daylight"][c]
        assert s["drives"] == 1 and math.isfinite(s["rmse"]) and math.isfinite(s["nees_mean"])


def test_patch_floor_reaches_the_pixel_pca_of_patches_only():
    from localization.workflows.benchmarks.appearance import features_label, localizer_params

    args = AppearanceBenchConfig(patch_floor=0.02)
    assert localizer_params(args)["features_params"]["patch_floor"] == 0.02
    assert "patch_floor=0.02" in features_label(args)
    plain = AppearanceBenchConfig(normalize="channels", patch_floor=0.02)
    assert "patch_floor" not in localizer_params(plain)["features_params"]


def test_smooth_reaches_the_pixel_pca_only_when_on():
    from localization.workflows.benchmarks.appearance import features_label, localizer_params

    on = AppearanceBenchConfig(smooth=0.8)
    assert localizer_params(on)["features_params"]["smooth"] == 0.8
    assert "smooth=0.8" in features_label(on)
    off = AppearanceBenchConfig()
    assert "smooth" not in localizer_params(off)["features_params"]
    assert "smooth" not in features_label(off)
    one = AppearanceBenchConfig(smooth=0.8, smooth_trainings="randomised")
    assert "smooth" not in localizer_params(one, "daylight")["features_params"]
    assert localizer_params(one, "randomised")["features_params"]["smooth"] == 0.8
    assert "smooth=0.8 (randomised)" in features_label(one)


def test_map_camera_random_draws_each_map_image_its_camera():
    from localization.workflows.benchmarks.appearance import map_conditions

    looks = map_conditions("experiences", 21)
    assert map_conditions("experiences", 21, "random") == [
        {"preset": c, "camera": "random"} for c in looks]
    assert map_conditions("default", 21, "random") == [{"preset": "default", "camera": "random"}]
    args = Args(only="appearance", appearance=AppearanceBenchConfig(
        map_camera="random", randomised_map="random"))
    with pytest.raises(UsageError, match="--appearance-map-camera"):
        check(args)
