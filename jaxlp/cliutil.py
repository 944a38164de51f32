"""What every command line of the project shares: bad input is one line on stderr and exit status 2.

Only command-line modules import this one (``python -m jaxlp``, ``python -m mjx_coman.walk``,
``python -m mjx_coman.seed000``, ``python -m mjx_coman.studies``, ``coman-sweep``).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

EXIT_USAGE = 2  # a bad argument, refused before any work
EXIT_INTERRUPTED = 130  # Ctrl-C (128 + SIGINT), as a shell reports it


def one_line(message) -> str:
    """``message`` with its whitespace (newlines included) folded to single spaces."""
    return " ".join(str(message).split())


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line on stderr and exit status 2 (subparsers included)."""

    def error(self, message):
        sys.stderr.write(f"{self.prog}: error: {one_line(message)}\n")
        sys.exit(EXIT_USAGE)


def refuse(prog: str, message) -> int:
    """Write ``PROG: error: MESSAGE`` as one line on stderr; return the exit status 2."""
    sys.stderr.write(f"{prog}: error: {one_line(message)}\n")
    return EXIT_USAGE


def interrupted(prog: str, what: str = "") -> int:
    """Write ``PROG: interrupted[ WHAT]`` as one line on stderr; return the exit status 130."""
    sys.stderr.write(f"{prog}: interrupted{(' ' + one_line(what)) if what else ''}\n")
    return EXIT_INTERRUPTED


def _existing_ancestor(path: Path) -> Path:
    parent = path
    while not parent.exists():
        parent = parent.parent
    return parent


def _can_write_in(folder: Path) -> bool:
    """Whether a file can be made in ``folder``: tried, not guessed from the mode bits (root passes those)."""
    if not folder.is_dir():
        return False
    try:
        with tempfile.TemporaryFile(dir=folder):
            return True
    except OSError:
        return False


def check_output_file(flag: str, path, suffixes=None) -> None:
    """Refuse an output file that could not be written, before the run that would write it.

    Raises:
        ValueError: a suffix not in ``suffixes``, a path naming a folder, or a folder that does not
            exist or is not writable; the message names ``flag`` and the path.
    """
    if path is None:
        return
    p = Path(path)
    if suffixes and p.suffix.lower() not in suffixes:
        raise ValueError(f"{flag} must end in one of {', '.join(suffixes)}, got {str(path)!r}")
    if p.is_dir():
        raise ValueError(f"{flag} names a folder, not a file: {str(path)!r}")
    if not _can_write_in(p.resolve().parent):
        raise ValueError(f"{flag} {str(path)!r}: its folder does not exist or is not writable")


def check_output_dir(flag: str, path) -> None:
    """Refuse an output folder that names a file or lies where nothing can be written.

    A folder that does not exist yet is fine when its nearest existing ancestor is writable.

    Raises:
        ValueError: naming ``flag`` and the path.
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ValueError(f"{flag} {str(path)!r} is a file, not a folder")
    anc = _existing_ancestor(p.resolve())
    if not _can_write_in(anc):
        raise ValueError(f"{flag} {str(path)!r}: cannot write into {str(anc)!r}")


def check_no_overwrite(flag: str, folder, names, force: bool) -> None:
    """Refuse to replace a finished result without ``--force``.

    Raises:
        ValueError: ``folder`` holds one of ``names`` and ``force`` is off; the message names them.
    """
    found = [n for n in names if (Path(folder) / n).exists()]
    if found and not force:
        raise ValueError(f"{flag} {str(folder)!r} already holds {', '.join(found)}: use --force to replace it, "
                         f"or another {flag}")
