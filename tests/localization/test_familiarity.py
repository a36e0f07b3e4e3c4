"""Image familiarity: the relative novelty of recent images, and the belief status it tempers."""

import gymnasium as gym
import numpy as np
import pytest

from envs.datasets import collect_dataset
from localization.familiarity import Familiarity, novelty_scale
from localization.wrapper_checks import single_map
from localization.wrappers import BeliefWrapper

from .conftest import SIZE, make_env
from .test_wrappers import start_pose


class NormRegressor:
    """A stand-in map whose manifold is the origin: the novelty of w is |w|."""

    def __init__(self, norms: list[float]) -> None:
        self._ws = np.array([[n, 0.0] for n in norms])
        self.w_scale_, self.w_mean_ = 1.0, np.zeros(2)

    def reconstruct(self, W: np.ndarray) -> np.ndarray:
        out = np.zeros_like(W)
        out[np.isnan(W).any(axis=1)] = np.nan  # out of the domain: NaN
        return out

    def novelty(self, W: np.ndarray) -> np.ndarray:
        return np.linalg.norm(W - self.reconstruct(W), axis=1)

    def training_novelty(self, sample: int = 500) -> np.ndarray:
        return self.novelty(self._ws[:sample] * self.w_scale_ + self.w_mean_)


def test_the_median_of_the_window_decides():
    """Training images' median novelty 2 is the unit; the window's median against the
    threshold; NaN counts as infinitely novel; reset forgets."""
    reg = NormRegressor([1.0, 2.0, 3.0])
    assert novelty_scale(reg) == 2.0
    fam = Familiarity(reg, threshold=3.0, window=3)
    assert fam.familiar and np.isnan(fam.novelty)
    assert fam.update([4.0, 0.0]) == 2.0 and fam.familiar
    assert fam.update([20.0, 0.0]) == 10.0 and not fam.familiar  # median of (2, 10): 6 > 3
    fam.reset()
    for u in ([2.0, 0.0], [20.0, 0.0], [4.0, 0.0]):
        fam.update(u)
    assert fam.familiar  # median of (1, 10, 2) = 2
    fam.update([np.nan, 0.0])
    assert fam.novelty == np.inf and not fam.familiar  # (10, 2, inf): 10
    assert fam.status("tracking") == "doubtful"
    assert fam.status("lost") == "lost" and fam.status("relocalizing") == "relocalizing"
    fam.reset()
    assert fam.familiar and fam.status("tracking") == "tracking"


def test_bad_settings():
    reg = NormRegressor([1.0])
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="familiar_novelty"):
            Familiarity(reg, bad)
    with pytest.raises(ValueError, match="window"):
        Familiarity(reg, 3.0, window=0)
    with pytest.raises(TypeError, match="familiar_novelty needs an AppearanceLocalizer"):
        single_map(object(), "familiar_novelty")


def test_another_citys_images_are_less_familiar(localizer, drive):
    """City 0's map rates city 0's drive images as more familiar than another city's."""
    env = gym.make("AppearanceNav-v0", scene_seed=5, image_size=SIZE, motion_noise=0.05)
    other, _ = collect_dataset(env, 60, "lanes", seed=0, progress=False)
    env.close()

    def median(images: np.ndarray) -> float:
        fam = Familiarity(localizer.regressor_, threshold=1.0, window=len(images))
        return float(np.median([fam.update(w) for w in localizer.transform(images)]))

    own = median(drive[0][::4])
    assert np.isfinite(own) and median(other) > 1.5 * own


def test_the_wrapper_reports_unfamiliar_images_as_doubtful(localizer):
    """A threshold below every image: each "tracking" step is published "doubtful" with the
    image's novelty; one above every image changes nothing; the filter itself is not touched."""
    statuses = {}
    for threshold in (None, 1e-9, 1e9):
        env = BeliefWrapper(make_env(max_episode_steps=30), localizer,
                            familiar_novelty=threshold)
        _, info = env.reset(seed=3, options={"pose": start_pose(env)})
        seen = []
        for _ in range(20):
            _, _, _, _, info = env.step(np.array([0.5, 0.0], dtype=np.float32))
            seen.append((info["belief_status"], env.belief.belief_status,
                         info.get("novelty")))
        statuses[threshold] = seen
        env.close()
    plain, strict, loose = statuses[None], statuses[1e-9], statuses[1e9]
    assert all(n is None for *_, n in plain)
    assert all(n > 0 for *_, n in strict)  # inf where an image is off the maps
    assert [s for s, *_ in loose] == [s for s, *_ in plain]
    assert [inner for _, inner, _ in strict] == [inner for _, inner, _ in plain]
    assert "tracking" in [s for s, *_ in plain]
    assert [s for s, *_ in strict] == ["doubtful" if s == "tracking" else s for s, *_ in plain]
    with pytest.raises(ValueError, match="familiar_novelty"):
        BeliefWrapper(make_env(), localizer, familiar_novelty=-1.0)
