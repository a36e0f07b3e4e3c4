"""BeliefFilter: the pose belief from appearance, one image at a time (no Gym inside).

It runs :class:`~localization.filtering.ekf.PoseEKF` with an
:class:`~localization.localizer.AppearanceLocalizer`: the prior of each step is
``x = F(x, k U)``, ``P = F P F^T + Q(x)`` (``k`` the localizer's calibrated control
gains), then the chosen measurement model updates it with the new image's features,
unless the NIS gate rejects the measurement or the GSE maps have no value there (the
image or the predicted pose lies outside the training domain).

Recovery (docs/method.md §13): from the ``inflate_after``-th rejection in a row the heading
variance grows by ``inflate_factor`` a step, up to ``MAX_HEADING_STD`` (a gate that rejects
the truth after a heading kick keeps rejecting it); only the heading (inflating the position
let aliased measurements through). After ``relocalize_after`` steps without an accepted
measurement the belief restarts at psi* of the current image, on trial against the belief it
replaced (:mod:`~localization.filtering.restart_trial`); the start from the first image is on
trial too, with nothing to come back to. Five steps without one make it "doubtful" while P
is narrow and "lost" once its position is too uncertain to steer on (the heading inflation
alone never gets there), or for a while after a contact where the map (``free_space``) has
room around it (:mod:`~localization.filtering.map_contact`). Divergence detection
(``detect_divergence``, :mod:`~localization.filtering.divergence`; off by default) grades
the images' evidence against the belief and restarts it where the window's images agree, or
widens P towards them when they agree a little off it (its drift test, off by default: a shove).
``belief_status`` is one of ``BELIEF_STATUSES``; a start with ``mode="global"`` is
"relocalizing" from the training poses' spread until the images agree.

:class:`~localization.wrappers.BeliefWrapper` drives it from an env;
:meth:`AppearanceLocalizer.fit_noise` runs it over a recorded drive to calibrate the noise.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from localization._validation import check_bool, check_choice, check_int, check_real
from localization.filtering._belief_contact import BeliefContactMixin
from localization.filtering._belief_recovery import (  # noqa: F401 (MAX_*: the belief's)
    MAX_HEADING_STD,
    RecoveryMixin,
)
from localization.filtering._belief_status import (  # noqa: F401 (LOST_*: the belief's names)
    LOST_AFTER_MISSES,
    LOST_HEADING_STD,
    LOST_POSITION_STD,
    StatusMixin,
)
from localization.filtering.adaptive_noise import innovation_scale
from localization.filtering.divergence import monitor_for
from localization.filtering.ekf import (
    OutOfDomainError,
    PoseEKF,
    UpdateResult,
    check_gate_probability,
    check_motion_model,
)
from localization.filtering.familiar_start import (
    FamiliarStartMixin,
    ImageStart,
    check_familiar_novelty,
)
from localization.filtering.heading_check import check_heading_check, turns_away
from localization.filtering.localizer_protocol import Localizer, check_localizer
from localization.filtering.map_contact import (
    CONTACT_MOTIONS,
    REPEAT_CONTACT_STEPS,
    Contact,
    FreeSpace,
    blocked_motion,
    check_bearing,
    check_free_space,
    contact_kinds,
)
from localization.filtering.measurement_bias import make_ekf, measurement_bias_for
from localization.filtering.novelty_noise import novelty_noise as novelty_noise_for
from localization.filtering.particle_start import DEFAULT_P0
from localization.filtering.recorded_run import run_recorded
from localization.filtering.restart_trial import RestartTrial, ViewOdometer
from localization.filtering.turn_response import TurnResponse, turn_response_for
from localization.geometry import Array

STATUSES = ("initial", "accepted", "gated", "out_of_domain", "relocalized", "reverted")
NOISE_MODELS = ("global", "heteroscedastic")
RESET_MODES = ("image", "global")


class BeliefFilter(RecoveryMixin, StatusMixin, FamiliarStartMixin, BeliefContactMixin):
    """EKF pose belief fed with image features.

    Parameters
    ----------
    localizer : Localizer
        Fitted, with its noise model (``fit_noise`` or ``fit_process_noise``).
    motion_model : object
        F: ``predict(x, u)``, ``jacobian_pose(x, u)`` (the env's ``motion_model``).
    measurement : {"pose", "features", "representation"}
    gate_probability : float or None
        NIS gate (None: no gate).
    relocalize_after : int or None
        Consecutive steps without an accepted measurement before the belief restarts from
        psi* (None: never).
    inflate_after : int or None
        Consecutive gated steps from which the heading variance is inflated (None: never).
    inflate_factor : float
        Factor of the heading variance per further gated step.
    alpha : array_like (3,), optional
        Body-frame covariance inflation (along, cross, heading) of Q, R and P0; default the
        localizer's calibrated ``consistency_[measurement]``.
    detect_divergence : bool or dict
        Run a :class:`~localization.filtering.divergence.DivergenceMonitor` (a dict: its
        settings); False: off (the EKF as before).
    noise : {"global", "heteroscedastic"}
        The measurement noise: one R per model, or R(x) scaled where the maps are weak
        (the localizer's ``measurement_model(..., noise="heteroscedastic")``; a localizer
        fitted with ``noise_folds >= 2``).
    adaptive_noise : bool or dict
        Scale that R up while the accepted innovations are larger than it predicts
        (:class:`~localization.filtering.adaptive_noise.InnovationScale`; a dict: its
        settings). False: off.
    measurement_bias : bool or dict
        Carry a persistent (AR(1)) bias of the measurement beside the pose
        (:mod:`~localization.filtering.measurement_bias`; a dict: ``rho``, ``phi``): maps
        that err in runs do not make the belief over-confident. False: off.
    novelty_noise : bool or dict
        Scale R by the image's novelty beyond that of the frames R came from
        (:class:`~localization.filtering.novelty_noise.NoveltyNoise`; a dict: its settings;
        a localizer of one map fitted with ``fit_noise``). False: off.
    free_space : callable, optional
        The map, ``free_space(points (n, 2), margin) -> (n,) bool`` (``city.free_mask``): a
        contact where it has room around the belief makes it "lost". None: no contact makes
        it lost.
    contact_motion : {"blocked", "commanded"}
        How a contact step is predicted: "blocked" (no translation, the commanded step as
        one standard deviation: :func:`~localization.filtering.map_contact.blocked_motion`),
        or with the commanded control as any other step.
    project_contacts : bool
        With ``free_space``: a contradicting contact with a known bearing also moves the
        belief's mean to the nearest pose (in P's metric) at which the map explains it
        (:func:`~localization.filtering.map_contact.contact_projection`; P kept): a pushed
        robot's belief moves to the wall it touches (docs/method.md §13). False: the
        contact only makes the belief "lost".
    heading_check : float or None
        With the "representation" model: check each update against the image's own psi* by
        the same map (:mod:`~localization.filtering.heading_check`): an image without psi*
        is "out_of_domain", an update turning the heading more than this (rad) away from
        psi*'s is undone ("gated"). None: off.
    familiar_novelty : float or None
        Restarts rest on familiar images (:mod:`~localization.filtering.familiar_start`;
        a localizer with ``initial_candidate``): an image whose relative novelty exceeds
        this is unfamiliar; a start from the first image is then unverified until a familiar
        image's psi* agrees with the belief (else the belief restarts there), and every other
        restart from an image needs a familiar one. None: off (every in-domain image).
    turn_response : bool or TurnResponse
        Predict the turn rate the robot really turns at for U
        (:mod:`localization.filtering.turn_response`; True: the env's robot): ``k U`` becomes
        ``[k_v v, r(v, w)]`` (a steady-state table: method §13.6). False: ``k U``.

    Attributes
    ----------
    ekf : PoseEKF or None
        None before :meth:`reset`.
    model : measurement model or None
        The one of the last update (a localizer with ``local``: None before it).
    last_update : UpdateResult or None
    belief_status : one of ``BELIEF_STATUSES``
    monitor : DivergenceMonitor or None
    bias : MeasurementBias or None
        The ``measurement_bias`` settings (the EKF is then a ``BiasedPoseEKF``).
    """

    def __init__(self, localizer: Localizer, motion_model: Any,
                 measurement: str = "representation",
                 gate_probability: float | None = 0.997, relocalize_after: int | None = 50,
                 alpha: ArrayLike | None = None, inflate_after: int | None = 3,
                 inflate_factor: float = 2.0,
                 detect_divergence: bool | dict[str, Any] = False,
                 noise: str = "global", free_space: FreeSpace | None = None,
                 contact_motion: str = "blocked", project_contacts: bool = True,
                 heading_check: float | None = None,
                 familiar_novelty: float | None = None,
                 turn_response: bool | TurnResponse = False,
                 adaptive_noise: bool | dict[str, Any] = False,
                 measurement_bias: bool | dict[str, Any] = False,
                 novelty_noise: bool | dict[str, Any] = False) -> None:
        check_localizer(localizer)
        check_choice(noise, "noise", NOISE_MODELS)
        self.contact_motion = check_choice(contact_motion, "contact_motion", CONTACT_MOTIONS)
        motion_model = check_motion_model(motion_model)
        gate_probability = check_gate_probability(gate_probability)
        if relocalize_after is not None:
            relocalize_after = check_int(relocalize_after, "relocalize_after", low=1)
        if inflate_after is not None:
            inflate_after = check_int(inflate_after, "inflate_after", low=1)
        inflate_factor = check_real(inflate_factor, "inflate_factor", low=1.0)
        self.inflate_after, self.inflate_factor = inflate_after, float(inflate_factor)
        self.localizer, self.motion_model, self.measurement = localizer, motion_model, measurement
        self.gate_probability, self.relocalize_after = gate_probability, relocalize_after
        self.alpha = localizer.consistency(measurement) if alpha is None else \
            np.asarray(alpha, dtype=np.float64)
        self.noise = noise
        self.adaptive = innovation_scale(adaptive_noise)
        self.bias = measurement_bias_for(measurement_bias)
        self.novelty = novelty_noise_for(novelty_noise, localizer)
        self._models: dict[int, Any] = {}  # measurement model per (district) localizer
        self.model = None if callable(getattr(localizer, "local", None)) else \
            self._local(None)[1]
        self.gain = np.asarray(localizer.control_gain_, dtype=np.float64)
        self.ekf: PoseEKF | None = None
        self.last_update: UpdateResult | None = None
        self.misses = self.gated = 0
        self.monitor = monitor_for(detect_divergence)
        if self.monitor is not None and callable(getattr(localizer, "local", None)):
            raise ValueError("detect_divergence is not supported with a localizer of several "
                             "maps (DistrictLocalizer): on a 60 m city its restarts jumped to "
                             "look-alike places in other districts (docs/method.md §12.1)")
        self.belief_status = "tracking"
        self._confirm = 0
        self._forced = self._lost_now = self._doubtful_now = False
        self._placed = False  # True once the belief came from an image or x0 (not the prior)
        self._trial: RestartTrial | None = None  # a restart on trial
        self._refused: ViewOdometer | None = None  # odometry since a stalled trial
        self._repeat_view = False  # this step's accepted image was a repeat of the trial's
        self.free_space = check_free_space(free_space)
        self.heading_check = check_heading_check(heading_check, measurement)
        self.familiar_novelty = check_familiar_novelty(familiar_novelty, localizer)
        self.turn_response = turn_response_for(turn_response)
        self._unverified = False  # a start from an unfamiliar image, not yet checked
        self.project_contacts = check_bool(project_contacts, "project_contacts")
        self._bumped = 0  # steps left "lost" after a contact that contradicts the belief
        self._since_contact = REPEAT_CONTACT_STEPS + 1  # steps since the last city contact

    @property
    def x(self) -> Array:
        """Belief mean [x, y, yaw] (3,)."""
        self._check()
        return self.ekf.x.copy()  # type: ignore[union-attr]

    @property
    def P(self) -> Array:
        """Belief covariance (3, 3)."""
        self._check()
        return self.ekf.P.copy()  # type: ignore[union-attr]

    @property
    def images_doubt(self) -> bool:
        """The divergence monitor called the last step's images doubtful (its NIS, drift or
        offset tests; False without a monitor)."""
        return self._doubtful_now

    def _check(self) -> None:
        if self.ekf is None:
            raise RuntimeError("the belief is not initialised: call reset() first")

    def _local(self, x: Array | None, w: Array | None = None) -> tuple[Localizer, Any]:
        """The localizer in charge at pose ``x`` for the image ``w`` and its measurement
        model: the localizer, or its ``local(x, w)`` (a district's map at ``x``, or the
        look of an :class:`~localization.experiences.ExperienceLocalizer` most like ``w``)."""
        local = getattr(self.localizer, "local", None)
        view = self.localizer if x is None or not callable(local) else local(x, w)
        model = self._models.get(id(view))
        if model is None:
            options = {} if self.noise == "global" else {"noise": self.noise}
            model = view.measurement_model(self.measurement, alpha=self.alpha, **options)
            self._models[id(view)] = model
        return view, model

    def _measurement(self, x: Array, w: Array) -> tuple[Array, Any, Localizer]:
        """The measurement z of image ``w``, its model and the localizer in charge at ``x``
        that made both; the model has observed ``w``."""
        view, model = self._local(x, w)
        z = view.measure(w, self.measurement)
        observe = getattr(model, "observe", None)
        if callable(observe) and np.all(np.isfinite(z)):
            observe(w)  # an R that depends on the image (heteroscedastic)
        return z, model, view

    def _Q(self, x: Array, u: Array) -> Array:
        return self.localizer.process_noise(x, alpha=self.alpha)

    def _start(self, x0: ArrayLike, P0: ArrayLike) -> None:
        self.ekf = make_ekf(self.motion_model, self._Q, x0, P0, self.gate_probability,
                            self.bias)
        self.misses = self.gated = self._bumped = 0
        self._confirm, self._forced, self._placed = 0, False, True
        if self.adaptive is not None:
            self.adaptive.reset()
        if self.monitor is not None:
            self.monitor.clear()

    def _from_image(self, w: Array, first: bool = False,
                     start: ImageStart | None = None) -> bool:
        """Start at psi*(w) with its noise, unconfirmed: "relocalizing" and on trial with
        nothing to come back to (:meth:`_on_trial` starts again at a later image's psi* unless
        this one is confirmed). False (nothing changed) when psi*(w) is out of domain, or with
        ``familiar_novelty`` when the image is unfamiliar (but the ``first``: unverified).
        ``start``: :meth:`_image_start` of ``w`` when already known."""
        x0, P0, familiar = self._image_start(w) if start is None else start
        if not np.all(np.isfinite(x0)) or not (familiar or first):
            return False
        self._start(x0, P0)
        self._unverified = not familiar
        self._put_on_trial(None, 0)
        self.belief_status = "relocalizing"
        return True

    def reset(self, w: ArrayLike, x0: ArrayLike | None = None, P0: ArrayLike | None = None,
              mode: str = "image") -> str:
        """Start the belief from the first image's features ``w`` (m,): psi*(w) with its
        noise, or from ``x0``, ``P0`` when given (e.g. a known start for calibration).

        If psi*(w) is out of domain the belief starts at the centre of the training poses
        with their spread as covariance and relocalizes at the next in-domain image.
        ``mode="global"`` (an unknown start, ``x0`` not allowed) starts there too, with
        ``belief_status`` "relocalizing": with ``detect_divergence`` the belief restarts
        where the first images agree; without, at the next image's psi*.

        Returns
        -------
        status : "initial" or "out_of_domain"
        """
        if mode not in RESET_MODES:
            raise ValueError(f"unknown reset mode {mode!r}; choose one of {RESET_MODES}")
        if mode == "global" and x0 is not None:
            raise ValueError("mode='global' starts from an unknown pose: do not pass x0")
        self.last_update, self._trial, self._refused = None, None, None
        self.belief_status, self._unverified = "tracking", False
        self._since_contact = REPEAT_CONTACT_STEPS + 1  # a new episode: no bump before
        if x0 is not None:
            self._start(x0, P0 if P0 is not None else DEFAULT_P0.copy())
            return "initial"
        if mode == "image" and self._from_image(np.asarray(w, dtype=np.float64), first=True):
            return "initial"
        mean, cov = self.localizer.prior()
        self._start(mean, cov)
        self._placed = False
        if self.monitor is not None and mode == "global":
            self._forced = True  # restart where the images agree
        else:
            self.misses = self.relocalize_after or 0
        if mode == "global":
            self.belief_status = "relocalizing"
            return "initial"
        return "out_of_domain"

    def step(self, u: ArrayLike, w: ArrayLike, contact: Contact = False,
             bearing: float | None = None) -> tuple[float, str]:
        """Predict with the commanded control ``u`` (2,), update with the new features ``w``.

        ``contact``: what the robot touched this step (``info["collision_with"]``, e.g.
        ``("traffic",)``; True for a contact of unknown kind, taken as the city's): the
        step is predicted as ``contact_motion`` says (a mover may also have pushed and
        turned the robot); with ``free_space``, a contact with the city where the map has
        room around the belief makes it "lost" for ``CONTACT_LOST_STEPS`` steps; so does,
        with or without a map, a second contact with the city within
        ``REPEAT_CONTACT_STEPS`` while not "tracking"
        (:mod:`~localization.filtering.map_contact`); ``bearing`` (rad from the heading,
        ``info["collision_bearing"]``; None or NaN: unknown) says where the robot was
        touched, so that only the map at that side of the belief explains the contact.

        Returns
        -------
        nis : float
            NaN when no NIS was computed (out of domain).
        status : "accepted", "gated", "out_of_domain", "relocalized" or "reverted" (a
            divergence restart undone: the images after it did not confirm it)
        """
        self._check()
        assert self.ekf is not None
        kinds, bearing = contact_kinds(contact), check_bearing(bearing)
        motion = self._step_motion(u, kinds)
        self.ekf.predict(*motion)
        self._track_refused(motion)
        self._repeat_view = False
        w = np.asarray(w, dtype=np.float64)
        nis, status = self._update(w)
        self.gated = self.gated + 1 if status == "gated" else 0
        if self.inflate_after is not None and self.gated >= self.inflate_after:
            self._inflate_heading()
        if status == "accepted":
            self.misses = 0
        else:
            self.misses += 1
            if self.relocalize_after is not None and self.misses >= self.relocalize_after:
                status = self._relocalize(w, status)
        self._lost_now = self._doubtful_now = False
        if status == "relocalized":
            self.belief_status = "relocalizing"
        elif self._trial is not None:
            status = self._on_trial(motion, w, status)
        elif self.monitor is not None:
            status = self._watch(motion, w, nis, status)
        self._contact(kinds, bearing)
        self._update_status(status)
        if self._unverified and status != "relocalized":
            status = self._verify_start(w, status)
        return nis, status

    def _step_motion(self, u: ArrayLike, kinds: frozenset[str]) -> tuple[Array, Array | None]:
        """The control ``k U`` of this step and its extra process noise (a contact's, of
        ``kinds``, with ``contact_motion="blocked"``; None otherwise)."""
        u = np.asarray(u, dtype=np.float64)
        u_k = self.gain * u
        if self.turn_response is not None:
            u_k[1] = self.turn_response(u)
        if kinds and self.contact_motion == "blocked":
            assert self.ekf is not None
            return blocked_motion(self.motion_model, self.ekf.x, u_k, "traffic" in kinds)
        return u_k, None

    def _update(self, w: Array) -> tuple[float, str]:
        assert self.ekf is not None
        z, self.model, view = self._measurement(self.ekf.x, w)
        psi = None if self.heading_check is None or not np.all(np.isfinite(z)) else \
            view.measure(w, "pose")  # psi* by the same map: the heading check's reference
        if not (np.all(np.isfinite(z)) and (psi is None or np.all(np.isfinite(psi)))):
            return np.nan, "out_of_domain"
        prior = self.ekf.snapshot()
        try:
            model = self.model if self.novelty is None else \
                self.novelty.wrap(self.model, view, w)
            self.last_update = self.ekf.update(z, model if self.adaptive is None
                                               else self.adaptive.wrap(model))
        except OutOfDomainError:
            return np.nan, "out_of_domain"
        accepted = self.last_update.accepted
        if accepted and psi is not None and turns_away(prior[0][2], self.ekf.x[2], psi[2],
                                                       self.heading_check):
            self.ekf.restore(prior)  # the update read the image as a turn psi* denies
            accepted = False
        if accepted and self.adaptive is not None:
            u = self.last_update
            self.adaptive.record(u.nis, u.dim_z, u.threshold)
        return self.last_update.nis, "accepted" if accepted else "gated"

    def run(self, W: ArrayLike, controls: ArrayLike, x0: ArrayLike | None = None,
            P0: ArrayLike | None = None) -> tuple[Array, Array, list[str]]:
        """Filter a recorded sequence: features ``W`` (n + 1, m) of frames 0..n and the
        controls (n, 2) between them.

        Returns
        -------
        means : (n + 1, 3)
        covs : (n + 1, 3, 3)
        statuses : list of n + 1 str
        """
        return run_recorded(self, W, controls, lambda w: self.reset(w, x0, P0))

