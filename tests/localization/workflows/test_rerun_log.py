"""Rerun recordings: a short .rrd written by RerunRecorder and read back with Rerun's own
reader (entity paths, rows per step, the logged poses), the demo's episode video, and clear
errors for bad paths and a missing rerun-sdk."""

from __future__ import annotations

import builtins

import numpy as np
import pytest

from localization.workflows.rerun_log import (
    VIEWER_EXTRA,
    RerunLog,
    RerunRecorder,
    check_rrd_path,
    require_rerun,
)
from localization.wrappers import BeliefWrapper, OracleWrapper

from ..conftest import make_env
from ..test_wrappers import start_pose

NO_RERUN = "rerun-sdk is not installed (the viewer extra: pip install 'appearance-nav[viewer]')"


def _read(path) -> dict[str, list]:
    """Entity path -> the chunks Rerun's reader finds there."""
    chunk = pytest.importorskip("rerun.chunk", reason=NO_RERUN)
    out: dict[str, list] = {}
    for c in chunk.RrdReader(path).stream():
        out.setdefault(c.entity_path, []).append(c)
    return out


def _rows(chunks: list, column: str) -> list:
    """The values of ``column`` over the chunks, in logging order."""
    values = []
    for c in chunks:
        batch = c.to_record_batch()
        if column in batch.schema.names:
            values += batch.column(column).to_pylist()
    return values


def test_particle_episode_round_trips_through_rerun(localizer, tmp_path):
    pytest.importorskip("rerun", reason=NO_RERUN)
    env = BeliefWrapper(make_env(max_episode_steps=6), localizer, filter="particles",
                        filter_options={"n_particles": 300, "seed": 0})
    path = tmp_path / "nested" / "run.rrd"
    means = []
    with RerunLog(path, max_particles=100) as log:
        recorder = RerunRecorder(env, log, "pf", episodes=1,
                                 path=lambda: np.array([[0.0, 0.0], [3.0, 3.0]]))
        for episode in range(2):  # only the first is recorded
            recorder.reset(seed=episode, options={"pose": start_pose(env)})
            means.append([env.mean.copy()])
            done = False
            while not done:
                _, _, terminated, truncated, _ = recorder.step([0.5, 0.1])
                means[-1].append(env.mean.copy())
                done = terminated or truncated
    assert path.is_file()
    entities = _read(path)
    run = "pf/episode_0"
    for name in ("map/world", "map/world/city/buildings", "map/world/city/streets",
                 "map/world/city/raster", f"map/world/{run}/true", f"map/world/{run}/belief",
                 f"map/world/{run}/ellipse", f"map/world/{run}/particles",
                 f"map/world/{run}/path", f"map/world/{run}/goal", f"camera/{run}",
                 f"plots/{run}/nees", f"plots/{run}/error", f"plots/{run}/accepted",
                 f"status/{run}"):
        assert "/" + name in entities, (name, sorted(entities))
    assert not any("episode_1" in e for e in entities)  # episodes=1
    assert all(c.is_static for c in entities["/map/world/city/buildings"])
    translations = _rows(entities[f"/map/world/{run}/belief"], "Transform3D:translation")
    assert len(translations) == 7  # reset + 6 steps
    assert np.allclose(np.array(translations).reshape(-1, 3)[:, :2], np.array(means[0])[:, :2], atol=1e-5)
    particles = _rows(entities[f"/map/world/{run}/particles"], "Points2D:positions")
    assert len(particles) == 7 and all(len(p) == 100 for p in particles)  # max_particles
    step_timeline = [c for c in entities[f"/camera/{run}"] if "step" in c.timeline_names]
    assert step_timeline and "frame" in step_timeline[0].timeline_names


