"""Pose-belief observation wrappers: the GSE belief, an oracle and dead reckoning.

All three turn the env's observation ``Dict(image, goal)`` into the same space

    Dict(pose_mean=Box((3,)), pose_cov=Box((6,)), goal=Box((2,)))      (+ image with keep_image)

``pose_mean = [x, y, yaw]`` (yaw wrapped to (-pi, pi]) and ``pose_cov`` the upper triangle of
the (3, 3) covariance row by row: ``[Pxx, Pxy, Pxyaw, Pyy, Pyyaw, Pyawyaw]``
(:func:`cov_to_triu` / :func:`triu_to_cov`). An agent trained on one pose source runs on the
others unchanged.

- :class:`BeliefWrapper`: a belief from appearance on an
  :class:`~localization.localizer.AppearanceLocalizer`, ``filter="ekf"`` (the EKF of
  :mod:`localization.filtering.belief`: predict with the known motion model F and the
  commanded action, update with a GSE measurement model of the image, NIS-gated) or
  ``filter="particles"`` (:class:`~localization.filtering.particles.ParticleBelief`:
  thousands of hypotheses, the dominant one in ``pose_mean`` / ``pose_cov``). The true pose
  is never used by the belief.
- :class:`OracleWrapper`: the true pose with a small fixed covariance (an upper bound).
- :class:`DeadReckoningWrapper`: F alone from the true start pose, covariance growing with Q.

Every wrapper adds ``info["nees"]`` from ``info["pose"]`` (evaluation only).

``render()`` (when the env has ``render_mode="rgb_array"``) draws the belief on the city map
(:mod:`localization.belief_render`): the true pose, the belief mean and its 2-sigma
ellipse, the particles and other hypotheses (particle filter), the goal, the planned path
(``planned_path``, set by whoever plans) and the camera image, so
``gymnasium.wrappers.RecordVideo`` records episodes as they are. Nothing is drawn unless
``render()`` is called.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike

from localization._validation import check_bool, check_choice, check_options, check_seed
from localization.districts import DistrictLocalizer
from localization.familiarity import Familiarity
from localization.filtering.belief import BeliefFilter
from localization.filtering.ekf import PoseEKF, check_gate_probability
from localization.filtering.free_space import city_sampler
from localization.filtering.map_contact import Contact
from localization.filtering.particles import ParticleBelief
from localization.filtering.process_noise import world_process_noise
from localization.geometry import Array, cov_to_triu, wrap_angle
from localization.localizer import MEASUREMENTS, AppearanceLocalizer, city_info
from localization.wrapper_checks import check_compatible, single_map
from localization.wrapper_render import RenderBelief

FILTERS = ("ekf", "particles")
LOCALIZE = ("image", "global")
#: filter_options each filter takes (the rest of its settings are BeliefWrapper's arguments)
FILTER_OPTIONS = {
    "ekf": ("detect_divergence", "alpha", "inflate_factor", "noise", "free_space",
            "contact_motion", "project_contacts", "heading_check", "familiar_novelty",
            "turn_response", "adaptive_noise", "measurement_bias", "novelty_noise"),
    "particles": ("n_particles", "min_particles", "kld_epsilon", "kld_confidence",
                  "resample_threshold", "resample", "alpha", "alpha_slow",
                  "alpha_fast", "injection_ratio", "max_injection", "ambiguous_injection",
                  "n_neighbors", "proposal_noise", "global_proposal_fraction", "sample_free",
                  "lost_ratio", "doubt_ratio", "confident_weight", "confirm_share",
                  "confirm_steps", "unconfirm_steps", "mode_radius", "heading_scale", "max_modes",
                  "min_mode_weight", "track_mode", "seed", "contact_motion", "free_space",
                  "contact_spread", "contact_spread_distance", "unmapped"),
}


class _SharedKwargs(dict):  # type: ignore[type-arg]
    """Constructor kwargs whose deep copy shares the values: Gymnasium deep-copies a wrapper's
    spec (and every outer wrapper's copies the inner specs), which would copy the localizer."""

    def __deepcopy__(self, memo: dict[int, Any]) -> _SharedKwargs:
        return _SharedKwargs(self)


def _nees(mean: Array, P: Array, pose: ArrayLike) -> float:
    e = np.asarray(pose, dtype=np.float64) - mean
    e[2] = wrap_angle(e[2])
    return float(e @ np.linalg.solve(P, e))


def _contact(info: Mapping[str, Any]) -> Contact:
    """What the robot touched this step: ``info["collision_with"]`` ("city", "traffic"), or
    ``info["collision"]`` (a contact of unknown kind) from an env that does not say."""
    kinds = info.get("collision_with")
    return tuple(kinds) if kinds is not None else bool(info.get("collision", False))


class _PoseObservation(RenderBelief, gym.ObservationWrapper):
    """Shared part: the belief Dict space, the observation from a mean and covariance, and
    :meth:`render` (:class:`~localization.wrapper_render.RenderBelief`)."""

    def __init__(self, env: gym.Env, keep_image: bool) -> None:
        if not isinstance(env, gym.Env):
            raise TypeError(f"env must be a gymnasium.Env (e.g. gymnasium.make(\"AppearanceNav-v0\")), "
                            f"got {type(env).__name__}")
        keep_image = check_bool(keep_image, "keep_image")
        gym.ObservationWrapper.__init__(self, env)
        space = env.observation_space
        if not (isinstance(space, spaces.Dict) and "image" in space.spaces
                and "goal" in space.spaces):
            raise ValueError(f"the env must observe Dict(image, goal), got {space}")
        self.keep_image = keep_image
        belief = {"pose_mean": spaces.Box(-np.inf, np.inf, (3,), np.float32),
                  "pose_cov": spaces.Box(-np.inf, np.inf, (6,), np.float32),
                  "goal": space["goal"]}
        if keep_image:
            belief["image"] = space["image"]
        self.observation_space = spaces.Dict(belief)
        self.mean: Array | None = None
        self.cov: Array | None = None
        RenderBelief.__init__(self)

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        """The belief observation from the env's observation and the current belief."""
        if self.mean is None or self.cov is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        out = {"pose_mean": self.mean.astype(np.float32), "pose_cov": cov_to_triu(self.cov),
               "goal": observation["goal"]}
        if self.keep_image:
            out["image"] = observation["image"]
        self._see(observation=observation)  # for render(): a reference, no copy
        return out

    def _control(self, action: Any) -> Array:
        space = self.env.action_space
        return np.clip(np.asarray(action, dtype=np.float64), space.low, space.high)

    def _add_nees(self, info: dict[str, Any]) -> None:
        if "pose" in info and self.mean is not None and self.cov is not None:
            info["nees"] = _nees(self.mean, self.cov, info["pose"])
        self._see(info=info)  # for render(): a reference, no copy


class BeliefWrapper(_PoseObservation, gym.utils.RecordConstructorArgs):
    """Replace the image observation by a pose belief from appearance.

    ``filter="ekf"``: each step the prior ``x = F(x, k U)``, ``P = F P F^T + Q(x)`` with the
    commanded (clipped) action U and the localizer's control gains k, then the EKF update
    with the measurement of the chosen model from the new image, rejected when
    ``NIS > chi2.ppf(gate_probability, dim z)`` or when the GSE maps have no value there
    (out of the training domain); see :class:`~localization.filtering.belief.BeliefFilter`.
    ``filter="particles"``: :class:`~localization.filtering.particles.ParticleBelief` on the
    same F, Q and measurement model; ``pose_mean`` / ``pose_cov`` are its dominant mode,
    never the average of distant modes. Both start from the first image (psi* of it, or
    its proposals): the true pose is never used. The observation space is the same for
    every filter.

    Parameters
    ----------
    env : gymnasium.Env
        An ``AppearanceNav-v0`` env (Dict observation with ``image`` and ``goal``;
        ``env.unwrapped.motion_model`` is F).
    localizer : AppearanceLocalizer or DistrictLocalizer
        Fitted for the same camera and image size, with its noise model
        (:meth:`~localization.localizer.AppearanceLocalizer.fit_noise`). With a
        :class:`~localization.districts.DistrictLocalizer` (a large city, one map per
        district) the EKF hands over between districts and the particles are weighed by
        their own districts' maps.
    measurement : {"pose", "features", "representation"}
        The measurement model of the update (the particles' likelihood).
    keep_image : bool
        Also pass the image through in the observation.
    gate_probability : float or None
        Chi-square probability of the NIS gate (None disables gating; EKF only). The
        particles cap their squared distances there.
    relocalize_after : int or None
        EKF: after this many consecutive steps without an accepted measurement the belief is
        re-initialised from psi* of the current image (as at reset); None never does.
    inflate_after : int or None
        EKF: from this many consecutive gated measurements on, P is inflated each step so the
        gate widens (see :class:`~localization.filtering.belief.BeliefFilter`); None never does.
    filter : {"ekf", "particles"}
    allow_other_city : bool
        Run a localizer fitted on another city (refused by default with
        :class:`~localization.localizer.OtherCityError`: the maps would alias silently).
    image_pose : bool
        Publish ``info["image_pose"]``, psi* of each image (for ``agents.ImageGuard``).
    familiar_novelty : float or None
        Report "doubtful" instead of "tracking" while the median relative novelty of the
        last 10 images exceeds this (:mod:`localization.familiarity`: images unlike the
        map's, e.g. another city's map); ``info["novelty"]`` gets each image's. None: off.
    filter_options : dict, optional
        More settings of the filter (``FILTER_OPTIONS[filter]``): for "ekf"
        ``detect_divergence`` (True: the EKF notices when it is lost and restarts where
        the images agree, method §13.1, or a dict of DivergenceMonitor settings; default
        False), ``alpha``, ``inflate_factor``, ``noise`` ("heteroscedastic": R(x, w),
        method §15.4), ``free_space`` (the map against which a contact with the city,
        ``info["collision_with"]``, can contradict the belief, at the side
        ``info["collision_bearing"]`` says it was touched: default
        ``env.unwrapped.city.free_mask``; None: contacts are ignored), ``project_contacts``
        (default True: a contradicting contact also moves the mean to the touched wall);
        for "particles" ParticleBelief's (``n_particles``, ..., ``sample_free``: default
        poses along the map's streets, from ``env.unwrapped.city.street_graph()``;
        ``seed``: default from ``reset(seed=...)``; ``free_space`` as the EKF's: a contact
        weighs the particles, and its mode tracker's EKF projects as the EKF does).

    Notes
    -----
    ``reset(options={"localize": "global"})`` starts with an unknown pose (particles: over
    the free streets and the image's proposals; EKF: the training poses' spread until the
    images agree); the other options go to the env. ``info`` gets ``nis`` (NaN when none was
    computed; always NaN for particles), ``nis_dof``, ``measurement_status`` (the filter's
    own status), ``belief_status`` ("tracking", "ambiguous", "doubtful", "lost" or
    "relocalizing", :data:`~localization.filtering.divergence.BELIEF_STATUSES`; "doubtful":
    this image alone disagrees with the belief, from the particles or the EKF with
    ``detect_divergence``), ``hypotheses``
    (``{"weights": (k,), "means": (k, 3)}``, heaviest first; one for the EKF),
    with ``image_pose=True`` ``image_pose`` (psi*(w), the pose this image alone says (3,), by
    the map in charge at the belief; NaN outside the training domain) and ``nees``
    (from ``info["pose"]``, for evaluation only).
    """

    def __init__(self, env: gym.Env, localizer: AppearanceLocalizer | DistrictLocalizer,
                 measurement: str = "representation", keep_image: bool = False,
                 gate_probability: float | None = 0.997, relocalize_after: int | None = 50,
                 inflate_after: int | None = 3, filter: str = "ekf",
                 filter_options: dict[str, Any] | None = None,
                 allow_other_city: bool = False, image_pose: bool = False,
                 familiar_novelty: float | None = None) -> None:
        # the spec refers to the localizer, as a scikit-learn meta-estimator does: Gymnasium's
        # deep copies duplicated it in every wrapper (1.1 GB a wrapper of a 60 m map); the
        # options dict is copied, its values (a free-space mask of the city, ...) are not
        gym.utils.RecordConstructorArgs.__init__(
            self, localizer=localizer, measurement=measurement, keep_image=keep_image,
            gate_probability=gate_probability, relocalize_after=relocalize_after,
            inflate_after=inflate_after, filter=filter, filter_options=dict(filter_options)
            if isinstance(filter_options, Mapping) else filter_options,
            allow_other_city=allow_other_city, image_pose=image_pose,
            familiar_novelty=familiar_novelty, _disable_deepcopy=True)
        self._saved_kwargs = _SharedKwargs(self._saved_kwargs)
        check_choice(measurement, "measurement", MEASUREMENTS)
        check_choice(filter, "filter", FILTERS)
        options = check_options(filter_options, f"filter_options of filter {filter!r}",
                                FILTER_OPTIONS[filter])
        gate_probability = check_gate_probability(gate_probability)
        _PoseObservation.__init__(self, env, keep_image)
        check_compatible(env, localizer)
        localizer.check_city(city_info(env), allow_other_city=check_bool(
            allow_other_city, "allow_other_city"))
        self.localizer = localizer
        self.image_pose = check_bool(image_pose, "image_pose")
        self.familiarity = None if familiar_novelty is None else Familiarity(
            single_map(localizer, "familiar_novelty").regressor_, familiar_novelty)
        self.measurement = measurement
        self.filter = filter
        mm = env.unwrapped.motion_model
        if "free_space" not in options and hasattr(env.unwrapped, "city"):
            options["free_space"] = env.unwrapped.city.free_mask
        if filter == "ekf":
            self.belief: BeliefFilter | ParticleBelief = BeliefFilter(
                localizer, mm, measurement, gate_probability, relocalize_after,
                inflate_after=inflate_after, **options)
        else:
            if gate_probability is None:
                raise ValueError("filter 'particles' needs a gate_probability in (0, 1) "
                                 "(its distances are capped there), got None")
            if "sample_free" not in options and hasattr(env.unwrapped, "city"):
                options["sample_free"] = city_sampler(env.unwrapped.city)
            self._seeded = "seed" in options
            self.belief = ParticleBelief(localizer, mm, measurement,
                                         gate_probability=gate_probability, **options)
        self._dof = int(np.asarray(localizer.noise_["features"]).shape[0]) \
            if measurement == "features" else 3
        self.belief_status = "tracking"
        self._localize = "image"

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None,
              ) -> tuple[dict[str, Any], dict[str, Any]]:
        """Reset the env and start the belief from the first image (see the class Notes).

        If the first image is outside the training domain the EKF starts at the centre
        of the training poses with their spread as covariance (status "out_of_domain").
        """
        options = dict(options) if options is not None else None
        localize = "image" if options is None else options.pop("localize", "image")
        self._localize = check_choice(localize, "options['localize']", LOCALIZE)
        seed = check_seed(seed, "seed", optional=True)
        obs, info = self.env.reset(seed=seed, options=options)
        w = self.localizer.transform(obs["image"])[0]
        if isinstance(self.belief, ParticleBelief) and seed is not None and not self._seeded:
            self.belief.rng = np.random.default_rng([seed, 0x5EED])
        status = self.belief.reset(w, mode=localize)
        if self.familiarity is not None:
            self.familiarity.reset()
        self._publish(info, np.nan, status, w)
        return self.observation(obs), info

    def step(self, action: Any) -> tuple[dict[str, Any], SupportsFloat, bool, bool,
                                         dict[str, Any]]:
        """Step the env, then predict with F(x, k U) and update with the new image."""
        if self.mean is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        obs, reward, terminated, truncated, info = self.env.step(action)
        w = self.localizer.transform(obs["image"])[0]
        nis, status = self.belief.step(self._control(action), w, contact=_contact(info),
                                       bearing=info.get("collision_bearing"))
        self._publish(info, nis if self.filter == "ekf" else np.nan, status, w)
        return self.observation(obs), reward, terminated, truncated, info

    @property
    def ekf(self) -> PoseEKF | None:
        """The underlying EKF (None before reset, and for the particle filter)."""
        return getattr(self.belief, "ekf", None)

    @property
    def hypotheses(self) -> dict[str, Array]:
        """``{"weights": (k,), "means": (k, 3)}``, heaviest first (one for the EKF)."""
        if isinstance(self.belief, ParticleBelief):
            h = self.belief.hypotheses
            return {"weights": h["weights"], "means": h["means"]}
        return {"weights": np.ones(1), "means": self.belief.x[None]}

    @property
    def render_title(self) -> str:
        """The first status line of :meth:`render`'s frames."""
        return f"{self.filter} belief"

    def _publish(self, info: dict[str, Any], nis: float, status: str, w: Array) -> None:
        self.mean, self.cov = self.belief.x, self.belief.P
        if self.image_pose:  # one more GSE query a step (0.5 ms on a 40000-image map): asked for
            maps = self.localizer.local(self.mean, w) if isinstance(
                self.localizer, DistrictLocalizer) else self.localizer
            info["image_pose"] = maps.measure(w, "pose")
        self.belief_status = self.belief.belief_status
        if self.familiarity is not None:
            info["novelty"] = self.familiarity.update(w)
            self.belief_status = self.familiarity.status(self.belief_status)
        info["nis"] = float(nis)
        info["nis_dof"] = self._dof
        info["measurement_status"] = status
        info["belief_status"] = self.belief_status
        info["hypotheses"] = self.hypotheses
        self._add_nees(info)


