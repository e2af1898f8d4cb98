"""Compiling kernels in helper processes that die with their parent: :func:`start_worker`.

A worker is a fresh Python process (``python -c``) that calls one function (named
``module:function``) and reports on its standard output the qualified name of each function
numba compiles, one per line, for the parent's progress count. The parent holds the write end
of the worker's standard input and never writes to it: a thread of the worker waits for that
pipe to close and then ends the worker at once. The system closes the pipe when the parent
exits in any way (SIGKILL included), so no worker outlives its parent, on every platform.
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import threading

__all__ = ["compiled_name", "serve", "start_worker"]


def compiled_name(dispatcher) -> str:
    """The name a worker reports for the numba dispatcher ``dispatcher``:
    ``module.qualified_name`` of its Python function."""
    function = dispatcher.py_func
    return f"{function.__module__}.{function.__qualname__}"


def start_worker(target: str) -> subprocess.Popen:
    """Start a worker calling ``target`` (``"module:function"``, the function taking no
    arguments). Read its ``stdout`` (text) for the names it compiles; ``wait()`` for it;
    closing its ``stdin`` (or the parent's death) ends it."""
    return subprocess.Popen(
        [sys.executable, "-c", f"from isf.compiled.workers import serve; serve({target!r})"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)


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
