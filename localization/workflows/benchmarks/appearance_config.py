"""Settings of the appearance benchmark (:mod:`.appearance`): :class:`AppearanceBenchConfig`,
its localizers (``trainings``), the randomised localizer's map images and the feature
extractors it compares."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from envs.conditions import CAMERAS

__all__ = ["FEATURES", "MAP_CAMERAS", "RANDOMISED_MAPS", "TRAININGS", "AppearanceBenchConfig"]

#: the benchmark's localizers: the looks of their noise and calibration drives
TRAININGS = {"daylight": "default", "randomised": "random"}
#: looks of the randomised localizer's map images (``--appearance-randomised-map``): each
#: image its own random look, daylight, or one map per look
#: (:func:`~.appearance.map_conditions`)
RANDOMISED_MAPS = ("random", "default", "experiences")
#: camera effects of the randomised localizer's map images (``--appearance-map-camera``)
MAP_CAMERAS = CAMERAS


#: feature extractors the benchmark compares (``--appearance-features``)
FEATURES = ("pixel_pca", "small_cnn")


@dataclass
class AppearanceBenchConfig:
    """Settings of the appearance benchmark."""

    cities: str = field(default="31,32", metadata={
        "help": "comma-separated scene seeds (never used to tune anything)"})
    conditions: str = field(default="default,dusk,night,overcast,fog,seasonal,exposure,noise,"
                                    "motion_blur,traffic", metadata={
        "help": "comma-separated condition presets to test ('default' first: the reference)"})
    trainings: str = field(default="daylight,randomised", metadata={
        "help": "localizers: daylight (default look only), randomised (conditions='random')"})
    lanes: str = field(default="route", metadata={
        "help": "route (the route's lanes, drives around it: the tracking test's setting) or "
                "streets (every street, random tours)"})
    image_size: int = field(default=64, metadata={"help": "square image side (px)"})
    motion_noise: float = field(default=0.1, metadata={"help": "env actuation noise"})
    n_train: int = field(default=15000, metadata={
        "help": "lane training images per city (and per look of an experience map; 15000 "
                "chosen over 6000 and 30000 on tuning cities 11-12 with the SmallCNN "
                "experience map: daylight single images within (0.25 m, 2 deg) 71-74 -> 76-81 %)"})
    n_drive: int = field(default=1500, metadata={"help": "steps of each noise-calibration drive"})
    features: str = field(default="pixel_pca", metadata={
        "help": "pixel_pca (PixelPCA, see --appearance-normalize) or small_cnn (the packaged "
                "SmallCNN trained on cities 100-119 under randomised conditions, "
                "localization.features.weights)"})
    randomised_map: str = field(default="experiences", metadata={
        "help": "conditions of the randomised localizer's map images: experiences (one map "
                "per look: daylight and a draw of each other lighting family, "
                "ExperienceLocalizer; chosen over random on tuning cities 11-12: within "
                "(0.25 m, 2 deg) 73.3 -> 84.4 % on average over the ten presets, closed-loop "
                "RMSE pooled over them 3.06 -> 0.23 m), random (every image its own look) or "
                "default (daylight images; its noise and calibration drives stay under "
                "randomised conditions)"})
    map_camera: str = field(default="look", metadata={
        "help": "camera effects of the randomised localizer's map images (experiences or "
                "default map): look (each look's own: one draw per map, so whether a map "
                "has seen sensor noise is the luck of its city's draw) or random (every image "
                "its own draw of exposure, noise and blur, envs.conditions.draw_camera); look "
                "kept over random on tuning cities 11-12 (five maps, within (0.25 m, 2 deg) "
                "averaged over ten presets 84.4 against 81.1 %, sensor noise 81.2 against 75.8)"})
    n_components: int = field(default=128, metadata={
        "help": "PixelPCA components (small_cnn: PCA components of its embedding); 128 chosen "
                "over 64 and 256 with normalize='patches' on tuning cities 11-12 (the "
                "SmallCNN rows of docs/benchmarks.md section 9 ran with 64)"})
    normalize: str = field(default="patches", metadata={
        "help": "PixelPCA illumination normalisation (localization.features.pixel_pca): "
                "'patches' (8 x 8 patches, floor 0.001) chosen over 'channels' on tuning "
                "cities 11-12 (daylight map, both with 128 components, percent within the three thresholds, at dusk 72 / 94 / 99 against 47 / 65 / 72, at "
                "night 64 / 86 / 96 against 0 / 0 / 0)"})
    patch_floor: float = field(default=0.001, metadata={
        "help": "normalize='patches': added to each patch's standard deviation (pixel values "
                "in [0, 1]; PixelPCA(patch_floor=...)); 0.001 kept over 0.01 and 0.03 on tuning "
                "cities 11-12 (within (0.25 m, 2 deg) averaged over both localizers and ten "
                "presets 83.4 against 82.5 and 82.3 %: a higher floor helps the daylight map "
                "under sensor noise, 78 -> 81-82 %, but costs it night, 70 -> 61 and 52 %)"})
    smooth: float = field(default=0.0, metadata={
        "help": "PixelPCA: standard deviation (px) of a Gaussian blur of every image before "
                "its normalisation (PixelPCA(smooth=...)) in the localizers of "
                "--appearance-smooth-trainings; 0: off"})
    smooth_trainings: str = field(default="daylight,randomised", metadata={
        "help": "comma-separated localizers (daylight, randomised) whose PixelPCA "
                "--appearance-smooth blurs"})
    first_order: str = field(default="forward", metadata={
        "help": "the first-order terms of GSE's r* (GSERegressor(first_order=...)): frames "
                "(GSE's recovery Jacobian) or forward (the features' forward model w(theta), "
                "docs/method.md section 8.5); forward chosen on tuning cities 11-12 (daylight "
                "map: within (0.25 m, 2 deg) 74 -> 80 % in daylight, dusk 71 -> 73, overcast "
                "74 -> 78, night 63 -> 61; closed-loop RMSE 0.136 -> 0.104 m in daylight)"})
    forward_ridge: float = field(default=0.03, metadata={
        "help": "first_order=forward: damping of the pose directions the features see least "
                "(GSERegressor(forward_ridge=...)); 0.03 chosen over 0, 0.1 on tuning cities "
                "11-12 (daylight map, single images within (0.25 m, 2 deg) mean of seven "
                "presets 71.4 -> 72.6 %, sensor noise 67.5 -> 70, exposure 68 -> 70.5)"})
    verify: int = field(default=10, metadata={
        "help": "single images: psi*(w) checked against the poses of this many training "
                "images nearest in feature space and replaced by one whose Phi* explains w "
                "--appearance-verify-margin times better (AppearanceLocalizer.predict(verify=...), "
                "0: off); 10 with margin 3 chosen on tuning cities 11-12 (daylight map, nine "
                "presets per city: within (0.25 m, 2 deg) / (0.5 m, 5 deg) / (5 m, 10 deg) "
                "74.8 / 92.8 / 98.6 -> 75.8 / 93.9 / 99.2 % on average)"})
    verify_margin: float = field(default=3.0, metadata={
        "help": "--appearance-verify's margin (>= 1; 3 chosen over 2 and 4 on tuning cities 11-12)"})
    turns: int = field(default=2, metadata={
        "help": "single images: the position is the median over the image and its views "
                "turned by 1..turns pixels either way (AppearanceLocalizer.predict(turns=...), "
                "perspective camera only; 0: off); 2 chosen over 0 and 1 on tuning cities 11-12 "
                "(daylight map, default / dusk / overcast / night: within (0.25 m, 2 deg) 74.9 "
                "-> 79.3 / 80.7 % on average)"})
    noise: str = field(default="global", metadata={
        "help": "the closed loop's measurement noise for the localizers of "
                "--appearance-noise-trainings (the others: global): global (one R from the "
                "noise drive) or heteroscedastic (R(theta, w) from 5-fold held-out residuals and "
                "the image's novelty, docs/method.md section 15.4; five more GSE fits per "
                "localizer). Global: heteroscedastic with --appearance-measurement-bias passed "
                "its rule for the daylight map at stop 69 (tuning cities 13-14: presets in the "
                "NEES band 4 -> 6), but at stop 77 the same runs read 4 -> 5 at 1.045x "
                "the mean RMSE (docs/benchmarks.md section 9, stops 69 and 77)"})
    adaptive_noise: bool = field(default=False, metadata={
        "help": "the closed loop's R scaled up while the accepted innovations are larger "
                "than it predicts (BeliefFilter(adaptive_noise=True), docs/method.md section "
                "15.5; the localizers of --appearance-noise-trainings); off: on tuning cities "
                "11-12 no preset came into the NEES band and a traffic drive was lost "
                "(docs/benchmarks.md section 9, stop 68)"})
    measurement_bias: bool = field(default=False, metadata={
        "help": "the closed loop's belief carries a persistent (AR(1)) bias of the "
                "measurement (BeliefFilter(measurement_bias=True), docs/method.md section "
                "15.6; the localizers of --appearance-noise-trainings): with the global R on "
                "tuning cities 11-12 it brought 2 presets into the NEES band, the rule asked 3; "
                "with --appearance-noise heteroscedastic it passed on tuning cities 13-14 "
                "(daylight map) and held out put 6 of 10 presets in the band, against 1, but on "
                "the five-map localizer (tuning 11-12) it lost a traffic drive, mean RMSE 2.20x "
                "(docs/benchmarks.md section 9, stops 69-70)"})
    noise_trainings: str = field(default="daylight,randomised", metadata={
        "help": "comma-separated localizers (daylight, randomised) whose closed loop uses "
                "--appearance-noise, --appearance-adaptive-noise and "
                "--appearance-measurement-bias; the others keep the global R alone; '': none"})
    familiar_novelty: float = field(default=0.0, metadata={
        "help": "the closed loop's belief starts and restarts only from familiar images "
                "(BeliefFilter(familiar_novelty=...), relative novelty at most this, "
                "docs/method.md section 13.5; 0: off). Off: with 3, R(theta, w) and the bias "
                "state, the five maps on tuning cities 11-12 had 5 presets in the NEES band "
                "against 4 at 1.51x the mean RMSE (docs/benchmarks.md section 9, stop 70)"})
    novelty_noise: str = field(default="", metadata={
        "help": "comma-separated localizers (daylight, randomised) whose closed loop scales "
                "R by the image's novelty beyond the noise drive's "
                "(BeliefFilter(novelty_noise=True), docs/method.md section 15.7; the "
                "randomised localizer has several maps and cannot); '': off. Off: on tuning "
                "cities 13-14 (daylight map) it brought 1 more preset into the NEES band, the "
                "rule asked 2, at 1.08x the mean RMSE; beside R(theta, w) and the bias state "
                "3 more (5 -> 8) at 1.051x, the rule allowed 1.05x (docs/benchmarks.md "
                "section 9, stop 77)"})
    calibrate_on_belief: bool = field(default=False, metadata={
        "help": "refine each localizer's consistency on a drive on its own belief (in the "
                "training's look) after the true-pose drive; off: on tuning cities 11-12 it "
                "raised the closed-loop NEES and RMSE (docs/benchmarks.md section 9, stop 51)"})
    n_test: int = field(default=300, metadata={"help": "single test images per city and condition"})
    n_drives: int = field(default=2, metadata={"help": "closed-loop drives per city and condition"})
    drive_steps: int = field(default=300, metadata={"help": "steps of each closed-loop drive"})
    quick: bool = field(default=False, metadata={"help": "smoke run: one city, tiny fits"})
    seed: int = field(default=0, metadata={"help": "seed of fits, test poses and drives"})
    out_dir: str = field(default="results", metadata={
        "help": "where bench_appearance.json/.md go"})

    def resolved(self) -> AppearanceBenchConfig:
        """The settings actually run (``quick``: one city, three conditions, small fits)."""
        if not self.quick:
            return self
        return dataclasses.replace(
            self, cities=self.cities.split(",")[0], conditions="default,night,traffic",
            image_size=32, n_train=400, n_drive=200, n_components=8, n_test=30, n_drives=1,
            drive_steps=40)

    def lists(self) -> tuple[list[int], list[str], list[str]]:
        """(cities, conditions, trainings) as lists."""
        return ([int(s) for s in self.cities.split(",")],
                [s.strip() for s in self.conditions.split(",")],
                [s.strip() for s in self.trainings.split(",")])

    def noise_of(self, training: str) -> tuple[str, bool, bool]:
        """(noise, adaptive_noise, measurement_bias) of the localizer ``training``: the
        options for the localizers of ``noise_trainings``, else the global R alone;
        ValueError naming ``noise_trainings`` for a name that is no localizer (it would
        otherwise leave both on the global R without a word)."""
        names = [s.strip() for s in self.noise_trainings.split(",") if s.strip()]
        bad = [n for n in names if n not in TRAININGS]
        if bad:
            raise ValueError(f"noise_trainings: unknown {bad}; choose from {list(TRAININGS)}")
        if training in names:
            return self.noise, self.adaptive_noise, self.measurement_bias
        return "global", False, False

    def novelty_trainings(self) -> list[str]:
        """The localizers of ``novelty_noise``; ValueError naming the option for others."""
        names = [s.strip() for s in self.novelty_noise.split(",") if s.strip()]
        bad = [n for n in names if n != "daylight"]
        if bad:
            raise ValueError(f"novelty_noise: {bad} cannot scale R by novelty (only "
                             "'daylight', a localizer of one map)")
        return names