class OracleWrapper(_PoseObservation, gym.utils.RecordConstructorArgs):
    """The true pose as the belief, with a fixed small covariance (an upper bound).

    Parameters
    ----------
    env : gymnasium.Env
        Reports the true pose in ``info["pose"]``.
    std : (float, float, float)
        Standard deviations of x, y (m) and yaw (rad) put in ``pose_cov``.
    keep_image : bool
    """

    render_title = "oracle: the true pose"

    def __init__(self, env: gym.Env, std: tuple[float, float, float] = (0.01, 0.01, 0.005),
                 keep_image: bool = False) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, std=std, keep_image=keep_image)
        _PoseObservation.__init__(self, env, keep_image)
        std_a = np.asarray(std, dtype=np.float64)
        if std_a.shape != (3,) or not np.all(np.isfinite(std_a)) or np.any(std_a <= 0):
            raise ValueError(f"std must be 3 positive numbers, got {std}")
        self._P = np.diag(std_a ** 2)

    def _set(self, info: dict[str, Any]) -> None:
        if "pose" not in info:
            raise KeyError("OracleWrapper needs info['pose'] from the env")
        self.mean, self.cov = np.asarray(info["pose"], dtype=np.float64).copy(), self._P.copy()
        self._add_nees(info)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None,
              ) -> tuple[dict[str, Any], dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self._set(info)
        return self.observation(obs), info

    def step(self, action: Any) -> tuple[dict[str, Any], SupportsFloat, bool, bool,
                                         dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._set(info)
        return self.observation(obs), reward, terminated, truncated, info


class DeadReckoningWrapper(_PoseObservation, gym.utils.RecordConstructorArgs):
    """Dead reckoning: the motion model F alone from the true start pose.

    ``x = F(x, U)``, ``P = F P F^T + Q(x)`` every step with the commanded (clipped) action;
    ``Q(x) = T(yaw) Q_body T(yaw)^T`` (:func:`localization.filtering.process_noise.world_process_noise`).

    Parameters
    ----------
    env : gymnasium.Env
        Reports the true pose in ``info["pose"]`` at reset (used once, for the start).
    process_noise_body : array_like (3, 3)
        Body-frame process noise ``Q_body``, e.g. ``localizer.process_noise_body_``.
    initial_std : (float, float, float)
        Standard deviations of the start pose (x, y, yaw) in ``pose_cov`` at reset.
    control_gain : (float, float)
        Calibrated control gains k: F predicts with ``k U`` (``localizer.control_gain_``).
    keep_image : bool
    """

    render_title = "dead reckoning: F alone"

    def __init__(self, env: gym.Env, process_noise_body: ArrayLike,
                 initial_std: tuple[float, float, float] = (0.01, 0.01, 0.005),
                 control_gain: tuple[float, float] = (1.0, 1.0),
                 keep_image: bool = False) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self, process_noise_body=process_noise_body, initial_std=initial_std,
            control_gain=control_gain, keep_image=keep_image)
        _PoseObservation.__init__(self, env, keep_image)
        std = np.asarray(initial_std, dtype=np.float64)
        if std.shape != (3,) or not np.all(np.isfinite(std)) or np.any(std <= 0):
            raise ValueError(f"initial_std must be 3 positive numbers, got {initial_std}")
        self._P0 = np.diag(std ** 2)
        Q = np.asarray(process_noise_body, dtype=np.float64)
        if Q.shape != (3, 3) or not np.all(np.isfinite(Q)):
            raise ValueError(f"process_noise_body must be a finite (3, 3) matrix, got {Q.shape}")
        self.process_noise_body = Q
        gain = np.asarray(control_gain, dtype=np.float64)
        if gain.shape != (2,) or not np.all(np.isfinite(gain)):
            raise ValueError(f"control_gain must be 2 finite numbers, got {control_gain}")
        self.control_gain = gain
        self.motion_model = env.unwrapped.motion_model
        self.ekf: PoseEKF | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None,
              ) -> tuple[dict[str, Any], dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        if "pose" not in info:
            raise KeyError("DeadReckoningWrapper needs info['pose'] from the env at reset")
        Q = lambda x, u: world_process_noise(self.process_noise_body, x)
        self.ekf = PoseEKF(self.motion_model, Q, info["pose"], self._P0, gate_probability=None)
        self.mean, self.cov = self.ekf.x.copy(), self.ekf.P.copy()
        self._add_nees(info)
        return self.observation(obs), info

    def step(self, action: Any) -> tuple[dict[str, Any], SupportsFloat, bool, bool,
                                         dict[str, Any]]:
        if self.ekf is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.ekf.predict(self.control_gain * self._control(action))
        self.mean, self.cov = self.ekf.x.copy(), self.ekf.P.copy()
        self._add_nees(info)
        return self.observation(obs), reward, terminated, truncated, info
