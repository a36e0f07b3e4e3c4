"""The shared base of the baseline regressors: input standardisation, periodic output
columns as (cos, sin), save / load without pickle."""

from __future__ import annotations

import json
import os
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.utils import Tags
from sklearn.utils.validation import check_is_fitted

from localization.geometry import Array, wrap_angle
from localization.gse.validation import validate_X, validate_y

__all__ = ["_PoseRegressorBase"]


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, (tuple, list)):
        return [_jsonable(x) for x in v]
    return v


class _PoseRegressorBase(RegressorMixin, BaseEstimator):
    """Shared input checks, periodic output encoding and npz persistence."""

    _fitted_scalars: tuple[str, ...] = ()

    def __sklearn_tags__(self) -> Tags:
        tags = super().__sklearn_tags__()
        tags.target_tags.multi_output = True
        return tags

    # -- validation / encoding ------------------------------------------------------
    def _validate_fit(self, X: ArrayLike, Y: ArrayLike) -> tuple[Array, Array]:
        X = validate_X(self, X, "X", reset=True, ensure_min_samples=2)
        Y, self.y_1d_ = validate_y(self, Y, len(X), "Y", "X")
        d = Y.shape[1]
        per = [int(p) for p in self.periodic]
        if any(not 0 <= p < d for p in per) or len(set(per)) != len(per):
            raise ValueError(f"periodic={tuple(self.periodic)} invalid for Y with {d} columns")
        self.periodic_ = tuple(sorted(per))
        self.n_outputs_ = d
        return X, Y

    def _validate_predict(self, X: ArrayLike) -> Array:
        check_is_fitted(self, "X_train_")
        return validate_X(self, X, "X", reset=False)

    def _encode(self, Y: Array) -> Array:
        """(n, d) -> (n, d + len(periodic)): angle columns become cos, sin (appended)."""
        lin = [c for c in range(Y.shape[1]) if c not in self.periodic_]
        parts = [Y[:, lin]] + [np.column_stack([np.cos(Y[:, c]), np.sin(Y[:, c])])
                               for c in self.periodic_]
        return np.column_stack(parts)

    def _decode(self, E: Array) -> Array:
        d = self.n_outputs_
        lin = [c for c in range(d) if c not in self.periodic_]
        Y = np.empty((E.shape[0], d))
        Y[:, lin] = E[:, : len(lin)]
        for j, c in enumerate(self.periodic_):
            cs = E[:, len(lin) + 2 * j: len(lin) + 2 * j + 2]
            Y[:, c] = wrap_angle(np.arctan2(cs[:, 1], cs[:, 0]))
        return Y[:, 0] if self.y_1d_ else Y

    # -- persistence ---------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> None:
        """Write training data and settings to ``path`` (npz format, exactly that name).

        Arrays ``X_train``, ``Y_train`` and ``settings`` (a JSON string with the
        constructor parameters and fitted scalars); readable with ``allow_pickle=False``.
        """
        check_is_fitted(self, "X_train_")
        params = self.get_params()
        params = {k: _jsonable(v) for k, v in params.items()}
        fitted = {k: _jsonable(getattr(self, k)) for k in self._fitted_scalars}
        settings = {"class": type(self).__name__, "params": params, "fitted": fitted,
                    "y_1d": bool(self.y_1d_)}
        with open(path, "wb") as fh:  # a file handle: numpy must not append ".npz"
            np.savez(fh, X_train=self.X_train_, Y_train=self.Y_train_,
                     settings=np.array(json.dumps(settings)))

    @classmethod
    def load(cls, path: str | os.PathLike) -> _PoseRegressorBase:
        """Rebuild a fitted model written by :meth:`save`."""
        with np.load(path, allow_pickle=False) as f:
            settings = json.loads(str(f["settings"]))
            X, Y = f["X_train"], f["Y_train"]
        if settings.get("class") != cls.__name__:
            raise ValueError(f"{path} holds a {settings.get('class')}, not a {cls.__name__}")
        params = settings["params"]
        for key in ("periodic", "k_grid"):
            if key in params:
                params[key] = tuple(params[key])
        model = cls(**params)
        model._restore(X, Y[:, 0] if settings["y_1d"] else Y, settings["fitted"])
        return model

    def _restore(self, X: Array, Y: Array, fitted: dict[str, Any]) -> None:
        raise NotImplementedError
