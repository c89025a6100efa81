"""Progress reporting that reads well wherever the output goes.

On a terminal (the stream is a TTY) a tqdm bar; anywhere else (CI, a log file, a pipe) a few plain
lines: one when the work starts, one at every tenth of it (at most one per ``min_interval``
seconds) and one at the end, instead of thousands of carriage-return updates. Every long loop of
the package (mapping, training, pictures) reports through :func:`progress` only.

``ICMAPPER_PROGRESS`` overrides the choice: ``bar`` (always a bar), ``lines`` (always plain lines)
or ``off``. This module holds no other logic and imports tqdm only when a bar is drawn.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from typing import IO, Any

#: Environment variable that overrides the automatic choice ("bar", "lines", "off").
ENV_VAR = "ICMAPPER_PROGRESS"
_MODES = ("auto", "bar", "lines", "off")


class LineProgress:
    """Plain-line progress: ``steps`` evenly spaced lines plus a start and an end line.

    The same small interface as a tqdm bar (``update``, ``set_postfix_str``, ``set_postfix``,
    ``close``, a context manager), so call sites do not care which one they hold.
    ``clock`` (seconds, monotonic) times the rate limit and the rates; tests inject their own.
    """

    def __init__(
        self,
        total: int | None,
        desc: str,
        unit: str = "it",
        initial: int = 0,
        stream: IO[str] | None = None,
        steps: int = 10,
        min_interval: float = 5.0,
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        self.total = None if total is None else int(total)
        self.desc, self.unit = desc, unit
        self.n = int(initial)
        self._start_n = self.n
        self.stream = stream if stream is not None else sys.stderr
        self.steps = max(1, int(steps))
        self.min_interval = float(min_interval)
        self.postfix = ""
        self._clock = clock
        self._t0 = clock()
        self._last_t = -float("inf")
        self._next_mark = self._mark_after(self.n)
        self._closed = False
        where = f"{self.n}/{self.total} {unit}" if self.total is not None else f"{self.n} {unit}"
        self._print(f"{desc}: started, {where}")

    def _mark_after(self, n: int) -> int:
        """The next count at which a line is due (the next tenth of the total)."""
        if not self.total:
            return 1 << 62
        k = n * self.steps // self.total + 1
        return -(-k * self.total // self.steps)  # ceil(k * total / steps)

    def _print(self, text: str) -> None:
        print(text, file=self.stream, flush=True)

    def _rate(self) -> str:
        dt = self._clock() - self._t0
        done = self.n - self._start_n
        rate = done / dt if dt > 0 else 0.0
        return f"{dt:.1f} s, {rate:.2f} {self.unit}/s"

    def update(self, n: int = 1) -> None:
        self.n += int(n)
        if self.total is None or self.n < self._next_mark or self.n >= self.total:
            return
        self._next_mark = self._mark_after(self.n)
        now = self._clock()
        if now - self._last_t < self.min_interval:
            return
        self._last_t = now
        pct = 100.0 * self.n / self.total
        extra = f" [{self.postfix}]" if self.postfix else ""
        where = f"{self.n}/{self.total} {self.unit} ({pct:.0f}%)"
        self._print(f"{self.desc}: {where}, {self._rate()}{extra}")

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        del refresh
        self.postfix = str(s)

    def set_postfix(self, ordered_dict: Any = None, refresh: bool = True, **kwargs: Any) -> None:
        del refresh
        items = dict(ordered_dict or {}, **kwargs)
        self.postfix = ", ".join(f"{k}={v}" for k, v in items.items())

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        total = f"/{self.total}" if self.total is not None else ""
        extra = f" [{self.postfix}]" if self.postfix else ""
        self._print(f"{self.desc}: done, {self.n}{total} {self.unit} in {self._rate()}{extra}")

    def __enter__(self) -> LineProgress:
        return self

    def __exit__(self, *_: Any) -> None:
        self.close()


class NoProgress:
    """Reports nothing (progress turned off); same interface as a bar."""

    n = 0

    def update(self, n: int = 1) -> None:
        self.n += int(n)

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        pass

    def set_postfix(self, ordered_dict: Any = None, refresh: bool = True, **kwargs: Any) -> None:
        pass

    def close(self) -> None:
        pass

    def __enter__(self) -> NoProgress:
        return self

    def __exit__(self, *_: Any) -> None:
        pass


def progress_mode(stream: IO[str] | None = None) -> str:
    """The mode, one of bar, lines, off: ``ICMAPPER_PROGRESS`` when set, else bar on a TTY."""
    forced = os.environ.get(ENV_VAR, "auto").strip().lower() or "auto"
    if forced not in _MODES:
        raise ValueError(f"{ENV_VAR}={forced!r}: expected one of {', '.join(_MODES)}")
    if forced != "auto":
        return forced
    stream = stream if stream is not None else sys.stderr
    isatty = getattr(stream, "isatty", None)
    try:
        return "bar" if isatty is not None and isatty() else "lines"
    except (OSError, ValueError):  # a closed or detached stream
        return "lines"


def progress(
    total: int | None,
    desc: str,
    unit: str = "it",
    enabled: bool = True,
    initial: int = 0,
    stream: IO[str] | None = None,
) -> Any:
    """A progress reporter for ``total`` units of work: a tqdm bar on a TTY, plain lines
    elsewhere (:class:`LineProgress`), nothing when ``enabled`` is false or the mode is "off".

    All three have ``update(n)``, ``set_postfix_str(s)``, ``set_postfix(**kw)`` and ``close()``.
    """
    if not enabled:
        return NoProgress()
    mode = progress_mode(stream)
    if mode == "off":
        return NoProgress()
    if mode == "lines":
        return LineProgress(total, desc, unit, initial, stream)
    from tqdm import tqdm

    return tqdm(
        total=total,
        initial=initial,
        desc=desc,
        unit=unit,
        dynamic_ncols=True,
        file=stream if stream is not None else sys.stderr,
    )
