"""Ctrl-C at random moments of a multi-object ``isf plan``: exit 130, one line, only complete files.

Each try starts the command in a subprocess (its own process group), waits a random time and
sends SIGINT to the group, as a terminal does on Ctrl-C. Whatever the moment (loading the
gripper, loading kernels, inside a compiled kernel, between two objects, while a file is
written), the command must say ``isf: interrupted`` and exit 130, and every file in the output
folder must be a complete plan (it parses and follows the schema); the objects not finished get
no file.
"""

import json
import os
import signal
import subprocess
import sys
import time
from typing import NamedTuple

import jsonschema
import numpy as np
import pytest

from isf.planning.plan_json import SCHEMA_PATH

TRIES = 20

OBJECTS = ["shape:cylinder", "shape:box", "shape:sphere"]


def _command(out_dir):
    objects = [flag for spec in OBJECTS for flag in ("-o", spec)]
    return [sys.executable, "-m", "isf", "plan", "-g", "paper-parallel", *objects, "-n", "4",
            "--out-dir", str(out_dir), "--quiet"]


def _foreground_sigint():
    """In the child before it runs the command: SIGINT acts, as in a terminal's foreground job
    (a test run started in the background has it ignored, and the child would inherit that)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


class Times(NamedTuple):
    """Seconds to start the command line (interpreter and imports) and to run it whole."""

    start: float
    run: float


@pytest.fixture(scope="module")
def times(tmp_path_factory):
    """The times of uninterrupted runs (kernels compiled first, so the tries load them)."""
    out = tmp_path_factory.mktemp("warm")
    proc = subprocess.run(_command(out), capture_output=True, text=True, timeout=1200)
    assert proc.returncode in (0, 1), proc.stderr
    start = time.perf_counter()
    subprocess.run([sys.executable, "-c", "import isf.cli"], check=True, timeout=300)
    started = time.perf_counter()
    proc = subprocess.run(_command(out), capture_output=True, text=True, timeout=600)
    assert proc.returncode in (0, 1), proc.stderr
    return Times(started - start, time.perf_counter() - started)


def test_sigint_at_random_moments_exits_130_and_leaves_only_complete_files(tmp_path, times):
    schema = json.loads(SCHEMA_PATH.read_text())
    rng = np.random.default_rng(26)
    # from once isf's command line runs (a signal during the interpreter's start-up and
    # imports, before any isf code runs, is Python's own) to the end of the run
    first = 2.0 * times.start
    delays = rng.uniform(first, max(first + 0.1, times.run), TRIES)
    kept = []
    for k, delay in enumerate(delays):
        out = tmp_path / f"try{k}"
        proc = subprocess.Popen(_command(out), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, start_new_session=True, preexec_fn=_foreground_sigint)
        time.sleep(delay)
        os.killpg(proc.pid, signal.SIGINT)  # as a terminal does: to the command and its helpers
        stdout, stderr = proc.communicate(timeout=120)
        files = sorted(os.listdir(out)) if out.exists() else []
        if proc.returncode in (0, 1):  # finished before the signal came
            assert len(files) == len(OBJECTS), stderr
        else:
            assert proc.returncode == 130, f"delay {delay:.2f} s: {stderr}"
            assert stderr.strip().splitlines()[-1] == "isf: interrupted", stderr
            assert "Traceback" not in stderr, stderr
        for name in files:
            assert not name.startswith("."), f"temporary file {name} left behind"
            jsonschema.validate(json.loads((out / name).read_text()), schema)
        kept.append(len(files))
    assert min(kept) < len(OBJECTS), "no try was interrupted: the delays are too long"
