"""Atomic file writes: a reader never sees a half-written file."""
from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path


class EditedModuleError(RuntimeError):
    """A generated module was edited by hand: its body no longer matches its header hash."""


def write_atomic(path: str | os.PathLike, data: str | bytes) -> Path:
    """Write ``data`` to a temporary file beside ``path``, then rename it over ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mode = "wb" if isinstance(data, bytes) else "w"
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, mode) as handle:
            os.fchmod(handle.fileno(), 0o666 & ~_umask())  # mkstemp makes 0600; use open()'s mode
            handle.write(data)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise
    return path


def _umask() -> int:
    """The process's file-creation mask (read by setting and restoring it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


HEADER_LINES = 5   # a generated module's header: origin, scene, generator and body digests, version


def body_digests(source: str) -> tuple[str | None, str]:
    """(the ``# body-sha256:`` a generated module's header states, None without one; the sha256 of its
    body as it is), so a hand edit of the body shows as a difference."""
    lines = source.splitlines(keepends=True)
    stated = next((line.split(":", 1)[1].strip() for line in lines[:HEADER_LINES]
                   if line.startswith("# body-sha256:")), None)
    return stated, hashlib.sha256("".join(lines[HEADER_LINES:]).encode()).hexdigest()
