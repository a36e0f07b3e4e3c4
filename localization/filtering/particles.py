"""ParticleBelief: a multi-hypothesis pose belief from appearance (Monte Carlo localization).

No Gym inside, like :class:`~localization.filtering.belief.BeliefFilter`, with the same
localizer (:class:`~localization.localizer.AppearanceLocalizer`). N particles ``X_i`` with
log-weights ``l_i``; with the names of the code::

    predict:  X_i = F(X_i, k U) + T(yaw_i) e_i,   e_i ~ N(0, Q),  Q = diag(sqrt a) Q_body diag(sqrt a)
    weight:   l_i = l_i + log L_i,   l = l - logsumexp(l)           (weights w_i = exp(l_i))
              log L_i = -0.5 min(d2_i, gate),   gate = chi2.ppf(gate_probability, dof)
    bump:     l_i = l_i + log B_i on a contact with the city (``free_space``): B_i = 1 where
              the map has a wall at the particle's touched point, CONTACT_MISS where it has
              room; "lost" for CONTACT_LOST_STEPS when that room holds > CONTACT_WEIGHT,
              and then first resampled with a share contact_spread moved to the walls
              the contact could have come from (:mod:`~.contact_spread`)
    AMCL:     w_avg = sum_i w_i L_i / sum_i w_i  (i over the particles not injected last step)
              w_slow += alpha_slow (w_avg - w_slow),  w_fast += alpha_fast (w_avg - w_fast)
              inject p = min(max_injection, max(0, 1 - w_fast / (injection_ratio w_slow)))
              of the particles at the image's proposals; max(p, ambiguous_injection) while
              the dominant mode is unconfirmed
    resample: when ESS = 1 / sum w_i^2 < resample_threshold N, or particles are injected;
              with ``min_particles``, N then follows the resampled set's spread (KLD-sampling)

(k the localizer's ``control_gain_``, a its calibrated ``consistency(measurement)``;
the averages: :mod:`localization.filtering.augmented_mcl`).
``d2_i`` and ``L_i``: :mod:`localization.filtering.particle_likelihood` (outliers capped at the
gate, never NaN). Proposals of an image (Augmented MCL's injections, the start): psi*(w) and the
training poses of the ``n_neighbors`` nearest training images in feature space, jittered by
``proposal_noise`` (body frame). ``pose_mean`` / ``pose_cov`` describe the heaviest mode
(:mod:`localization.filtering._modes`), never the average of distant modes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from filterpy.monte_carlo import systematic_resample
from numpy.typing import ArrayLike
from sklearn.exceptions import NotFittedError

from localization._validation import check_array, check_choice, check_int, check_real
from localization.filtering._modes import Mode, find_modes
from localization.filtering._particle_contact import ParticleContactMixin
from localization.filtering._particle_state import ParticleStateMixin
from localization.filtering._particle_status import PARTICLE_STATUSES, ParticleStatusMixin
from localization.filtering.augmented_mcl import LikelihoodAverages
from localization.filtering.contact_spread import ContactSpread
from localization.filtering.district_particles import check_measurement_noise, image_models
from localization.filtering.kld_sampling import KLDSampling
from localization.filtering.log_weights import log_sum_exp, normalise_log_weights
from localization.filtering.map_contact import (
    CONTACT_MOTIONS,
    Contact,
    FreeSpace,
    blocked_motion,
    check_bearing,
    check_free_space,
    contact_kinds,
)
from localization.filtering.measurement_noise import inflate
from localization.filtering.mode_confirmation import ModeConfirmation
from localization.filtering.mode_tracker import make_tracker
from localization.filtering.particle_likelihood import (
    MEASUREMENTS,
    capped_log_likelihood,
    check_unmapped,
    unmapped_d2,
)
from localization.filtering.particle_motion import is_unicycle, move_particles
from localization.filtering.particle_start import SampleFree, free_particles, gaussian_particles
from localization.filtering.recorded_run import run_recorded
from localization.filtering.resampling import resample_and_inject
from localization.geometry import Array, wrap_angle

__all__ = ["PARTICLE_STATUSES", "ParticleBelief"]

RESET_MODES = ("image", "global")


class ParticleBelief(ParticleContactMixin, ParticleStatusMixin, ParticleStateMixin):
    """Particle-filter pose belief fed with image features (see the module docstring).

    Parameters
    ----------
    localizer : AppearanceLocalizer
        Fitted, with its noise model (``fit_noise`` or ``fit_process_noise``).
    motion_model : object
        F: ``predict(x, u)`` (the env's ``motion_model``); vectorised when it is a unicycle.
    measurement : {"representation", "pose", "features"}
    n_particles : int
        The particles of a start, and the most there are.
    min_particles : int or None
        KLD-sampling (:mod:`localization.filtering.kld_sampling`, AMCL's adaptive count):
        after each resampling N becomes Fox's bound on the bins the particles occupy,
        clamped to ``[min_particles, n_particles]`` (AMCL's default 500, kept after tuning
        cities 13-14, docs/method.md §13.2). None, or not below ``n_particles``: N stays
        ``n_particles``.
    kld_epsilon, kld_confidence : float in (0, 1)
        The bound's KL distance and probability (AMCL's ``pf_err`` and ``pf_z``).
    resample_threshold : float in (0, 1]
        Resample when ESS < resample_threshold * N (N: the current count).
    resample : callable
        ``filterpy.monte_carlo`` scheme, weights (N,) -> indexes (N,).
    gate_probability : float in (0, 1)
        Squared distances are capped at ``chi2.ppf(gate_probability, dof)``.
    alpha : array_like (3,), optional
        Body-frame inflation of Q and R; default ``localizer.consistency(measurement)``.
    alpha_slow, alpha_fast : float
        Augmented MCL's averaging rates, ``0 < alpha_slow < alpha_fast <= 1``.
    injection_ratio : float in (0, 1]
        Inject once w_fast falls below injection_ratio * w_slow (1: Thrun's rule).
    max_injection : float in [0, 1]
        Cap of the injected fraction per step (0: never inject).
    ambiguous_injection : float in [0, 1]
        While the dominant mode is unconfirmed (see ``confirm_share``), at least this share
        of the particles is replaced each step by the image's proposals, so that every
        place the images point to keeps particles until a landmark confirms one (Augmented
        MCL does not inject on a wrong twin: the likelihood does not fall there). It does
        not count as relocalizing, nor restart the confirmation.
    n_neighbors : int
        Training images retrieved as proposals.
    proposal_noise : array_like (3, 3), optional
        Body-frame jitter of the proposals; default the representation model's R.
    global_proposal_fraction : float in [0, 1]
        Share of the particles a global start draws from the image's proposals.
    sample_free : callable, optional
        ``sample_free(n, rng) -> (n, 3)`` free poses for a global start; default the
        localizer's training poses (jittered by ``proposal_noise``).
    lost_ratio, doubt_ratio, confident_weight : float
        Status thresholds (see ``PARTICLE_STATUSES``).
    confirm_share : float in [0, 1]; confirm_steps : int; unconfirm_steps : int or None
        When the images confirm a dominant mode seeded from them (until then the status is
        at best "ambiguous"): :class:`~localization.filtering.mode_confirmation.ModeConfirmation`.
    mode_radius, heading_scale : float
        Mode kernel (m) and metres per radian (:func:`~localization.filtering._modes.find_modes`).
    max_modes : int; min_mode_weight : float in (0, 1)
        At most ``max_modes`` hypotheses are summarised, down to ``min_mode_weight`` of
        weight left (the rest of the weight is in none).

    Every default of the status, confirmation, injection and summary was chosen on tuning
    cities 11-16 (14-16 look-alike); docs/method.md §13.2 gives the numbers.
    seed : int or None
        Seeds every draw (numpy Generator); the same seed gives the same run.
    contact_motion : {"blocked", "commanded"}
        How a contact step moves the particles: blocked (``[0, k w]`` plus a draw of
        :func:`~localization.filtering.map_contact.blocked_motion`'s covariance each, as the
        EKF's), or with the commanded control as any other step.
    free_space : callable, optional
        The map (``city.free_mask``): a contact with the city weighs each particle by
        :func:`~localization.filtering.map_contact.contact_log_likelihood`, and one that
        leaves less than ``1 - CONTACT_WEIGHT`` of the weight where the map explains it
        makes the belief "lost" for ``CONTACT_LOST_STEPS`` steps (as the EKF's). None: no.
    contact_spread : float in [0, 1]; contact_spread_distance : float
        On such a contradicting contact, this share of the particles is moved up to this
        many metres to where the map explains it
        (:class:`~localization.filtering.contact_spread.ContactSpread`; 0: none).
    unmapped : {"floor", "typical"}
        What a particle gets where the maps are undefined (off the training poses): the
        gate's floor, as an outlier; or, where ``free_space`` (needed) says the pose is on
        the street, ``d2 = dof`` (the chi-square mean: the map says nothing there), so a
        robot off a lane map's tube is not out-scored by a look-alike on it (method §13.2).
    """

    def __init__(self, localizer: Any, motion_model: Any, measurement: str = "representation",
                 n_particles: int = 2000, min_particles: int | None = 500,
                 kld_epsilon: float = 0.05, kld_confidence: float = 0.99,
                 resample_threshold: float = 0.5,
                 resample: Callable[[Array], ArrayLike] = systematic_resample,
                 gate_probability: float = 0.997, alpha: ArrayLike | None = None,
                 alpha_slow: float = 0.01, alpha_fast: float = 0.2, injection_ratio: float = 0.7,
                 max_injection: float = 0.5, ambiguous_injection: float = 0.1,
                 n_neighbors: int = 10, proposal_noise: ArrayLike | None = None,
                 global_proposal_fraction: float = 0.2, sample_free: SampleFree | None = None,
                 lost_ratio: float = 0.2, doubt_ratio: float = 0.02,
                 confident_weight: float = 0.8, confirm_share: float = 0.5,
                 confirm_steps: int = 2, unconfirm_steps: int | None = 5,
                 mode_radius: float = 1.0, heading_scale: float = 2.0, max_modes: int = 64,
                 min_mode_weight: float = 0.002,
                 track_mode: bool | dict[str, Any] = True,
                 seed: int | None = None, contact_motion: str = "blocked",
                 free_space: FreeSpace | None = None, contact_spread: float = 0.5,
                 contact_spread_distance: float = 2.0, unmapped: str = "floor") -> None:
        if measurement not in MEASUREMENTS:
            raise ValueError(f"unknown measurement {measurement!r}; choose one of {MEASUREMENTS}")
        if isinstance(n_particles, bool) or int(n_particles) != n_particles or n_particles < 1:
            raise ValueError(f"n_particles must be a positive integer, got {n_particles}")
        if int(n_neighbors) < 1:
            raise ValueError(f"n_neighbors must be >= 1, got {n_neighbors}")
        if sample_free is not None and not callable(sample_free):
            raise TypeError(f"sample_free must be callable (n, rng) -> (n, 3), got {sample_free!r}")
        if not callable(resample):
            raise TypeError(f"resample must be callable weights -> indexes, got {resample!r}")
        if getattr(localizer, "process_noise_body_", None) is None:
            raise NotFittedError("the localizer has no process noise: call fit_noise() or "
                                 "fit_process_noise() first")
        check_measurement_noise(localizer, measurement)
        self.localizer, self.motion_model, self.measurement = localizer, motion_model, measurement
        self.n_particles = int(n_particles)
        adaptive = min_particles is not None and check_int(
            min_particles, "min_particles", low=1) < self.n_particles
        self.kld = (KLDSampling(min_particles, self.n_particles, kld_epsilon, kld_confidence)
                    if adaptive else None)
        unit, unit_open = {"low": 0.0, "high": 1.0}, {"low": 0.0, "high": 1.0, "low_open": True}
        self.resample_threshold = check_real(resample_threshold, "resample_threshold", **unit_open)
        self.amcl = LikelihoodAverages(alpha_slow, alpha_fast, injection_ratio, max_injection)
        self.ambiguous_injection = check_real(ambiguous_injection, "ambiguous_injection", **unit)
        self.global_proposal_fraction = check_real(global_proposal_fraction,
                                                   "global_proposal_fraction", **unit)
        self.lost_ratio = check_real(lost_ratio, "lost_ratio", **unit)
        self.doubt_ratio = check_real(doubt_ratio, "doubt_ratio", **unit)
        self.confident_weight = check_real(confident_weight, "confident_weight", **unit)
        self.confirmation = ModeConfirmation(confirm_share, confirm_steps, unconfirm_steps)
        self.resample, self.sample_free = resample, sample_free
        self.mode_radius, self.heading_scale = float(mode_radius), float(heading_scale)
        self.max_modes = check_int(max_modes, "max_modes", low=1)
        self.min_mode_weight = check_real(min_mode_weight, "min_mode_weight", low=0.0, high=1.0,
                                          low_open=True, high_open=True)
        self.alpha = (localizer.consistency(measurement) if alpha is None
                      else np.asarray(alpha, dtype=np.float64))
        if self.alpha.shape != (3,) or not np.all(self.alpha > 0):
            raise ValueError(f"alpha must be 3 positive numbers, got {alpha}")
        self.Q = inflate(localizer.process_noise_body_, self.alpha)
        self.gain = np.asarray(localizer.control_gain_, dtype=np.float64)
        self._unicycle = is_unicycle(motion_model)
        self.proposal_noise = np.asarray(localizer.noise_["representation"] if proposal_noise
                                         is None else proposal_noise, dtype=np.float64)
        if self.proposal_noise.shape != (3, 3):
            raise ValueError(f"proposal_noise must be (3, 3), got {self.proposal_noise.shape}")
        self.likelihood, self._proposals, self._m = image_models(
            localizer, measurement, self.alpha, gate_probability, n_neighbors,
            self.proposal_noise)
        self.R, self.gate = self.likelihood.R, self.likelihood.gate
        self.rng = np.random.default_rng(seed)
        self.contact_motion = check_choice(contact_motion, "contact_motion", CONTACT_MOTIONS)
        self.free_space, self._bumped = check_free_space(free_space), 0
        self.spread = ContactSpread(contact_spread, contact_spread_distance)
        self.unmapped = check_unmapped(unmapped, self.free_space)
        self.tracker = make_tracker(track_mode, localizer, motion_model, measurement,
                                    alpha=self.alpha, radius=self.mode_radius,
                                    heading_scale=self.heading_scale,
                                    confident_weight=self.confident_weight,
                                    free_space=self.free_space,
                                    contact_motion=self.contact_motion)
        self.particles: Array | None = None
        self.log_weights: Array | None = None
        self.modes: list[Mode] = []
        self.status = self.belief_status = "initial"
        self._misses = 0  # steps in a row whose image had no measurement
        self.injected = 0
        self._recovering = False  # Augmented MCL injected this step
        self._fresh = np.zeros(0, dtype=bool)  # particles injected at the last step

    def _check_w(self, w: ArrayLike) -> Array:
        return check_array(w, "w (features)", shape=(self._m,))

    def _set(self, X: Array, log_w: Array | None = None) -> None:
        self.particles = np.column_stack([X[:, :2], wrap_angle(X[:, 2])])
        n = len(X)
        self.log_weights = (np.full(n, -np.log(n)) if log_w is None
                            else normalise_log_weights(log_w))
        self.modes = find_modes(self.particles, np.exp(self.log_weights), self.mode_radius,
                                self.heading_scale, self.max_modes, self.min_mode_weight)

    # --------------------------------------------------------------- proposals
    def proposals(self, w: ArrayLike) -> Array:
        """Poses (k, 3) the image suggests (:class:`ImageProposals`)."""
        return self._proposals(self._check_w(w))

    def _jitter(self, centres: Array, n: int) -> Array:
        return self._proposals.jitter(centres, n, self.rng)

    # ------------------------------------------------------------------- run
    def reset(self, w: ArrayLike, mode: str = "image", x0: ArrayLike | None = None,
              P0: ArrayLike | None = None) -> str:
        """Start from the first image's features ``w`` (m,).

        ``mode="image"``: every particle from the image's proposals; ``"global"``: a
        ``global_proposal_fraction`` from them, the rest over the free space
        (``sample_free``); with ``x0`` (and ``P0``, default small) a Gaussian around x0.
        ``belief_status`` is then "tracking" (a given pose), "relocalizing" (a global start)
        or, from the image alone, "ambiguous" until the images confirm its mode.

        Returns
        -------
        status : "initial"
        """
        w = self._check_w(w)
        if mode not in RESET_MODES:
            raise ValueError(f"unknown mode {mode!r}; choose one of {RESET_MODES}")
        N, known = self.n_particles, x0 is not None
        if known:
            X = gaussian_particles(x0, P0, N, self.rng)
        elif mode == "image":
            X = self._jitter(self.proposals(w), N)
        else:
            n_prop = round(self.global_proposal_fraction * N)
            X = np.vstack([self._jitter(self.proposals(w), n_prop), free_particles(
                self.sample_free, N - n_prop, self.rng,
                lambda n: self._jitter(self._proposals.train_poses, n))])
        self._set(X)
        if self.tracker is not None:
            self.tracker.reset(w, self.modes[0], known=known)
        self.amcl.reset()
        self.status, self.injected, self._recovering, self._bumped = "initial", 0, False, 0
        self._misses = 0
        self.confirmation.reset(known)
        self._confirm(w)
        self.belief_status = self._start_status(mode, known)
        self._fresh = np.zeros(self.n_particles, dtype=bool)
        return self.status

    def predict(self, u: ArrayLike, contact: Contact = False) -> None:
        """Move every particle: ``X_i = F(X_i, k U) + T(yaw_i) e_i``, ``e_i ~ N(0, Q)``; a
        ``contact`` step (what was touched: ``info["collision_with"]``, or True) as
        ``contact_motion`` says."""
        self._check()
        u = check_array(u, "u (control)", shape=(2,), what="[v, w]")
        u_k, Q_contact, kinds = self.gain * u, None, contact_kinds(contact)
        if kinds and self.contact_motion == "blocked":
            u_k, Q_contact = blocked_motion(self.motion_model, self.particles[0], u_k,
                                            "traffic" in kinds)
        self.particles = move_particles(self.motion_model, self.particles, u_k, self.Q,
                                        self.rng, self._unicycle, Q_contact)

    def distances(self, w: ArrayLike, X: ArrayLike | None = None, z: Array | None = None
                  ) -> Array:
        """Squared Mahalanobis distances d2 (N,) of the measurement ``z`` of ``w`` (default
        ``localizer.measure(w, measurement)``) at the particles ``X`` (default the current
        ones); NaN where the maps are undefined."""
        w = self._check_w(w)
        z = self.likelihood.measure(w) if z is None else z
        return self.likelihood.distances(z, self.particles if X is None else X)

    def step(self, u: ArrayLike, w: ArrayLike, contact: Contact = False,
             bearing: float | None = None) -> tuple[float, str]:
        """Predict with the commanded control ``u`` (2,), weight with the features ``w``
        (and a contact with the city, touched at ``bearing``, with ``free_space``), inject and
        resample. ``contact``: what the robot touched this step (``info["collision_with"]``,
        or True; see ``contact_motion``); ``bearing``: ``info["collision_bearing"]``.

        Returns
        -------
        likelihood : float
            ``w_avg``, the weighted mean of the capped likelihoods ``L_i`` (NaN out of domain).
        status : one of ``PARTICLE_STATUSES`` except "initial"
        """
        self._check()
        w = self._check_w(w)
        self.predict(u, contact)
        kinds, bearing = contact_kinds(contact), check_bearing(bearing)
        log_B = self._bump(kinds, bearing)
        contact = (kinds, bearing)
        self.injected = 0
        z = self.likelihood.measure(w)
        if not np.all(np.isfinite(z)):
            self._set(self.particles, self.log_weights + log_B)
            self.status = "lost" if self._bumped else "out_of_domain"
            self._misses += 1
            self.belief_status = self._coast_status()
            self._track(u, w, contact)
            return np.nan, self.status
        log_L = self._log_likelihood(z) + log_B
        old = self.log_weights[~self._fresh] if (~self._fresh).any() else self.log_weights
        w_avg = float(np.exp(log_sum_exp(old + log_L[~self._fresh] if (~self._fresh).any()
                                         else old + log_L) - log_sum_exp(old)))
        self.amcl.update(w_avg)
        log_w = self.log_weights + log_L
        log_w = normalise_log_weights(log_w)
        n_amcl = self._draw(self.amcl.injection_probability)
        n_inject = max(n_amcl, 0 if self.confirmed else self._draw(self.ambiguous_injection))
        if n_inject > 0 or 1.0 / np.sum(np.exp(2 * log_w)) < self.resample_threshold * len(log_w):
            self._resample(log_w, n_inject, w)
        else:
            self._set(self.particles, log_w)
            self._fresh[:] = False
        self.injected, self._recovering = n_inject, n_amcl > 0
        if self._recovering:
            self.confirmation.withdraw()
        self._confirm(w)
        self.status = self._status(w_avg)
        self._track(u, w, contact)
        self._misses, self.belief_status = 0, self.status
        return w_avg, self.status

    def _log_likelihood(self, z: Array) -> Array:
        """log L_i of the measurement ``z`` at every particle (``unmapped``: see above)."""
        X = self.particles
        return capped_log_likelihood(self.likelihood.distances(z, X), self.gate, None if (
            self.unmapped == "floor") else unmapped_d2(self.free_space, X, len(self.R)))

    def _draw(self, share: float) -> int:
        """How many particles to inject at this share: Binomial(N, share)."""
        return int(self.rng.binomial(len(self.particles), share)) if share > 0 else 0

    def _track(self, u: ArrayLike, w: Array, contact: tuple[frozenset[str], float | None]
               ) -> None:
        """Step the mode tracker (``contact``: what this step touched and where); a report
        most particles disagree with, or whose images its monitor doubts, is "doubtful"."""
        if self.tracker is None:
            return
        source = self.tracker.step(u, w, self.particles, self.weights, self.modes[0], *contact)
        doubted = source == "ekf" and (self.tracker.support < self.tracker.support_weight
                                       or self.tracker.images_doubt)
        if doubted and self.status == "tracking":
            self.status = "doubtful"

    def _resample(self, log_w: Array, n_inject: int, w: Array) -> None:
        """Resample, replacing ``n_inject`` random particles by proposals of the image."""
        X, self._fresh = resample_and_inject(
            self.particles, log_w, self.resample, self.rng, n_inject,
            lambda n: self._jitter(self.proposals(w), n))
        if self.kld is not None:
            X, self._fresh = self.kld.adapt(X, self._fresh, self.rng)
        self._set(X)

    def _confirm(self, w: Array) -> None:
        """Tell :attr:`confirmation` how far this image's retrieved neighbours agree with
        the dominant mode (:mod:`localization.filtering.mode_confirmation`)."""
        c = self.confirmation
        if c.confirmed and c.unconfirm_steps is None:
            return  # nothing can withdraw it: skip the retrieval
        c.update(self._proposals.agreement(w, self.modes[0].mean, self.mode_radius,
                                           self.heading_scale))

    def run(self, W: ArrayLike, controls: ArrayLike, x0: ArrayLike | None = None,
            P0: ArrayLike | None = None, mode: str = "image",
            hypotheses: list[dict[str, Array]] | None = None
            ) -> tuple[Array, Array, list[str]]:
        """Filter a recorded sequence: features ``W`` (n + 1, m) of frames 0..n and the
        controls (n, 2) between them; a list passed as ``hypotheses`` receives each frame's
        :attr:`hypotheses`.

        Returns
        -------
        means : (n + 1, 3)  dominant-mode means
        covs : (n + 1, 3, 3)
        statuses : list of n + 1 str
        """
        record = None if hypotheses is None else (lambda: hypotheses.append(self.hypotheses))
        return run_recorded(self, W, controls, lambda w: self.reset(w, mode, x0, P0), record)
