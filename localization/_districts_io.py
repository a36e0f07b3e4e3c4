"""Persistence of :class:`~localization.districts.DistrictLocalizer` (one npz, no pickles).

``settings``: the format, parameters, cells and shared noise as JSON; ``district/<k>``: the
bytes of district k's own localizer file (:func:`~localization._localizer_io.save_localizer`).
"""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from localization._localizer_io import load_localizer, read_file, save_localizer
from localization.localizer import AppearanceLocalizer

FORMAT = "appearance-nav-districts/1"
_ARRAYS = ("cells_", "novelty_scale_", "n_train_", "control_gain_", "_poses_mean", "_poses_cov")


def save_districts(loc: Any, path: str | Path) -> None:
    """Write a fitted DistrictLocalizer to ``path`` (``.npz``), creating its folder."""
    path = _check_path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    districts = {}
    for k, d in enumerate(loc.districts_):
        buf = io.BytesIO()
        save_localizer(d, buf)
        districts[f"district/{k}"] = np.frombuffer(buf.getvalue(), dtype=np.uint8)
    pnb = loc.process_noise_body_
    settings = {
        "format": getattr(loc, "FORMAT", FORMAT), "params": loc.get_params(),
        "n_districts": len(loc.districts_), "labels": list(getattr(loc, "labels_", [])),
        "n_features": loc.n_features_,
        "arrays": {a: np.asarray(getattr(loc, a)).tolist() for a in _ARRAYS},
        "process_noise_body": None if pnb is None else np.asarray(pnb).tolist(),
        "consistency": {k: np.asarray(v).tolist() for k, v in loc.consistency_.items()},
        "quality": {k: float(v) for k, v in loc.quality_.items()}}
    np.savez(path, settings=np.array(json.dumps(settings)), **districts)


def load_districts(cls: type, path: str | Path) -> Any:
    """Rebuild a DistrictLocalizer written by :func:`save_districts`; FileNotFoundError if
    there is no such file, ValueError (naming the file) if it is corrupted or incomplete."""
    _, settings, data = read_file(path, cls.__name__)
    want = getattr(cls, "FORMAT", FORMAT)
    if settings.get("format") != want:
        raise ValueError(f"{path}: unknown format {settings.get('format')!r} (want {want})")
    try:
        params = dict(settings["params"])
        if "grid" in params:
            params["grid"] = tuple(params["grid"])
        loc = cls(**params)
        for a in _ARRAYS:
            setattr(loc, a, np.asarray(settings["arrays"][a]))
        loc.n_features_ = int(settings["n_features"])
        if settings.get("labels"):
            loc.labels_ = [str(label) for label in settings["labels"]]
        pnb = settings["process_noise_body"]
        loc.process_noise_body_ = None if pnb is None else np.asarray(pnb, dtype=np.float64)
        loc.consistency_ = {k: np.asarray(v, dtype=np.float64)
                            for k, v in settings["consistency"].items()}
        loc.quality_ = {k: float(v) for k, v in settings["quality"].items()}
        loc.districts_ = [
            load_localizer(AppearanceLocalizer, io.BytesIO(data[f"district/{k}"].tobytes()),
                           name=f"{path} (district {k})")
            for k in range(int(settings["n_districts"]))]
    except (ValueError, KeyError, TypeError, AttributeError) as err:
        raise ValueError(f"{path}: corrupted or incomplete {cls.__name__} "
                         f"({type(err).__name__}: {err})") from err
    loc._set_views()
    return loc


def _check_path(path: object) -> Path:
    if not isinstance(path, (str, Path)):
        raise TypeError(f"path must be a str or pathlib.Path, got {type(path).__name__}")
    return Path(path)
