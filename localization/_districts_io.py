"""Persistence of :class:`~localization.districts.DistrictLocalizer` (no pickles).

A folder: ``districts.json`` (the settings, cells and shared noise as JSON) and one
``district_<k>.npz`` per district (:meth:`AppearanceLocalizer.save`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from localization.localizer import AppearanceLocalizer

FORMAT = "appearance-nav-districts/1"
INDEX = "districts.json"
_ARRAYS = ("cells_", "novelty_scale_", "n_train_", "control_gain_", "_poses_mean", "_poses_cov")


def save_districts(loc: Any, path: str | Path) -> None:
    """Write a fitted DistrictLocalizer to the folder ``path`` (created if missing)."""
    folder = _check_path(path)
    folder.mkdir(parents=True, exist_ok=True)
    for k, d in enumerate(loc.districts_):
        d.save(folder / f"district_{k}.npz")
    pnb = loc.process_noise_body_
    index = {"format": FORMAT, "params": loc.get_params(), "n_districts": len(loc.districts_),
             "n_features": loc.n_features_,
             "arrays": {a: np.asarray(getattr(loc, a)).tolist() for a in _ARRAYS},
             "process_noise_body": None if pnb is None else np.asarray(pnb).tolist(),
             "consistency": {k: np.asarray(v).tolist() for k, v in loc.consistency_.items()},
             "quality": {k: float(v) for k, v in loc.quality_.items()}}
    (folder / INDEX).write_text(json.dumps(index))


def load_districts(cls: type, path: str | Path) -> Any:
    """Rebuild a DistrictLocalizer written by :func:`save_districts`; FileNotFoundError if
    there is no such folder, ValueError (naming the file) if it is corrupted or incomplete."""
    folder = _check_path(path)
    if not (folder / INDEX).is_file():
        raise FileNotFoundError(f"no saved DistrictLocalizer in {folder} (no {INDEX})")
    try:
        index = json.loads((folder / INDEX).read_text())
        if index.get("format") != FORMAT:
            raise ValueError(f"unknown format {index.get('format')!r} (want {FORMAT})")
        params = dict(index["params"])
        params["grid"] = tuple(params["grid"])
        loc = cls(**params)
        for a in _ARRAYS:
            setattr(loc, a, np.asarray(index["arrays"][a]))
        loc.n_features_ = int(index["n_features"])
        pnb = index["process_noise_body"]
        loc.process_noise_body_ = None if pnb is None else np.asarray(pnb, dtype=np.float64)
        loc.consistency_ = {k: np.asarray(v, dtype=np.float64)
                            for k, v in index["consistency"].items()}
        loc.quality_ = {k: float(v) for k, v in index["quality"].items()}
        n = int(index["n_districts"])
    except (ValueError, KeyError, TypeError, AttributeError) as err:
        raise ValueError(f"{folder / INDEX}: corrupted or incomplete DistrictLocalizer "
                         f"({type(err).__name__}: {err})") from err
    loc.districts_ = [AppearanceLocalizer.load(folder / f"district_{k}.npz") for k in range(n)]
    loc._set_views()
    return loc


def _check_path(path: object) -> Path:
    if not isinstance(path, (str, Path)):
        raise TypeError(f"path must be a str or pathlib.Path, got {type(path).__name__}")
    return Path(path)
