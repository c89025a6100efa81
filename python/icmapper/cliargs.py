"""Checks every command applies to its arguments before any work starts, so that one rule holds
everywhere and a mistake costs one clear line, not a traceback after minutes of work.

- **Frames**: ``--frame N`` counts from 0 to the sequence's length - 1 (no negative indices).
- **Output files** (``--out FILE``, ``--json``, ``--video``): the file's folder must exist (as
  for a shell redirection); nothing is created for it. **Output folders** (``--out DIR``,
  ``--city``) are created with their parents. Either way the user's path is named.
- **Sizes** (``--image-size H W``, ``--thumb-size H W``): one option shape, ``add_size_option``.

Nothing here reads data or writes files.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path


def check_frame(frame: int, count: int, flag: str = "--frame", what: str = "the sequence") -> int:
    """``frame`` when it is in 0..count-1; ValueError naming the flag and the valid range."""
    if not 0 <= int(frame) < count:
        valid = f"frames 0-{count - 1}" if count else "no frames"
        raise ValueError(f"{flag} {frame}: {what} has {valid}")
    return int(frame)


def output_file(path: str | os.PathLike, flag: str) -> Path:
    """``path`` as a file a command may write: not a folder, in an existing, writable folder.
    ValueError naming ``flag`` and the user's path otherwise."""
    out = Path(path)
    folder = out.parent
    if out.is_dir():
        raise ValueError(f"{flag} {path}: is a folder; give a file name")
    if not folder.is_dir():
        raise ValueError(f"{flag} {path}: folder {folder} does not exist (create it first)")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ValueError(f"{flag} {path}: folder {folder} is not writable")
    return out


def output_folder(path: str | os.PathLike, flag: str) -> Path:
    """``path`` as a folder a command may create or write into: not an existing file, and its
    nearest existing ancestor a writable folder. ValueError naming ``flag`` and the path."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{flag} {path}: is a file; give a folder")
    ancestor = out
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if ancestor.exists() and not ancestor.is_dir():
        raise ValueError(f"{flag} {path}: {ancestor} is a file, not a folder")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise ValueError(f"{flag} {path}: folder {ancestor} is not writable")
    return out


def add_size_option(
    p: argparse.ArgumentParser, flag: str, default: tuple[int, int] | None, what: str | None
) -> None:
    """Adds an (H, W) pixel size option ``flag`` (two integers) to ``p``; its help is ``what``
    followed by the default (none when ``default`` is None: the command derives it)."""
    shown = what if what is None or default is None else f"{what} (default %(default)s)"
    p.add_argument(flag, type=int, nargs=2, default=default, metavar=("H", "W"), help=shown)
