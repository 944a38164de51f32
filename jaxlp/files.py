"""Writing results: atomically (a temporary file beside the target, then a rename) and as strict JSON.

Shared by every package that writes results (``sweeps``, ``mjx_coman.studies``): a killed run leaves either
the old file or the new one, never a partial one, and JSON parsers that reject ``NaN`` read every file.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Callable

import numpy as np


def _atomic_write(path: Path, write: Callable) -> None:
    """Write through ``write(fileobj)`` to a temporary file beside ``path``, then rename."""
    fd, tmp = tempfile.mkstemp(prefix="." + path.name, suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def save_npz_atomic(path: Path, arrays: dict) -> None:
    """``np.savez`` to ``path`` atomically."""
    _atomic_write(Path(path), lambda f: np.savez(f, **arrays))


def save_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    save_bytes_atomic(path, text.encode())


def save_bytes_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    _atomic_write(Path(path), lambda f: f.write(data))


def finite_or_none(x):
    """``x`` with non-finite floats as ``None`` and NumPy scalars as Python ones, through dicts and sequences."""
    if isinstance(x, dict):
        return {k: finite_or_none(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [finite_or_none(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return finite_or_none(x.item())
    return x


def strict_json(obj, indent: int = 1) -> str:
    """JSON that strict parsers accept: non-finite numbers become ``null``."""
    return json.dumps(finite_or_none(obj), indent=indent, allow_nan=False)
