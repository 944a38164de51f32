"""Grid axes from text: push directions, phases and impulses (the command lines' ``--directions``,
``--phases``, ``--impulses``), each refused with a :class:`GridError` naming the bad value."""

from __future__ import annotations

import argparse
import math

import numpy as np

DIRECTIONS_RAD = {"forward": 0.0, "left": math.pi / 2, "backward": math.pi, "right": -math.pi / 2}
MAX_AXIS = 100_000  # values of one grid axis (--phases N, --impulses a:b:N), checked before any is made


class GridError(ValueError):
    """A bad sweep configuration (the command line turns it into exit status 2)."""


def arg_type(parse):
    """``parse`` as an argparse ``type``: a :class:`GridError` becomes the one-line usage error."""
    def conv(text):
        try:
            return parse(text)
        except GridError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
    conv.__name__ = parse.__name__
    return conv


def direction_rad(name: str) -> float:
    """The heading of a push direction: a name of :data:`DIRECTIONS_RAD` or degrees counterclockwise from
    forward (``"45"``).

    Raises:
        GridError: neither a name nor a finite number.
    """
    if name in DIRECTIONS_RAD:
        return DIRECTIONS_RAD[name]
    try:
        deg = float(name)
    except (TypeError, ValueError):
        deg = math.nan
    if not math.isfinite(deg):
        raise GridError(f"unknown direction {name!r}; choose one of {', '.join(DIRECTIONS_RAD)} or an angle in degrees")
    return math.radians(deg)


def parse_directions(text: str) -> tuple[str, ...]:
    """``"8"``: 8 headings 45 degrees apart from forward; ``"forward,45,left"``: those (names or degrees).

    Raises:
        GridError: an empty list, a bad direction, or one heading twice.
    """
    text = str(text).strip()
    if text.isdigit():
        n = int(text)
        if not 1 <= n <= 360:
            raise GridError(f"--directions must be a count in [1, 360] or a list, got {text!r}")
        return tuple(f"{360.0 * k / n:g}" for k in range(n))
    vals = tuple(v.strip() for v in text.split(",") if v.strip())
    if not vals:
        raise GridError(f"--directions gives no direction: {text!r}")
    vals = tuple(v if v in DIRECTIONS_RAD else f"{float(v):g}" if _is_number(v) else v for v in vals)
    heads = [round(math.degrees(direction_rad(v))) % 360 for v in vals]
    if len(set(heads)) != len(heads):
        raise GridError(f"--directions names a heading twice: {text!r}")
    return vals


def _is_number(text: str) -> bool:
    try:
        return math.isfinite(float(text))
    except ValueError:
        return False


def parse_phases(text: str) -> tuple[float, ...]:
    """``"8"``: 8 phases evenly spaced in [0, 1); ``"0,0.5,0.75"``: those phases.

    Raises:
        GridError: an empty grid or a phase outside [0, 1).
    """
    text = str(text).strip()
    try:
        if "," not in text and "." not in text:
            n = int(text)
            if n < 1:
                raise GridError(f"--phases must be a count >= 1 or a list in [0, 1), got {text!r}")
            if n > MAX_AXIS:
                raise GridError(f"--phases {n} is more than {MAX_AXIS} timings")
            return tuple(float(k) / n for k in range(n))
        vals = tuple(float(v) for v in text.split(",") if v.strip())
    except GridError:
        raise
    except ValueError:
        raise GridError(f"--phases must be a count or comma-separated numbers, got {text!r}") from None
    if not vals:
        raise GridError(f"--phases gives an empty grid: {text!r}")
    if any(not (0.0 <= v < 1.0) for v in vals):
        raise GridError(f"--phases must lie in [0, 1), got {text!r}")
    return vals


def parse_impulses(text: str) -> tuple[float, ...]:
    """Impulses in N s: ``"start:stop:num"`` (inclusive, evenly spaced) or ``"1,2.5,4"``.

    Raises:
        GridError: an empty grid, a malformed range, a negative or non-finite impulse.
    """
    text = str(text).strip()
    try:
        if ":" in text:
            parts = text.split(":")
            if len(parts) != 3:
                raise GridError(f"--impulses range must be start:stop:num, got {text!r}")
            start, stop, num = float(parts[0]), float(parts[1]), int(parts[2])
            if num < 1:
                raise GridError(f"--impulses gives an empty grid: {text!r}")
            if num > MAX_AXIS:
                raise GridError(f"--impulses {text!r} asks for {num} impulses, more than {MAX_AXIS}")
            vals = tuple(float(v) for v in np.linspace(start, stop, num))
        else:
            vals = tuple(float(v) for v in text.split(",") if v.strip())
    except GridError:
        raise
    except ValueError:
        raise GridError(f"--impulses must be start:stop:num or comma-separated numbers (N s), got {text!r}") from None
    if not vals:
        raise GridError(f"--impulses gives an empty grid: {text!r}")
    if any(not math.isfinite(v) for v in vals):
        raise GridError(f"--impulses must be finite, got {text!r}")
    if any(v < 0 for v in vals):
        raise GridError(f"--impulses must be non-negative (use --direction for the sign), got {text!r}")
    return vals
