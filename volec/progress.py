"""Progress of long work, one mechanism for every stage.

In: a count of steps (or an iterable) and a description. Out: on a terminal, a tqdm bar on
standard error; anywhere else (a log file, CI, a batch worker, a notebook run headless), plain
log lines through :mod:`logging` (logger ``volec.progress``): when the work starts, at every
quarter and when it ends, with the seconds taken, so a log stays readable and short.
:func:`step` announces a stage (``volec: MESSAGE`` on standard error).
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Iterable, Iterator
from typing import TypeVar

log = logging.getLogger("volec.progress")
T = TypeVar("T")

LOG_SHARES = (0.25, 0.5, 0.75)
"""Shares of the work at which a line is logged when not on a terminal."""


def on_terminal() -> bool:
    """True when standard error is a terminal (bars), False otherwise (log lines)."""
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


class Progress:
    """Progress over ``total`` steps: ``update()`` after each, ``close()`` (or a ``with``
    block) at the end. Shown only when ``enabled``; as a bar on a terminal (or with
    ``bar=True``), as log lines otherwise."""

    def __init__(self, total: int, desc: str, unit: str = "it", enabled: bool = True,
                 bar: bool | None = None) -> None:
        self.total, self.desc, self.unit = int(total), desc, unit
        self.done = 0
        self._start = time.perf_counter()
        self._next_share = 0
        self._bar = None
        self._log = False
        if enabled and (on_terminal() if bar is None else bar):
            from tqdm.auto import tqdm

            self._bar = tqdm(total=self.total, desc=desc, unit=unit)
        elif enabled:
            self._log = True
            log.info("%s: %d %s to do", desc, self.total, unit)

    def update(self, n: int = 1) -> None:
        """``n`` more steps done."""
        self.done += n
        if self._bar is not None:
            self._bar.update(n)
        if not self._log or not self.total:
            return
        while (self._next_share < len(LOG_SHARES)
               and self.done >= LOG_SHARES[self._next_share] * self.total
               and self.done < self.total):
            log.info("%s: %d of %d %s, %.0f s", self.desc, self.done, self.total, self.unit,
                     time.perf_counter() - self._start)
            self._next_share += 1

    def note(self, text: str) -> None:
        """A short status beside the bar (e.g. the current loss); not logged."""
        if self._bar is not None:
            self._bar.set_postfix_str(text)

    def close(self) -> None:
        """The work has ended."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        if self._log:
            log.info("%s: %d of %d %s done in %.1f s", self.desc, self.done, self.total,
                     self.unit, time.perf_counter() - self._start)
            self._log = False

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def progress_over(items: Iterable[T], desc: str, enabled: bool = True, unit: str = "it",
             total: int | None = None) -> Iterator[T]:
    """``items``, one at a time, with a :class:`Progress` over them (``total``: their count
    when ``items`` has no length)."""
    count = total if total is not None else len(items)  # type: ignore[arg-type]
    with Progress(count, desc, unit, enabled) as bar:
        for item in items:
            yield item
            bar.update()


def step(enabled: bool, message: str) -> None:
    """Announce a stage or a result: ``volec: MESSAGE`` on standard error when ``enabled``."""
    if enabled:
        print(f"volec: {message}", file=sys.stderr, flush=True)
