"""Atomic file writes: a temp file beside the target (``.NAME.<random>.tmp``), renamed over it
only when the write finished; on any failure the temp file is removed and the target is left as
it was. The file gets the mode a plain ``open`` would give it (0666 less the umask), not the
temp file's 0600. The one place the Python side writes files this way (the engine has its own):
``atomic_open`` for a file handle, ``atomic_path`` for writers that want a path (matplotlib,
Pillow, the engine's ``save``)."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any


def umask() -> int:
    """The process's file mode creation mask (read without changing it for long)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _temp_beside(path: Path, suffix: str = ".tmp") -> tuple[int, str]:
    """mkstemp in ``path``'s folder; an OSError names ``path`` (not the temp file)."""
    try:
        return tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
    except OSError as exc:
        raise OSError(exc.errno, f"cannot write {path}: {exc.strerror}") from None


def _publish(tmp: str, path: Path) -> None:
    """Gives the temp file a plain file's mode and renames it onto ``path``."""
    os.chmod(tmp, 0o666 & ~umask())
    os.replace(tmp, path)


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """``with atomic_path(path) as tmp: write(tmp)`` writes ``path`` atomically through a writer
    that takes a file name; the temp file keeps ``path``'s suffix (writers that pick the format
    from it: ``.png``, ``.gif``, ``.mp4``)."""
    path = Path(path)
    fd, tmp = _temp_beside(path, path.suffix or ".tmp")
    os.close(fd)
    try:
        yield Path(tmp)
        _publish(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "w") -> Iterator[IO[Any]]:
    """``with atomic_open(path) as fh: ...`` writes ``path`` atomically (text mode is UTF-8)."""
    path = Path(path)
    fd, tmp = _temp_beside(path)
    try:
        encoding = None if "b" in mode else "utf-8"
        with os.fdopen(fd, mode, encoding=encoding) as fh:
            yield fh
        _publish(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Writes ``text`` to ``path`` atomically."""
    with atomic_open(path) as fh:
        fh.write(text)
