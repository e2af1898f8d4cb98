"""The progress of a batch on stderr: a bar rewritten in place on a terminal, plain lines
otherwise (at most one every :data:`LINE_INTERVAL` seconds, and the last)."""

from __future__ import annotations

import sys
import time
from typing import TextIO

__all__ = ["LINE_INTERVAL", "TaskProgress"]

LINE_INTERVAL = 10.0
"""Seconds between two progress lines when stderr is not a terminal."""


class TaskProgress:
    """Counts a batch's tasks and shows them: done, failed, running, and the time left.

    Args:
        total: tasks to run in this invocation.
        slots: tasks that can run at once (worker threads), to count the running ones.
        stream: where to write (default stderr); None writes nothing.
    """

    def __init__(self, total: int, slots: int, stream: TextIO | None = sys.stderr, width: int = 30):
        self.total, self.slots, self.stream, self.width = total, max(1, slots), stream, width
        self.done = self.failed = 0
        self.started = time.monotonic()
        self._last_line = -LINE_INTERVAL
        self._tty = stream is not None and stream.isatty()

    @property
    def running(self) -> int:
        return min(self.slots, self.total - self.done - self.failed)

    def eta(self) -> float | None:
        """Seconds left at the pace so far; None before the first task ends."""
        finished = self.done + self.failed
        if not finished:
            return None
        return (time.monotonic() - self.started) / finished * (self.total - finished)

    def text(self) -> str:
        finished = self.done + self.failed
        filled = round(self.width * finished / self.total) if self.total else self.width
        eta = self.eta()
        left = "--:--" if eta is None else _clock(eta)
        return (f"[{'#' * filled}{'.' * (self.width - filled)}] {finished}/{self.total} tasks: "
                f"{self.done} done, {self.failed} failed, {self.running} running, ETA {left}")

    def update(self, ok: bool) -> None:
        """Count one finished task (``ok``: done, else failed) and show the progress."""
        if ok:
            self.done += 1
        else:
            self.failed += 1
        self.show()

    def show(self) -> None:
        if self.stream is None:
            return
        last = self.done + self.failed == self.total
        if self._tty:
            self.stream.write(f"\r{self.text()}" + ("\n" if last else ""))
        elif last or time.monotonic() - self._last_line >= LINE_INTERVAL:
            self.stream.write(f"isf batch: {self.text()}\n")
            self._last_line = time.monotonic()
        self.stream.flush()

    def close(self) -> None:
        """End the bar's line on a terminal if it is not complete."""
        if self._tty and self.done + self.failed < self.total:
            self.stream.write("\n")
            self.stream.flush()


def _clock(seconds: float) -> str:
    seconds = int(round(seconds))
    hours, rest = divmod(seconds, 3600)
    return f"{hours}:{rest // 60:02d}:{rest % 60:02d}" if hours else f"{rest // 60:02d}:{rest % 60:02d}"
