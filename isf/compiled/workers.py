"""Compiling kernels in helper processes that die with their parent: :func:`start_worker`.

A worker is a Python process that calls one function (named ``module:function``) and reports
on its standard output the qualified name of each function numba compiles, one per line, for
the parent's progress count. The parent holds the write end of the worker's standard input and
never writes to it: a thread of the worker waits for that pipe to close and then ends the worker
at once. The system closes the pipe when the parent exits in any way (SIGKILL included), so no
worker outlives its parent, on every platform.

On Linux, when the parent runs a single thread, the worker is a fork of it: it starts with isf
already imported (a fresh ``python -c`` spends one to two seconds importing it first). Elsewhere,
or beside other threads (where a fork could inherit a lock another thread holds), it is a fresh
``python -c``.
"""

from __future__ import annotations

import importlib
import os
import signal
import subprocess
import sys
import threading

__all__ = ["ForkedWorker", "compiled_name", "serve", "start_worker"]


def compiled_name(dispatcher) -> str:
    """The name a worker reports for the numba dispatcher ``dispatcher``:
    ``module.qualified_name`` of its Python function."""
    function = dispatcher.py_func
    return f"{function.__module__}.{function.__qualname__}"


def start_worker(target: str) -> subprocess.Popen | ForkedWorker:
    """Start a worker calling ``target`` (``"module:function"``, the function taking no
    arguments). Read its ``stdout`` (text) for the names it compiles; ``wait()`` for it;
    closing its ``stdin`` (or the parent's death) ends it; ``pid`` is its process id."""
    if sys.platform.startswith("linux") and threading.active_count() == 1:
        return ForkedWorker(target)
    return subprocess.Popen(
        [sys.executable, "-c", f"from isf.compiled.workers import serve; serve({target!r})"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)


class ForkedWorker:
    """A worker forked from this process (see the module docstring), with what the parent
    uses of a ``subprocess.Popen``: ``pid``, ``stdin``, ``stdout`` (text), ``wait()``."""

    def __init__(self, target: str):
        to_worker, worker_stdin = os.pipe()
        worker_stdout, from_worker = os.pipe()
        for stream in (sys.stdout, sys.stderr):  # nothing buffered is written twice
            if stream is not None:
                stream.flush()
        self.pid = os.fork()
        if self.pid == 0:
            os.close(worker_stdin), os.close(worker_stdout)
            _serve_forked(target, to_worker, from_worker)  # never returns
        os.close(to_worker), os.close(from_worker)
        self.stdin = os.fdopen(worker_stdin, "w")
        self.stdout = os.fdopen(worker_stdout, "r")
        self.returncode: int | None = None
        _unwaited.add(self)  # as subprocess keeps its Popen objects: the pipe stays open

    def wait(self) -> int:
        """Wait for the worker to end; its exit code (negative: the signal that ended it)."""
        if self.returncode is None:
            _, status = os.waitpid(self.pid, 0)
            self.returncode = os.waitstatus_to_exitcode(status)
            _unwaited.discard(self)
        return self.returncode


_unwaited: set[ForkedWorker] = set()
"""The forked workers not yet waited for: kept, so that dropping one does not close its stdin
(which would end it)."""


def _serve_forked(target: str, stdin: int, stdout: int) -> None:
    """The body of a forked worker: ``stdin`` and ``stdout`` (file descriptors) become its
    standard streams, its standard error is discarded, Ctrl-C and SIGTERM end it as they end
    a fresh Python, and it exits when :func:`serve` returns or raises."""
    import fcntl  # POSIX: forked workers are Linux's

    code = 1
    try:
        given = (stdin, stdout, os.open(os.devnull, os.O_WRONLY))
        sources = [fcntl.fcntl(fd, fcntl.F_DUPFD, 3) for fd in given]  # none of 0-2 (if closed)
        for fd in given:
            os.close(fd)
        for standard, source in enumerate(sources):
            os.dup2(source, standard)
            os.close(source)
        for number in (signal.SIGINT, signal.SIGTERM):
            signal.signal(number, signal.SIG_DFL)
        sys.stdin, sys.stdout = os.fdopen(0, "r"), os.fdopen(1, "w")
        sys.stderr = os.fdopen(2, "w")
        serve(target)
        code = 0
    finally:
        os._exit(code)


def _end_when_parent_gone() -> None:
    sys.stdin.buffer.read()  # returns when the parent closed the pipe, or died
    os._exit(1)


def serve(target: str) -> None:
    """A worker's body (see the module docstring): watch the parent, report each compiled
    function on stdout, call ``target``."""
    threading.Thread(target=_end_when_parent_gone, daemon=True).start()
    from numba.core import event

    class Report(event.Listener):
        def on_start(self, event_):
            pass

        def on_end(self, event_):
            print(compiled_name(event_.data["dispatcher"]), flush=True)

    event.register("numba:compile", Report())
    module, _, function = target.partition(":")
    getattr(importlib.import_module(module), function)()
