"""The heading check of the belief filter's "representation" updates (docs/method.md §13.4).

The representation model's update is linearised: its pose-equivalent innovation is
``H^-1 (r*(w) - R*(x))``. Where R* is poorly conditioned (a 60 m city's street maps, a few
tenths of a radian off the lane heading they were trained on) an along-track offset of the
image reads as a turn, and an accepted update can turn the belief 0.1-0.4 rad away from the
heading the image itself gives: psi*(w), the regression's own inverse of the same map. The
pilot then steers on that heading off the lanes, where every image is off the maps (tuning
city 53, docs/benchmarks.md §10 "Stop 59"). With ``BeliefFilter(heading_check=margin)`` an
image whose psi* is undefined is out of domain, and an update that leaves the heading more than
``margin`` further from psi*'s heading than the prior was is undone.
"""

from __future__ import annotations

from localization._validation import check_real
from localization.geometry import wrap_angle

__all__ = ["check_heading_check", "turns_away"]


def check_heading_check(heading_check: object, measurement: str) -> float | None:
    """``heading_check``: None, or a margin (rad) >= 0 with the "representation" model."""
    if heading_check is None:
        return None
    margin = check_real(heading_check, "heading_check", low=0.0)
    if measurement != "representation":
        raise ValueError("heading_check checks the representation model's updates against "
                         f"psi*; measurement={measurement!r} has no such update (use None)")
    return float(margin)


def turns_away(before: float, after: float, psi: float, margin: float) -> bool:
    """Whether an update took the heading from ``before`` to ``after`` more than ``margin``
    further from psi*'s heading ``psi`` (rad)."""
    return bool(abs(wrap_angle(after - psi)) > abs(wrap_angle(before - psi)) + margin)
