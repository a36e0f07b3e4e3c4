"""Appearance conditions of AppearanceNav-v0: light, weather, season, camera and traffic.

The world does not look the same twice. A :class:`Conditions` is everything about one
episode's look that is not the city itself: the sun (direction, colour and intensity), the
ambient light and the robot's own headlight (MuJoCo's headlight rides on the camera),
the horizon's tint and glow, fog, the street lamps, seasonal colour shifts of the ground
and the facades, the camera's exposure, sensor noise and motion blur, and how many
vehicles and pedestrians move along the streets (:mod:`envs.traffic`).

``gymnasium.make("AppearanceNav-v0", conditions=...)`` takes

- ``None`` or ``"default"``: today's look (the images are byte-identical to an env made
  without ``conditions``);
- a preset name of :data:`PRESETS` ("dusk", "night", "overcast", "fog", "seasonal",
  "exposure", "noise", "motion_blur", "traffic", ...);
- ``"random"``: every episode draws its conditions (:func:`draw_random`) from the episode's
  seed (the same seed gives the same conditions and images; nothing but the seed changes
  them);
- a dict ``{"preset": name, **fields}``: a preset (default "default", or "random"; or a
  :class:`Conditions`) with fields of :class:`Conditions` overridden (for "random", after
  every draw), e.g. ``{"preset": "night", "vehicles": 4}``; with ``"camera": "random"`` a
  fixed look whose camera effects (exposure, sensor noise, motion blur) every episode draws
  (:func:`draw_camera`), e.g. a map's images of one light through varying cameras;
- a :class:`Conditions`.

:func:`parse_conditions` checks any of these and returns a :class:`ConditionsSpec`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from localization._validation import check_array, check_int, check_real

__all__ = ["CAMERAS", "DEFAULT", "MAX_MOVERS", "NO_CAMERA", "PRESETS", "Conditions",
           "ConditionsSpec", "draw_camera", "draw_random", "experience_looks", "parse_conditions"]

Vec3 = tuple[float, float, float]
MAX_MOVERS = 16  # vehicles (and pedestrians) at most
#: the lighting families "random" draws from (each jittered)
RANDOM_BASES = ("default", "dusk", "night", "overcast", "fog")


@dataclass(frozen=True)
class Conditions:
    """One episode's appearance (the defaults are today's look).

    Attributes
    ----------
    name : str — the preset it came from ("random:<base>" for a random draw).
    sun_direction : (3,) — direction the sunlight travels (z < 0: from above).
    sun : (3,) in [0, 2] — the sun's diffuse colour times intensity (0: no sun).
    ambient : (3,) in [0, 2] — ambient light everywhere (MuJoCo's headlight ambient).
    headlight : (3,) in [0, 2] — the robot's own light along the camera axis.
    sky : (3,) in [0, 1] — tint of the horizon (sky and skyline painted on it).
    sky_glow : float in [0, 1] — light the horizon gives off itself (city glow at night).
    fog : (start, end) metres; ``end == 0`` means no fog, else ``0 <= start < end``.
    fog_colour : (3,) in [0, 1].
    lamps : float in [0, 2] — brightness of the street lamps (0: off, not drawn).
    ground : (3,) in [0, 1] — tint of the ground (streets, pavements, grass).
    facades : float in [0, 1] — strength of the facades' colour shift (0: none).
    season : int >= 0 — names the per-building direction of the shift.
    exposure : float in (0, 8] — camera gain (1: none).
    noise : float in [0, 1] — standard deviation of the sensor noise (pixel values / 255).
    motion_blur : float in [0, 1] — exposure time (s): the image smears by what the camera
        turns and moves during it (none when standing still).
    vehicles, pedestrians : int in [0, MAX_MOVERS] — moving things on the streets.
    """

    name: str = "default"
    sun_direction: Vec3 = (0.3, 0.4, -1.0)
    sun: Vec3 = (0.5, 0.5, 0.5)
    ambient: Vec3 = (0.45, 0.45, 0.45)
    headlight: Vec3 = (0.35, 0.35, 0.35)
    sky: Vec3 = (1.0, 1.0, 1.0)
    sky_glow: float = 0.0
    fog: tuple[float, float] = (0.0, 0.0)
    fog_colour: Vec3 = (0.6, 0.6, 0.6)
    lamps: float = 0.0
    ground: Vec3 = (1.0, 1.0, 1.0)
    facades: float = 0.0
    season: int = 0
    exposure: float = 1.0
    noise: float = 0.0
    motion_blur: float = 0.0
    vehicles: int = 0
    pedestrians: int = 0

    @property
    def has_fog(self) -> bool:
        return self.fog[1] > 0.0

    @property
    def has_camera_effects(self) -> bool:
        return self.exposure != 1.0 or self.noise > 0.0 or self.motion_blur > 0.0

    def to_info(self) -> dict[str, Any]:
        """The fields as a JSON-able dict (lists for vectors), plus ``"holds"``: the names of
        the conditions that differ from today's look."""
        out = {f.name: _plain(getattr(self, f.name)) for f in dataclasses.fields(self)}
        out["holds"] = self.holds()
        return out

    def holds(self) -> list[str]:
        """Which conditions hold: "lighting", "fog", "lamps", "seasonal", "exposure", "noise",
        "motion_blur", "vehicles", "pedestrians" (empty for today's look)."""
        d = DEFAULT
        light = (self.sun_direction, self.sun, self.ambient, self.headlight, self.sky,
                 self.sky_glow) != (d.sun_direction, d.sun, d.ambient, d.headlight, d.sky,
                                    d.sky_glow)
        flags = {"lighting": light, "fog": self.has_fog, "lamps": self.lamps > 0,
                 "seasonal": self.ground != d.ground or self.facades > 0,
                 "exposure": self.exposure != 1.0, "noise": self.noise > 0,
                 "motion_blur": self.motion_blur > 0, "vehicles": self.vehicles > 0,
                 "pedestrians": self.pedestrians > 0}
        return [k for k, v in flags.items() if v]


def _plain(v: Any) -> Any:
    return list(v) if isinstance(v, tuple) else v


DEFAULT = Conditions()
_NIGHT_FOG = (3.0, 20.0)  # black fog: the headlight fades with distance
PRESETS: dict[str, Conditions] = {
    "default": DEFAULT,
    "dusk": Conditions(name="dusk", sun_direction=(-0.95, 0.3, -0.12), sun=(0.55, 0.3, 0.15),
                       ambient=(0.3, 0.25, 0.28), headlight=(0.3, 0.28, 0.25),
                       sky=(0.95, 0.6, 0.5), lamps=0.6, fog=(12.0, 45.0),
                       fog_colour=(0.35, 0.25, 0.3)),
    "night": Conditions(name="night", sun=(0.0, 0.0, 0.0), ambient=(0.08, 0.08, 0.1),
                        headlight=(0.7, 0.67, 0.58), sky=(0.12, 0.13, 0.25), sky_glow=0.08,
                        fog=_NIGHT_FOG, fog_colour=(0.0, 0.0, 0.02), lamps=1.0),
    "overcast": Conditions(name="overcast", sun=(0.15, 0.15, 0.16), ambient=(0.5, 0.5, 0.52),
                           headlight=(0.2, 0.2, 0.2), sky=(0.7, 0.72, 0.75),
                           fog=(15.0, 60.0), fog_colour=(0.65, 0.66, 0.68)),
    "fog": Conditions(name="fog", sun=(0.2, 0.2, 0.2), ambient=(0.5, 0.5, 0.5),
                      headlight=(0.25, 0.25, 0.25), fog=(1.0, 14.0),
                      fog_colour=(0.72, 0.73, 0.75)),
    "seasonal": Conditions(name="seasonal", ground=(0.95, 0.8, 0.6), facades=0.45, season=1),
    "exposure": Conditions(name="exposure", exposure=1.6),
    "noise": Conditions(name="noise", noise=0.05),
    "motion_blur": Conditions(name="motion_blur", motion_blur=0.08),
    "traffic": Conditions(name="traffic", vehicles=6, pedestrians=6),
}
FIELDS = tuple(f.name for f in dataclasses.fields(Conditions) if f.name != "name")
#: the camera fields of a look without camera effects
NO_CAMERA = {"exposure": 1.0, "noise": 0.0, "motion_blur": 0.0}
#: the values of ``conditions={"camera": ...}``
CAMERAS = ("look", "random")


@dataclass(frozen=True)
class ConditionsSpec:
    """What an env was asked for: fixed ``conditions``, or a random draw per episode with
    ``overrides`` applied after it."""

    conditions: Conditions | None
    overrides: tuple[tuple[str, Any], ...] = ()
    camera: str = "look"

    @property
    def random(self) -> bool:
        return self.conditions is None

    @property
    def varies(self) -> bool:
        """Whether episodes draw anything: the whole look, or the camera of a fixed look."""
        return self.random or self.camera == "random"

    @property
    def is_default(self) -> bool:
        return self.conditions == DEFAULT and self.camera == "look"

    def _max(self, name: str) -> float:
        if self.conditions is not None:
            return getattr(self.conditions, name)
        return dict(self.overrides).get(name, 0 if name in ("vehicles", "pedestrians") else 1.0)

    @property
    def max_vehicles(self) -> int:
        return int(self._max("vehicles"))

    @property
    def max_pedestrians(self) -> int:
        return int(self._max("pedestrians"))

    @property
    def lamps(self) -> bool:
        """Whether street lamps can be lit (they are then part of the model)."""
        return self._max("lamps") > 0

    def draw(self, rng: np.random.Generator) -> Conditions:
        """The conditions of one episode (fixed ones, or a random draw with the overrides;
        ``camera="random"``: a fixed look with the camera effects of :func:`draw_camera`)."""
        if self.conditions is not None:
            if self.camera == "random":
                return dataclasses.replace(self.conditions, **{**NO_CAMERA, **draw_camera(rng)})
            return self.conditions
        return dataclasses.replace(draw_random(rng), **dict(self.overrides))


def parse_conditions(spec: object) -> ConditionsSpec:
    """Check ``conditions`` (see the module docstring) and return what it asks for.

    Raises
    ------
    TypeError
        If it is not None, a str, a dict or a :class:`Conditions`, or a field has the wrong type.
    ValueError
        For an unknown preset name or key, or a field value out of its range.
    """
    if spec is None:
        return ConditionsSpec(DEFAULT)
    if isinstance(spec, Conditions):
        return ConditionsSpec(_checked(spec))
    if isinstance(spec, str):
        return _preset(spec, {})
    if isinstance(spec, Mapping):
        allowed = ("preset", "camera", *FIELDS)
        bad = sorted(str(k) for k in spec if k not in allowed)
        if bad:
            raise ValueError(f"unknown conditions key(s) {bad}; allowed keys: {list(allowed)}")
        preset = spec.get("preset", "default")
        camera = spec.get("camera", "look")
        if camera not in CAMERAS:
            raise ValueError(f'conditions["camera"] must be one of {list(CAMERAS)}, got '
                             f"{camera!r}")
        fields = {k: v for k, v in spec.items() if k not in ("preset", "camera")}
        if isinstance(preset, Conditions):
            parsed = ConditionsSpec(_checked(dataclasses.replace(preset, **{
                k: _check_field(k, v) for k, v in fields.items()})))
        elif isinstance(preset, str):
            parsed = _preset(preset, fields)
        else:
            raise TypeError(f'conditions["preset"] must be a preset name (str) or a '
                            f"Conditions, got {preset!r}")
        if camera == "random" and parsed.random:
            raise ValueError('conditions["camera"]="random" applies to a fixed look; the '
                             '"random" preset already draws its camera')
        return dataclasses.replace(parsed, camera=camera)
    raise TypeError("conditions must be None, a preset name, a dict or a Conditions, got "
                    f"{type(spec).__name__}")


def _preset(name: str, overrides: dict[str, Any]) -> ConditionsSpec:
    if name != "random" and name not in PRESETS:
        raise ValueError(f"unknown conditions preset {name!r}; choose one of "
                         f"{[*PRESETS, 'random']}")
    fields = {k: _check_field(k, v) for k, v in overrides.items()}
    if name == "random":
        return ConditionsSpec(None, tuple(sorted(fields.items())))
    base = PRESETS[name]
    return ConditionsSpec(_checked(dataclasses.replace(base, **fields)) if fields else base)


def _checked(c: Conditions) -> Conditions:
    for k in FIELDS:
        _check_field(k, getattr(c, k))
    if not isinstance(c.name, str):
        raise TypeError(f"conditions name must be a str, got {c.name!r}")
    return c


_VEC_RANGES = {"sun": 2.0, "ambient": 2.0, "headlight": 2.0, "sky": 1.0, "fog_colour": 1.0,
               "ground": 1.0}
_REAL_RANGES = {"sky_glow": (0.0, 1.0), "lamps": (0.0, 2.0), "facades": (0.0, 1.0),
                "noise": (0.0, 1.0), "motion_blur": (0.0, 1.0)}


def _check_field(key: str, value: Any) -> Any:
    """A field value checked and converted (tuples of floats, floats, ints)."""
    name = f'conditions["{key}"]'
    if key in _VEC_RANGES or key == "sun_direction":
        v = check_array(value, name, shape=(3,))
        if key == "sun_direction":
            if np.linalg.norm(v) < 1e-6:
                raise ValueError(f"{name} must be a non-zero direction, got {v.tolist()}")
        elif v.min() < 0.0 or v.max() > _VEC_RANGES[key]:
            raise ValueError(f"{name} must lie in [0, {_VEC_RANGES[key]}], got {v.tolist()}")
        return tuple(float(x) for x in v)
    if key == "fog":
        start, end = check_array(value, name, shape=(2,), what="(start, end) metres").tolist()
        if end != 0.0 and not 0.0 <= start < end:
            raise ValueError(f"{name} must be (start, end) with 0 <= start < end (metres), or "
                             f"end = 0 for no fog; got {(start, end)}")
        return (float(start), float(end))
    if key in _REAL_RANGES:
        lo, hi = _REAL_RANGES[key]
        return check_real(value, name, low=lo, high=hi)
    if key == "exposure":
        return check_real(value, name, low=0.0, high=8.0, low_open=True)
    if key == "season":
        return check_int(value, name, low=0)
    if key in ("vehicles", "pedestrians"):
        return check_int(value, name, low=0, high=MAX_MOVERS)
    raise ValueError(f"unknown conditions key {key!r}")  # unreachable: keys checked before


def draw_random(rng: np.random.Generator, family: str | None = None) -> Conditions:
    """A random episode look: a lighting family of :data:`RANDOM_BASES` (drawn, or
    ``family``) with its sun turned, recoloured and dimmed, fog distances stretched, and (each
    half of the time) a seasonal shift and camera effects; no traffic (add it with
    overrides).

    Raises
    ------
    ValueError
        If ``family`` is not one of :data:`RANDOM_BASES`.
    """
    if family is not None and family not in RANDOM_BASES:
        raise ValueError(f"family must be one of {RANDOM_BASES}, got {family!r}")
    base = PRESETS[str(rng.choice(RANDOM_BASES)) if family is None else family]
    az, tilt = rng.uniform(-math.pi / 3, math.pi / 3), rng.uniform(0.7, 1.4)
    x, y, z = base.sun_direction
    c, s = math.cos(az), math.sin(az)
    warm = rng.uniform(-0.1, 0.1)
    colour = np.array([1.0 + warm, 1.0, 1.0 - warm])

    def light(v: Vec3, lo: float = 0.75, hi: float = 1.25) -> Vec3:
        return tuple(float(a) for a in np.clip(np.asarray(v) * colour * rng.uniform(lo, hi),
                                               0.0, 2.0))

    fields: dict[str, Any] = {
        "name": f"random:{base.name}", "sun_direction": (c * x - s * y, s * x + c * y, z * tilt),
        "sun": light(base.sun), "ambient": light(base.ambient), "headlight": light(base.headlight),
    }
    if base.has_fog:
        k = rng.uniform(0.7, 1.4)
        fields["fog"] = (base.fog[0] * k, base.fog[1] * k)
    if rng.uniform() < 0.5:
        fields.update(ground=tuple(float(g) for g in rng.uniform(0.75, 1.0, 3)),
                      facades=float(rng.uniform(0.0, 0.5)), season=int(rng.integers(1, 10_000)))
    fields.update(draw_camera(rng))
    return dataclasses.replace(base, **fields)


def draw_camera(rng: np.random.Generator) -> dict[str, float]:
    """The camera effects of one random draw: half of the time an exposure of
    ``exp(U(-0.4, 0.4))``, sensor noise ``U(0, 0.04)`` and motion blur ``U(0, 0.06)``, else
    none (an empty dict: the look's own camera).

    Returns
    -------
    dict — ``{"exposure": ..., "noise": ..., "motion_blur": ...}`` or ``{}``.
    """
    if rng.uniform() < 0.5:
        return {"exposure": float(np.exp(rng.uniform(-0.4, 0.4))),
                "noise": float(rng.uniform(0.0, 0.04)),
                "motion_blur": float(rng.uniform(0.0, 0.06))}
    return {}


def experience_looks(seed: int) -> list[Conditions]:
    """Looks of a map of several experiences (``ExperienceLocalizer``): today's daylight and
    one draw (:func:`draw_random`, seeded by ``seed``) of each other lighting family of
    :data:`RANDOM_BASES`."""
    rng = np.random.default_rng(seed)
    return [DEFAULT, *(draw_random(rng, family) for family in RANDOM_BASES
                       if family != "default")]
