"""Load a saved localizer of either kind: :func:`load_localizer`."""

from __future__ import annotations

from pathlib import Path

from localization._districts_io import FORMAT as DISTRICTS_FORMAT
from localization._localizer_io import read_file
from localization.districts import DistrictLocalizer
from localization.experiences import ExperienceLocalizer
from localization.localizer import AppearanceLocalizer

__all__ = ["load_localizer"]


def load_localizer(path: str | Path) -> AppearanceLocalizer | DistrictLocalizer:
    """The localizer saved in ``path`` by :meth:`AppearanceLocalizer.save`,
    :meth:`DistrictLocalizer.save` or :meth:`ExperienceLocalizer.save`
    (``allow_pickle=False``).

    Raises
    ------
    FileNotFoundError
        If there is no such file.
    ValueError
        If the file is not a saved localizer, is corrupted or incomplete (naming the file).
    """
    _, settings, _ = read_file(path, "localizer")
    if settings.get("format") == DISTRICTS_FORMAT:
        return DistrictLocalizer.load(path)
    if settings.get("format") == ExperienceLocalizer.FORMAT:
        return ExperienceLocalizer.load(path)
    return AppearanceLocalizer.load(path)
