"""Can a path be written? Checked without leaving anything behind, before any command creates
its store, output folder or cache (each check returns why not, or None)."""

from __future__ import annotations

import os
import tempfile
from datetime import UTC, datetime
from pathlib import Path

from vlmrl_cli.core.errors import BadInput


def folder_problem(path: Path) -> str | None:
    """Why ``path`` cannot be used as an output folder (made if missing), or None; probed by making and
    removing a folder in its nearest existing parent (read-only mounts and /proc answer too)."""
    existing = path.absolute()
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        return f"{existing} is a file, not a folder"
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".vlmrl-probe-", dir=existing))
    except OSError as exc:
        return f"nothing can be created in {existing} ({exc.strerror or exc})"
    return None


def file_problem(path: Path) -> str | None:
    """Why a file cannot be created (or rewritten) at ``path``, or None; nothing is created."""
    if path.exists():
        if path.is_dir():
            return f"{path} is a folder, not a file"
        return None if os.access(path, os.W_OK) else f"{path} is not writable"
    return folder_problem(path.parent)


def out_folder_problem(out: Path) -> str | None:
    """Why ``out`` cannot be a command's output folder (written into, or made), or None; nothing is created.

    Example:
        >>> import tempfile, pathlib
        >>> root = pathlib.Path(tempfile.mkdtemp())
        >>> _ = (root / "f").write_text("x")
        >>> out_folder_problem(root / "f"), out_folder_problem(root / "new") is None
        ('it is a file', True)
    """
    if out.exists() and not out.is_dir():
        return "it is a file"
    return folder_problem(out)


def check_out_folder(out: Path, flag: str = "--out") -> None:
    """``BadInput`` naming ``flag`` unless ``out`` can be the output folder (checked before anything is made)."""
    problem = out_folder_problem(out)
    if problem:
        raise BadInput(f"cannot write to the output folder {out} ({problem}); pass {flag} to a writable folder.")


#: Where commands write by default when a default could land on committed results: the current
#: folder's ``results/_scratch/``, which the repository's .gitignore ignores.
SCRATCH = Path("results") / "_scratch"


def fresh_scratch_folder(command: str, now: datetime | None = None) -> Path:
    """A new folder name ``results/_scratch/COMMAND/YYYYMMDD-HHMMSS`` (UTC; ``-2``, ... if taken).

    Example:
        >>> from datetime import datetime, UTC
        >>> fresh_scratch_folder("compare", datetime(2026, 12, 7, 15, 30, 5, tzinfo=UTC)).as_posix()
        'results/_scratch/compare/20261207-153005'
    """
    stamp = (now or datetime.now(UTC)).strftime("%Y%m%d-%H%M%S")
    folder, n = SCRATCH / command / stamp, 1
    while folder.exists():
        n += 1
        folder = SCRATCH / command / f"{stamp}-{n}"
    return folder
