"""The robustness benchmark: rows, targets, and parallel episodes equal to the serial run."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import gymnasium as gym
import pytest

from agents.evaluation import Episode
from localization.cli._args import UsageError
from localization.cli.bench import Args, check
from localization.workflows.benchmarks.robustness import (
    RobustnessConfig,
    _summary,
    localizer_params,
    localizer_path,
    make_env,
    run_robustness_bench,
    runs_condition,
    training_of,
    trainings_used,
)
from localization.workflows.benchmarks.robustness_report import (
    DEFAULT_STEPS,
    HELD_OUT_CITIES,
    _success_cell,
    held_out_label,
    targets,
    tipped_over_note,
)


def test_image_free_sources_skip_lighting_presets_only() -> None:
    assert runs_condition("ekf", "night") and runs_condition("particles", "fog")
    assert not runs_condition("oracle", "night") and not runs_condition("dead_reckoning", "dusk")
    assert runs_condition("oracle", "traffic") and runs_condition("dead_reckoning", "kidnap")
    assert training_of("kidnap") == "daylight" and training_of("traffic") == "randomised"


def test_a_push_row_shoves_the_robot_at_the_kidnap_step() -> None:
    from envs.kidnapping import PUSH_DISTANCE, KidnapWrapper

    def kidnapper(condition: str) -> KidnapWrapper | None:
        env = make_env(RobustnessConfig(kidnap_at=7), 21, condition, "oracle")
        while not isinstance(env, KidnapWrapper) and hasattr(env, "env"):
            env = env.env
        return env if isinstance(env, KidnapWrapper) else None

    push, kidnap = kidnapper("push"), kidnapper("kidnap")
    assert push.push == PUSH_DISTANCE and push.at_steps == {7}
    assert kidnap.push is None and kidnap.at_steps == {7}
    assert kidnapper("nominal") is None
    assert training_of("push") == "daylight" and runs_condition("oracle", "push")


def test_rows_on_the_true_pose_alone_fit_no_localizer() -> None:
    assert trainings_used([("scripted", "oracle", "traffic"), ("ppo", "oracle", "nominal")]) == []
    assert trainings_used([("scripted", "dead_reckoning", "kidnap"),
                           ("scripted", "ekf", "traffic")]) == ["daylight", "randomised"]


def test_traffic_can_run_on_the_daylight_localizer() -> None:
    assert training_of("traffic", "daylight") == "daylight"
    assert training_of("night", "daylight") == "randomised"
    assert trainings_used([("scripted", "ekf", "traffic"), ("scripted", "ekf", "nominal")],
                          "daylight") == ["daylight"]
    with pytest.raises(ValueError, match="moving_localizer"):
        RobustnessConfig(moving_localizer="night").lists()
    label = targets({"scripted/ekf/traffic": {"success_rate": 1.0}}, "daylight")[0]["target"]
    assert "traffic (daylight localizer)" in label


def test_each_localizer_gets_its_own_features() -> None:
    plain = RobustnessConfig(daylight_features="pixel_pca")
    assert localizer_params(plain, "daylight") == {"features_params": {"n_components": 64}}
    assert "conditions" in localizer_params(plain, "randomised")["features_params"]["weights"]
    cnn = localizer_params(RobustnessConfig(), "daylight")
    assert Path(cnn["features_params"]["weights"]).name == "small_cnn_perspective_random.pt"
    assert cnn["rows"] == (0.0, 1.0)


def test_the_report_calls_only_the_held_out_cities_held_out() -> None:
    assert RobustnessConfig().cities == HELD_OUT_CITIES
    assert held_out_label("21,22") == held_out_label(" 22") == "held out"
    assert "not the held-out" in held_out_label("13,14")
    assert "not the held-out" in held_out_label("21,15")


def test_success_within_the_default_limit_counts_only_the_early_arrivals() -> None:
    def episode(success: bool, steps: int) -> Episode:
        return Episode(seed=0, success=success, steps=steps, time=steps / 10, path_length=9.0,
                       shortest=8.0, collision_steps=0, final_distance=0.3, belief_rmse=0.1)

    runs = [episode(True, 100), episode(True, DEFAULT_STEPS), episode(True, DEFAULT_STEPS + 1),
            episode(False, 600)]
    row = _summary(runs)
    assert row["success_rate"] == 0.75 and row["success_within_default"] == 0.5
    assert row["success_within_default_se"] == pytest.approx((0.25 / 4) ** 0.5)
    assert _success_cell(row, 600) == f"0.75 ± 0.22 (0.50 in {DEFAULT_STEPS})"
    assert _success_cell(row, DEFAULT_STEPS) == "0.75 ± 0.22"


@pytest.mark.parametrize("key, value, match", [
    ("conditions", "nominal,sunny", "conditions"),
    ("sources", "ekf,gps", "sources"),
    ("agents", "", "agents"),
])
def test_unknown_names_are_refused(key: str, value: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        RobustnessConfig(**{key: value}).lists()


def test_an_unknown_randomised_map_is_named() -> None:
    args = Args(only="robustness", robustness=RobustnessConfig(randomised_map="dusk"))
    with pytest.raises(UsageError, match="--robustness-randomised-map"):
        check(args)


def test_a_free_daylight_localizer_has_its_own_file_and_a_checked_name() -> None:
    streets, free = RobustnessConfig(daylight_lanes="streets"), RobustnessConfig()
    assert free.daylight_lanes == "free" and free.resolved().daylight_lanes == "free"
    assert RobustnessConfig(quick=True).resolved().daylight_lanes == "streets"
    assert localizer_path(streets, 21, "daylight") != localizer_path(free, 21, "daylight")
    assert localizer_path(streets, 21, "randomised") == localizer_path(free, 21, "randomised")
    with pytest.raises(ValueError, match="daylight_lanes"):
        RobustnessConfig(daylight_lanes="lanes").lists()
    with pytest.raises(UsageError, match="--robustness-daylight-lanes"):
        check(Args(only="robustness", robustness=RobustnessConfig(daylight_lanes="route")))


def test_the_cli_names_a_bad_belief_or_pilot_option_before_anything_runs() -> None:
    for name, bad in (("offset_doubt", -0.4), ("particle_offset_doubt", float("nan")),
                      ("slow_steps", -1), ("guard_patience", -20),
                      ("guard_agree", -0.3), ("guard_memory", -5),
                      ("particle_guard_patience", -1), ("particle_guard_agree", -0.3),
                      ("particle_guard_memory", -1), ("familiar_novelty", -5.0),
                      ("particle_familiar_novelty", -1.0)):
        option = "--robustness-" + name.replace("_", "-")
        with pytest.raises(UsageError, match=option):
            check(Args(only="robustness", robustness=RobustnessConfig(**{name: bad})))


def test_the_report_names_rows_where_the_robot_was_flipped() -> None:
    upright = {"episodes": 200, "tipped_over_episodes": 0.0}
    assert tipped_over_note({"summary": {"scripted/ekf/traffic": upright}}) == ""
    flipped = {"episodes": 200, "tipped_over_episodes": 0.005}
    note = tipped_over_note({"summary": {"scripted/oracle/traffic": flipped,
                                         "scripted/ekf/traffic": upright}})
    assert "scripted / oracle / traffic: 1 of 200" in note and "ekf" not in note


def test_targets_from_rows() -> None:
    row = {"success_rate": 0.95, "collisions_per_episode": 0.03}
    summary = {"scripted/oracle/nominal": {**row, "success_rate": 1.0, "collisions_per_episode":
                                           0.0},
               "scripted/ekf/nominal": row, "scripted/particles/kidnap": row,
               "scripted/ekf/night": row}
    got = {t["target"]: t["pass"] for t in targets(summary)}
    assert got == {"scripted on the EKF belief, nominal: success": False,
                   "scripted on the particle belief, one kidnap: success": True,
                   "scripted on the EKF belief, night (randomised localizer): success": True,
                   "scripted on ekf, nominal: collisions per episode": False}
    traffic = {"scripted/oracle/traffic": {"success_rate": 1.0, "collisions_per_episode": 2.0,
                                           "traffic_collisions_per_episode": 2.0},
               "scripted/ekf/traffic": {"success_rate": 0.5, "collisions_per_episode": 5.0,
                                        "traffic_collisions_per_episode": 1.5}}
    assert [t["target"] for t in targets(traffic) if "collisions" in t["target"]] == [
        ("scripted on ekf, traffic: collisions per episode (with moving objects: 1.50, "
         "true pose 2.00)")]


def test_parallel_episodes_equal_the_serial_run(tmp_path: Path) -> None:
    args = RobustnessConfig(cities="21", conditions="nominal,kidnap,traffic",
                            sources="oracle,ekf,dead_reckoning", agents="scripted", episodes=2,
                            image_size=32, n_train=500, n_train_randomised=500, n_drive=400,
                            max_steps=25, kidnap_at=5, out_dir=str(tmp_path))
    serial = run_robustness_bench(args)
    episodes = tmp_path / "robustness" / "episodes"
    assert len(list(episodes.glob("*.json"))) == 18  # every task's records, for a resume
    shutil.rmtree(episodes)  # run them again, on 2 workers, with the same localizers
    parallel = run_robustness_bench(RobustnessConfig(**{**vars(args), "workers": 2,
                                                        "reuse_localizers": True}))
    assert serial["episodes"] == parallel["episodes"]
    resumed = run_robustness_bench(RobustnessConfig(**{**vars(args), "reuse_localizers": True}))
    assert resumed["episodes"] == serial["episodes"]
    assert set(serial["summary"]) == {f"scripted/{s}/{c}" for s in ("oracle", "ekf",
                                      "dead_reckoning") for c in ("nominal", "kidnap", "traffic")}
    assert all(r["episodes"] == 2 for r in serial["summary"].values())
    assert json.loads((tmp_path / "bench_robustness.json").read_text())["targets"]
    assert "| traffic |" in (tmp_path / "bench_robustness.md").read_text()


def test_detect_divergence_applies_to_the_ekf_rows_and_keys_their_records() -> None:
    """``detect_divergence`` gives the EKF rows' belief its divergence monitor (and only
    theirs), and their episode records a file of their own (a resume never mixes them)."""
    from localization.workflows.benchmarks.robustness import (
        RobustnessConfig,
        RobustTask,
        belief_options,
        task_path,
    )

    plain = RobustnessConfig(detect_divergence=False, guard=False, familiar_novelty=0.0)
    detect = RobustnessConfig(guard=False, familiar_novelty=0.0)
    assert belief_options(plain, "ekf") == {"filter": "ekf", "image_pose": False}
    # the scripted agent's guard reads psi* of each image: the belief publishes it then only
    assert belief_options(RobustnessConfig(), "particles")["image_pose"] is True
    assert belief_options(detect, "ekf") == {"filter": "ekf", "image_pose": False,
                                             "filter_options": {"detect_divergence": True}}
    assert belief_options(detect, "particles") == {"filter": "particles", "image_pose": False}
    # the randomised localizer of experiences has several maps: no monitor there
    assert belief_options(detect, "ekf", "traffic") == belief_options(detect, "ekf", "night") \
        == {"filter": "ekf", "image_pose": False}
    assert belief_options(detect, "ekf", "push") == belief_options(detect, "ekf")
    assert belief_options(detect, "oracle") == {}
    names = {task_path(RobustTask(config, 21, "nominal", source, "scripted", (1, 2))).name
             for config in (plain, detect) for source in ("ekf", "particles")}
    assert len(names) == 3  # the particle rows' records are the same either way
    typical = RobustnessConfig(guard=False, particle_unmapped="typical", familiar_novelty=0.0)
    assert belief_options(typical, "particles") == {
        "filter": "particles", "image_pose": False, "filter_options": {"unmapped": "typical"}}
    assert belief_options(typical, "ekf") == belief_options(detect, "ekf")
    path = task_path(RobustTask(typical, 21, "nominal", "particles", "scripted", (1, 2))).name
    assert "_unmapped-typical" in path and path not in names
    with pytest.raises(ValueError, match="particle_unmapped"):
        RobustnessConfig(particle_unmapped="zero").lists()


def test_the_offset_doubt_goes_to_the_ekf_monitor_and_keys_its_records() -> None:
    from localization.workflows.benchmarks.robustness import (
        RobustnessConfig,
        RobustTask,
        belief_options,
        task_path,
    )

    offset = RobustnessConfig(guard=False, offset_doubt=0.5, particle_offset_doubt=0.5)
    assert belief_options(offset, "ekf")["filter_options"] == {
        "detect_divergence": {"offset_doubt": 0.5}}
    assert belief_options(offset, "particles")["filter_options"] == {
        "track_mode": {"offset_doubt": 0.5}}
    assert belief_options(RobustnessConfig(guard=False, offset_doubt=0.5), "particles") == \
        belief_options(RobustnessConfig(guard=False), "particles")  # each belief its own
    assert "filter_options" not in belief_options(  # no monitor, so no offset test
        RobustnessConfig(guard=False, offset_doubt=0.5, detect_divergence=False), "ekf")
    names = [task_path(RobustTask(c, 21, "push", "ekf", "scripted", (1, 2))).name
             for c in (RobustnessConfig(guard=False), offset)]
    assert names[0].endswith("_detect_familiar5.json")
    assert names[1].endswith("_detect-offset0.5_familiar5.json")
    name = task_path(RobustTask(offset, 21, "push", "particles", "scripted", (1, 2))).name
    assert name.endswith("_offset0.5.json")
    for bad in (-0.5, float("nan")):
        with pytest.raises(ValueError, match="offset_doubt"):
            RobustnessConfig(offset_doubt=bad).lists()
        with pytest.raises(ValueError, match="particle_offset_doubt"):
            RobustnessConfig(particle_offset_doubt=bad).lists()


def test_slow_steps_go_to_the_scripted_agent_and_key_their_records() -> None:
    from localization.workflows.benchmarks.robustness import (
        RobustnessConfig,
        RobustTask,
        make_agent,
        task_path,
    )

    city = gym.make("AppearanceNav-v0", scene_seed=0).unwrapped.city
    bounded, plain = (RobustnessConfig(slow_steps=30, guard_patience=0),
                      RobustnessConfig(guard_patience=0))
    assert make_agent(bounded, "scripted", "ekf", city).slow_steps == 30
    assert make_agent(plain, "scripted", "ekf", city).slow_steps is None  # 0: unbounded
    names = [task_path(RobustTask(c, 21, "push", "ekf", "scripted", (1, 2))).name
             for c in (plain, bounded)]
    assert names[1] == names[0].replace(".json", "_slow30.json")
    for bad in (-1, 2.5, True):
        with pytest.raises(ValueError, match="slow_steps"):
            RobustnessConfig(slow_steps=bad).lists()
        for name in ("guard_patience", "particle_guard_patience"):
            with pytest.raises(ValueError, match=name):
                RobustnessConfig(**{name: bad}).lists()
    with pytest.raises(ValueError, match="particle_guard_agree"):
        RobustnessConfig(particle_guard_agree=-0.3).lists()


def test_guard_patience_is_set_per_belief_and_keys_the_records() -> None:
    """By default the EKF rows' guard yields after 20 vetoes, the particle rows' after 20 to a
    belief within 0.3 m of its image; the true pose has no guard, so its records are the same."""
    from localization.workflows.benchmarks.robustness import (
        RobustnessConfig,
        RobustTask,
        make_agent,
        task_path,
    )

    city = gym.make("AppearanceNav-v0", scene_seed=0).unwrapped.city
    default = RobustnessConfig()
    never = RobustnessConfig(guard_patience=0, particle_guard_patience=0)
    assert make_agent(default, "scripted", "ekf", city).guard.patience == 20
    assert make_agent(default, "scripted", "ekf", city).guard.agree is None
    assert make_agent(never, "scripted", "ekf", city).guard.patience is None
    guard = make_agent(default, "scripted", "particles", city).guard
    assert guard.patience == 20 and guard.agree == 0.3
    assert make_agent(never, "scripted", "particles", city).guard.patience is None
    agreeing = RobustnessConfig(particle_guard_agree=0.5)
    assert make_agent(agreeing, "scripted", "particles", city).guard.agree == 0.5

    def name(config: RobustnessConfig, source: str) -> str:
        return task_path(RobustTask(config, 21, "push", source, "scripted", (1, 2))).name

    assert name(default, "ekf") == name(never, "ekf").replace(".json", "_yield20.json")
    assert name(default, "particles") == name(never, "particles").replace(
        ".json", "_yield20-agree0.3.json")
    assert name(agreeing, "particles").endswith("_yield20-agree0.5.json")
    ekf_agreeing = RobustnessConfig(guard_agree=0.3)
    assert make_agent(ekf_agreeing, "scripted", "ekf", city).guard.agree == 0.3
    assert name(ekf_agreeing, "ekf").endswith("_yield20-agree0.3.json")
    with pytest.raises(ValueError, match="guard_agree"):
        RobustnessConfig(guard_agree=-1.0).lists()
    remembering = RobustnessConfig(guard_memory=5, particle_guard_memory=3)
    assert make_agent(remembering, "scripted", "ekf", city).guard.memory == 5
    assert make_agent(remembering, "scripted", "particles", city).guard.memory == 3
    assert make_agent(default, "scripted", "ekf", city).guard.memory == 0
    assert name(remembering, "ekf").endswith("_yield20_memory5.json")
    assert name(remembering, "particles").endswith("_yield20-agree0.3_memory3.json")
    assert name(RobustnessConfig(guard_patience=0, guard_memory=5), "ekf").endswith(
        "_memory5.json")
    assert name(remembering, "oracle") == name(default, "oracle")
    with pytest.raises(ValueError, match="particle_guard_memory"):
        RobustnessConfig(particle_guard_memory=1.5).lists()
    assert name(default, "oracle") == name(never, "oracle") == name(agreeing, "oracle")


def test_familiar_novelty_reaches_the_belief_rows_and_keys_their_records() -> None:
    """By default the EKF rows report unfamiliar images as doubtful (5), the particle rows
    do not; records are keyed by it; the experience maps (several maps) never get it."""
    from localization.workflows.benchmarks.robustness import (
        RobustnessConfig,
        RobustTask,
        belief_options,
        task_path,
    )

    familiar = RobustnessConfig(particle_familiar_novelty=5.0)
    plain = RobustnessConfig(familiar_novelty=0.0)
    assert belief_options(RobustnessConfig(), "ekf")["familiar_novelty"] == 5.0
    assert "familiar_novelty" not in belief_options(RobustnessConfig(), "particles")
    for source in ("ekf", "particles"):
        assert belief_options(familiar, source)["familiar_novelty"] == 5.0
        assert "familiar_novelty" not in belief_options(plain, source)
    assert belief_options(familiar, "oracle") == {}
    experiences = RobustnessConfig(randomised_map="experiences")
    assert "familiar_novelty" not in belief_options(experiences, "ekf", "night")

    def name(config: RobustnessConfig, source: str) -> str:
        return task_path(RobustTask(config, 21, "nominal", source, "scripted", (1, 2))).name

    assert name(familiar, "ekf") == name(plain, "ekf").replace("_detect", "_detect_familiar5")
    assert "_familiar5" in name(familiar, "particles")
    assert "_familiar" not in name(RobustnessConfig(), "particles")
    assert name(familiar, "oracle") == name(plain, "oracle")
    with pytest.raises(ValueError, match="familiar_novelty"):
        RobustnessConfig(familiar_novelty=float("nan")).lists()
