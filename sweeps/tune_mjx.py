"""``coman-sweep tune --plant mjx``: tuning through the MJX COMAN walk (needs :mod:`mjx_coman.walking.rollout`)."""

from __future__ import annotations


def check_available() -> None:
    """Raise ``RuntimeError`` (one line) when the MJX walking rollout is not available."""
    try:
        from mjx_coman.walking import rollout  # noqa: F401
    except ImportError:
        raise RuntimeError("plant 'mjx': the MJX walking rollout (mjx_coman.walking.rollout) is not available "
                           "yet; use --plant 3lp") from None
    raise RuntimeError("plant 'mjx': tuning through the MJX walk is not implemented yet; use --plant 3lp")


def tune_mjx(config, progress: bool = True) -> dict:
    check_available()
    raise AssertionError("unreachable")
