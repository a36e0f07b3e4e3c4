"""Persistence of :class:`~localization.localizer.AppearanceLocalizer` (one npz, no pickles).

Settings go in a JSON string; the feature extractor's state, the GSE regressor (its own npz,
stored as bytes), the noise model and the quality report as named arrays.

Format 3 adds the map (``city_``, ``fingerprint_``) to the settings and ``quality/<key>``
arrays; format-2 files still load, with an unknown city (``city_ = fingerprint_ = None``)
and no quality report. The heteroscedastic noise scales (``noise_scale_``) are
``noise_scale/<measurement>/<key>`` arrays (:meth:`HeteroscedasticNoise.get_state`): a file
without them loads with none (an older reader ignores them).
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from localization._localizer_map import check_city_info
from localization.features import features_from_state
from localization.filtering.heteroscedastic_noise import HeteroscedasticNoise
from localization.gse.regressor import GSERegressor

FORMAT = "appearance-nav-localizer/3"
#: older formats :func:`load_localizer` still reads
LEGACY_FORMATS = ("appearance-nav-localizer/2",)
_GROUPS = ("noise", "rms", "tau", "consistency")
_SCALE = "noise_scale"
_ATTRS = {"noise": "noise_", "rms": "residual_rms_", "tau": "correlation_time_",
          "consistency": "consistency_"}


def save_localizer(loc: Any, path: str | Path | io.BytesIO) -> None:
    """Write a fitted localizer to ``path`` (``np.savez_compressed``), creating its folder
    (or into a buffer: a district of a :class:`~localization.districts.DistrictLocalizer`)."""
    if not isinstance(path, io.BytesIO):
        path = _check_path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    loc.regressor_.save(buf)
    settings = {"format": FORMAT, "params": loc.get_params(), "camera": loc.camera_,
                "image_size": list(loc.image_size_), "yaw_cut_": loc.yaw_cut_,
                "city": getattr(loc, "city_", None), "fingerprint": getattr(loc, "fingerprint_", None)}
    arrays = {f"features/{k}": v for k, v in loc.features_.get_state().items()}
    for group in _GROUPS:
        arrays |= {f"{group}/{k}": v for k, v in getattr(loc, _ATTRS[group]).items()}
    arrays |= {f"quality/{k}": np.float64(v) for k, v in getattr(loc, "quality_", {}).items()}
    for name, model in getattr(loc, "noise_scale_", {}).items():
        arrays |= {f"{_SCALE}/{name}/{k}": v for k, v in model.get_state().items()}
    arrays["control_gain"] = loc.control_gain_
    arrays["dropped"] = np.asarray(getattr(loc, "dropped_", np.zeros(0, np.intp)), np.int64)
    if getattr(loc, "initial_noise_", None) is not None:
        arrays["initial_noise"] = loc.initial_noise_
    if loc.process_noise_body_ is not None:
        arrays["process_noise_body"] = loc.process_noise_body_
    if getattr(loc, "novelty_ref_", None) is not None:
        arrays["novelty_ref"] = np.float64(loc.novelty_ref_)
    np.savez_compressed(path, settings=np.array(json.dumps(settings)),
                        regressor=np.frombuffer(buf.getvalue(), dtype=np.uint8), **arrays)


def saved_path(path: Path) -> Path:
    """The file ``save(path)`` wrote: numpy's ``savez`` appends ``.npz`` to a name without it,
    so ``load("maps/city")`` finds ``maps/city.npz`` when ``maps/city`` itself does not exist."""
    if path.suffix != ".npz" and not path.exists():
        return path.with_name(path.name + ".npz")
    return path


def read_file(path: str | Path | io.BytesIO, what: str = "AppearanceLocalizer",
              name: str = "") -> tuple[Any, dict[str, Any], dict[str, np.ndarray]]:
    """(path, JSON settings, arrays) of a saved localizer file of either kind, or of a buffer
    (``name`` says what it is in the errors); FileNotFoundError if there is no such file,
    ValueError naming it if it is not a saved localizer (``what``)."""
    if isinstance(path, io.BytesIO):
        path = _Named(path, name)
    else:
        path = saved_path(_check_path(path))
        if not path.is_file():
            raise FileNotFoundError(f"no saved {what} file {path}")
    try:
        with np.load(path, allow_pickle=False) as f:
            data = {k: f[k] for k in f.files}
        settings = json.loads(str(data.pop("settings")))
    except (OSError, EOFError, ValueError, KeyError, zipfile.BadZipFile) as err:
        # unreadable, truncated, not a zip, not JSON (JSONDecodeError is a ValueError), no key
        raise ValueError(f"{path} is not a saved {what}: {err}") from None
    if not isinstance(settings, dict):
        raise ValueError(f"{path} is not a saved {what} (settings are not a JSON "  # noqa: TRY004  (a bad file is a bad value)
                         f"object)")
    return path, settings, data


def load_localizer(cls: type, path: str | Path | io.BytesIO, name: str = "") -> Any:
    """Rebuild a localizer written by :func:`save_localizer`; ValueError if the file is not
    one, or is corrupted or incomplete; FileNotFoundError if there is no such file. A buffer
    (``name`` says what it is in the errors) is read as such."""
    path, settings, data = read_file(path, name=name)
    if settings.get("format") not in (FORMAT, *LEGACY_FORMATS):
        raise ValueError(f"{path}: unknown format {settings.get('format')!r} (want {FORMAT})")
    try:
        params = dict(settings["params"])
        params["rows"] = tuple(params["rows"])
        loc = cls(**params)
        loc.camera_ = settings["camera"]
        loc.image_size_ = tuple(int(s) for s in settings["image_size"])
        loc.yaw_cut_ = float(settings["yaw_cut_"])
        loc.features_ = features_from_state(
            {k[len("features/"):]: v for k, v in data.items() if k.startswith("features/")})
        loc.regressor_ = GSERegressor.load(io.BytesIO(data["regressor"].tobytes()))
        for group in _GROUPS:
            setattr(loc, _ATTRS[group], {k[len(group) + 1:]: v for k, v in data.items()
                                         if k.startswith(group + "/")})
        loc.noise_scale_ = _load_scales(data)
        loc.control_gain_ = np.asarray(data["control_gain"], dtype=np.float64)
        loc.process_noise_body_ = data.get("process_noise_body")
        loc.initial_noise_ = data.get("initial_noise")
        loc.novelty_ref_ = float(data["novelty_ref"]) if "novelty_ref" in data else None
        loc.dropped_ = np.asarray(data.get("dropped", np.zeros(0)), dtype=np.intp)
        loc.city_ = check_city_info(settings.get("city"), "the file's city")
        loc.fingerprint_ = settings.get("fingerprint")
        if loc.fingerprint_ is not None and not isinstance(loc.fingerprint_, str):
            raise TypeError(f"fingerprint must be a str, got {type(loc.fingerprint_).__name__}")
        loc.quality_ = {k[len("quality/"):]: float(v) for k, v in data.items()
                        if k.startswith("quality/")}
    except Exception as err:
        raise ValueError(f"{path}: corrupted or incomplete localizer "
                         f"({type(err).__name__}: {err})") from err
    return loc


def _load_scales(data: dict[str, np.ndarray]) -> dict[str, HeteroscedasticNoise]:
    """``noise_scale_`` from the ``noise_scale/<measurement>/<key>`` arrays."""
    states: dict[str, dict[str, np.ndarray]] = {}
    for k, v in data.items():
        if k.startswith(_SCALE + "/"):
            name, key = k[len(_SCALE) + 1:].split("/", 1)
            states.setdefault(name, {})[key] = v
    return {name: HeteroscedasticNoise.from_state(state) for name, state in states.items()}


def _check_path(path: object) -> Path:
    if not isinstance(path, (str, Path)):
        raise TypeError(f"path must be a str or pathlib.Path, got {type(path).__name__}")
    return Path(path)


class _Named(io.BytesIO):
    """A buffer whose str() names it in load errors."""

    def __init__(self, buf: io.BytesIO, name: str) -> None:
        super().__init__(buf.getvalue())
        self._name = name

    def __str__(self) -> str:
        return self._name