def test_oracle_recorder_logs_what_render_draws(tmp_path):
    pytest.importorskip("rerun", reason=NO_RERUN)
    env = OracleWrapper(make_env(max_episode_steps=3))
    path = tmp_path / "oracle.rrd"
    with RerunLog(path, env.unwrapped.top_down_map()) as log:
        recorder = RerunRecorder(env, log, "oracle")
        recorder.reset(seed=1)
        poses = [env.mean.copy()]
        for _ in range(3):
            recorder.step([0.4, 0.0])
            poses.append(env.mean.copy())
    entities = _read(path)
    true = _rows(entities["/map/world/oracle/episode_0/true"], "Transform3D:translation")
    assert np.allclose(np.array(true).reshape(-1, 3)[:, :2], np.array(poses)[:, :2], atol=1e-5)
    assert "/map/world/oracle/episode_0/particles" not in entities  # no particles to log


def test_bad_rerun_inputs(tmp_path):
    (tmp_path / "a_file").write_text("x")
    with pytest.raises(ValueError, match=r"\.rrd"):
        check_rrd_path(tmp_path / "out.txt")
    (tmp_path / "dir.rrd").mkdir()
    with pytest.raises(ValueError, match="folder"):
        check_rrd_path(tmp_path / "dir.rrd")
    with pytest.raises(ValueError, match="a_file"):
        check_rrd_path(tmp_path / "a_file" / "x.rrd")
    with pytest.raises(TypeError, match="path"):
        check_rrd_path(3)
    with pytest.raises(ValueError, match=r"\.rrd"):
        RerunLog(tmp_path / "out.rrd.txt")
    pytest.importorskip("rerun", reason=NO_RERUN)
    with RerunLog(tmp_path / "ok.rrd") as log:
        with pytest.raises(TypeError, match="pose wrapper"):
            RerunRecorder(make_env(), log, "bare")
        with pytest.raises(TypeError, match="RerunLog"):
            RerunRecorder(OracleWrapper(make_env()), "log.rrd", "x")
        with pytest.raises(ValueError, match="name"):
            RerunRecorder(OracleWrapper(make_env()), log, "")
        with pytest.raises(ValueError, match="run"):
            log.log_step("", 0, None)


def test_missing_rerun_names_the_extra(monkeypatch):
    real_import = builtins.__import__

    def no_rerun(name, *args, **kwargs):
        if name == "rerun" or name.startswith("rerun."):
            raise ImportError("No module named 'rerun'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_rerun)
    with pytest.raises(ModuleNotFoundError, match="appearance-nav\\[viewer\\]"):
        require_rerun()
    assert "appearance-nav[viewer]" in VIEWER_EXTRA


def test_episode_video_writes_the_mp4_and_the_recording(localizer, tmp_path):
    iio = pytest.importorskip("imageio.v3")
    from localization.workflows.episode_video import episode_video

    rerun = None
    try:
        require_rerun()
        rerun = tmp_path / "episode.rrd"
    except ModuleNotFoundError:
        pass
    result = episode_video(localizer, tmp_path / "episode.mp4", image_size=32,
                           motion_noise=0.05, kidnap_at=8, max_steps=20, rerun=rerun)
    frames = iio.imread(tmp_path / "episode.mp4")
    assert len(frames) == result["frames"] == result["steps"] + 1
    assert frames.shape[1:] == (384, 576, 3)
    assert (tmp_path / "episode.png").is_file()
    assert result["kidnap_step"] == 8
    if rerun is not None:
        assert "/status/demo/scripted_particles/episode_0" in _read(rerun)


def test_track_runs_record_every_run(localizer, tmp_path):
    pytest.importorskip("rerun", reason=NO_RERUN)
    from localization.workflows.track_runs import TrackConfig, run_tracking

    rrd = tmp_path / "track.rrd"
    args = TrackConfig(measurements="pose,representation", starts="0", steps=4,
                       out=str(tmp_path / "out"), rerun=str(rrd), image_size=32)
    run_tracking(args, make_env(max_episode_steps=None), localizer)
    entities = _read(rrd)
    for name in ("pose", "representation"):
        run = f"track/{name}_0/episode_0"
        belief = _rows(entities[f"/map/world/{run}/belief"], "Transform3D:translation")
        assert len(belief) == 5  # reset + 4 steps
        assert f"/map/world/{run}/path" in entities and f"/plots/{run}/nis" in entities
