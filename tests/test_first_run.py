"""Start-up: ``import isf`` and the commands that need no kernels load none of the heavy
libraries (numba, Pinocchio, trimesh, scipy); the public names load on first use."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("numba", "pinocchio", "trimesh", "scipy")

_LOADED = """
import contextlib, io, json, sys
{body}
print(json.dumps(sorted(name for name in {heavy!r} if name in sys.modules)))
"""


def _heavy_after(body: str) -> list[str]:
    """The heavy libraries a fresh interpreter holds after running ``body``."""
    out = subprocess.run([sys.executable, "-c", _LOADED.format(body=body, heavy=HEAVY)],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_import_isf_loads_no_heavy_library():
    assert _heavy_after("import isf; isf.__version__; isf.ISFError; dir(isf)") == []


def test_a_public_name_loads_its_module_on_first_use():
    assert _heavy_after("import isf; isf.plan") != []  # the planner needs the kernels' libraries


@pytest.mark.parametrize("argv", [["--help"], ["grippers"], ["samplers"]])
def test_commands_that_compile_nothing_load_no_heavy_library(argv):
    body = ("from isf.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
            f"    main({argv!r})")
    assert _heavy_after(body) == []


def test_isf_compile_fills_the_cache():
    out = subprocess.run([sys.executable, "-m", "isf", "compile"], capture_output=True,
                         text=True, check=True)
    assert "kernels compiled or loaded" in out.stderr.splitlines()[-1]
    # a second run finds every kernel in the cache: nothing to count
    again = subprocess.run([sys.executable, "-m", "isf", "compile"], capture_output=True,
                           text=True, check=True)
    assert "compiling" not in again.stderr
