"""Exceptions of the data readers."""

from __future__ import annotations


class DataError(ValueError):
    """A dataset file is missing, malformed or inconsistent; the message names the file."""
