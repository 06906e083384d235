r"""The bounds a designer builds to, on by default: what a synthesized linkage must keep, and which it breaks.

A fit says nothing of whether a linkage can be built: a four-bar whose coupler and rocker stretch
nearly into a line at one crank angle (a transmission angle of a few degrees) jams or needs a
flywheel there, and one whose links are ten times the target's size has no room in the machine.
`jaxlink.synthesize` therefore keeps, **by default**, the bounds a designer would accept
(`DEFAULTS`, each printed in the command's header, each switched off by None — on the command
line `--min-transmission 0 --max-size none --max-pivot none`):

- **transmission**: the least transmission angle over the interval (`transmission`: located
  between samples) at least `MIN_TRANSMISSION` = 30°: its margin sin² γ at least sin² 30° = 1/4;
- **link**: no link longer than `MAX_SIZE` = 3 times the target's extent (its largest distance
  between two points, `size.extent`);
- **pivot**: no frame pivot further than `MAX_PIVOT` = 3 extents from the target's centre.

The search keeps the transmission floor and one size bound K for links and pivots both (`size`):
the two size bounds' larger (None if either is None), so that with equal bounds (the default) it is
exact, and with different ones the search is looser and the exact check here marks a design over
the smaller. Each reported design carries what it `violates` (empty: it meets every bound in
force), computed from the same exact numbers the search filters with (the certificate's margin
against the floor, the measured sizes against the bounds): a design that breaks a bound is never
reported as meeting it.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

#: the least transmission angle a design keeps by default (degrees)
MIN_TRANSMISSION = 30.0
#: the longest link by default, in the target's extents
MAX_SIZE = 3.0
#: the furthest frame pivot from the target's centre by default, in the target's extents
MAX_PIVOT = 3.0


class Bounds(NamedTuple):
    """The bounds in force (None: that one off): `min_transmission` (degrees), `max_size` (the
    longest link, extents), `max_pivot` (the furthest frame pivot from the target's centre, extents)."""

    min_transmission: float | None = MIN_TRANSMISSION
    max_size: float | None = MAX_SIZE
    max_pivot: float | None = MAX_PIVOT

    @property
    def search_size(self) -> float | None:
        """The one size bound the search keeps to, links and pivots alike (module doc)."""
        if self.max_size is None or self.max_pivot is None:
            return None
        return max(self.max_size, self.max_pivot)

    @property
    def floor(self) -> float:
        """sin² of the least transmission angle (0: none)."""
        return 0.0 if self.min_transmission is None else math.sin(math.radians(self.min_transmission)) ** 2

    @property
    def any(self) -> bool:
        return any(b is not None for b in self)


#: the defaults of `jaxlink.synthesize` and of `jaxlink synthesize`
DEFAULTS = Bounds()
#: every bound off: the search of before the defaults
OFF = Bounds(None, None, None)


def _number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))


def checked(min_transmission: Any, max_size: Any, max_pivot: Any) -> Bounds:
    """The bounds of `synthesize`'s arguments: `min_transmission` an angle in [0, 90) degrees (0 or
    None: none), `max_size` and `max_pivot` positive finite numbers of extents (None: none);
    ValueError naming the argument otherwise."""
    if min_transmission is not None and (not _number(min_transmission) or not 0 <= min_transmission < 90):
        raise ValueError(f"min_transmission = {min_transmission!r}: an angle in degrees from 0 to below 90 (e.g. "
                         f"{MIN_TRANSMISSION:g}, the default), or 0 or None for none")
    for name, v, default in (("max_size", max_size, MAX_SIZE), ("max_pivot", max_pivot, MAX_PIVOT)):
        if v is not None and (not _number(v) or not math.isfinite(v) or v <= 0):
            raise ValueError(f"{name} = {v!r}: a positive number of target extents (the largest distance between "
                             f"two target points; default {default:g}), or None for no bound")
    return Bounds(None if min_transmission is None or min_transmission == 0 else float(min_transmission),
                  None if max_size is None else float(max_size), None if max_pivot is None else float(max_pivot))


def violations(bounds: Bounds, margin: float, link_size: float, pivot_size: float) -> tuple[str, ...]:
    """What a design breaks of `bounds` (empty: none): its least transmission margin sin² γ
    (`transmission.least`; inf: no dyad whose margin is an angle's; nan: unknown, a break), its
    longest link and its furthest frame pivot from the target's centre, in extents (`size.design_sizes`)."""
    out = []
    if bounds.min_transmission is not None and not margin >= bounds.floor:
        ang = math.degrees(math.asin(math.sqrt(min(max(margin, 0.0), 1.0)))) if np.isfinite(margin) else float("nan")
        out.append(f"transmission angle {ang:.1f}° < {bounds.min_transmission:g}°")
    if bounds.max_size is not None and not link_size <= bounds.max_size:
        out.append(f"link {link_size:.2f} > {bounds.max_size:g} extents")
    if bounds.max_pivot is not None and not pivot_size <= bounds.max_pivot:
        out.append(f"frame pivot {pivot_size:.2f} > {bounds.max_pivot:g} extents from the centre")
    return tuple(out)


def describe(bounds: Bounds) -> str:
    """The bounds in force in words, with the options that change them (the command's header)."""
    parts = [f"transmission angle >= {bounds.min_transmission:g}° (--min-transmission)"
             if bounds.min_transmission is not None else "transmission angle: no bound (--min-transmission 0)",
             f"links <= {bounds.max_size:g} extents (--max-size)"
             if bounds.max_size is not None else "links: no bound (--max-size none)",
             f"frame pivots <= {bounds.max_pivot:g} extents from the target's centre (--max-pivot)"
             if bounds.max_pivot is not None else "frame pivots: no bound (--max-pivot none)"]
    return "; ".join(parts)
