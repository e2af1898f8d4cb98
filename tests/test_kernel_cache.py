"""isf.kernel_cache: cached kernels are dropped when a module they depend on changes."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

from isf.kernel_cache import RECORD, module_digests, refresh


def write_package(root, files: dict[str, str]):
    package = root / "pkg"
    package.mkdir(exist_ok=True)
    for name, text in files.items():
        (package / f"{name}.py").write_text(textwrap.dedent(text))
    return package


def test_a_digest_covers_every_module_imported_directly_or_not(tmp_path):
    package = write_package(tmp_path, {
        "top": "from .middle import f\n",
        "middle": "from . import (\n    bottom,\n)\n",
        "bottom": "X = 1\n",
        "apart": "import os\n",
    })
    before = module_digests(package)
    (package / "bottom.py").write_text("X = 2\n")
    after = module_digests(package)
    assert {name for name in before if before[name] != after[name]} == {"top", "middle", "bottom"}


def test_refresh_deletes_the_kernels_of_changed_modules_only(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir()
    kernels = ["top.f-3.py311.nbi", "top.f-3.py311.1.nbc", "apart.g-1.py311.nbi", "topper.h-1.py311.nbi"]
    for name in kernels:
        (cache / name).write_bytes(b"")
    assert refresh(cache, {"top": "1", "apart": "1", "topper": "1"}) == ["apart", "top", "topper"]
    for name in kernels:  # no record yet: everything went
        assert not (cache / name).exists()
        (cache / name).write_bytes(b"")
    assert refresh(cache, {"top": "1", "apart": "1", "topper": "1"}) == []  # nothing changed
    assert refresh(cache, {"top": "2", "apart": "1", "topper": "1"}) == ["top"]
    assert sorted(p.name for p in cache.iterdir()) == sorted(
        ["apart.g-1.py311.nbi", "topper.h-1.py311.nbi", RECORD])


def test_a_kernel_runs_the_new_code_of_a_kernel_it_calls_from_another_module(tmp_path):
    # numba's own cache checks only the caller's file: without the refresh the second run
    # would print the cached 1
    package = write_package(tmp_path, {
        "__init__": """
            from pathlib import Path
            from isf.kernel_cache import module_digests, refresh
            from .caller import g
            refresh(Path(g._cache._cache_path), module_digests(Path(__file__).parent))
        """,
        "callee": """
            from numba import njit
            @njit(cache=True)
            def f():
                return 1
        """,
        "caller": """
            from numba import njit
            from .callee import f
            @njit(cache=True)
            def g():
                return f()
        """,
    })
    run = [sys.executable, "-c", "import pkg; print(pkg.g())"]
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    env.pop("NUMBA_CACHE_DIR", None)  # the cache beside the sources
    first = subprocess.run(run, env=env, capture_output=True, text=True, check=True)
    assert first.stdout.strip() == "1"
    assert list((package / "__pycache__").glob("caller.g-*.nbi"))  # cached on disk
    callee = package / "callee.py"
    callee.write_text(callee.read_text().replace("return 1", "return 2"))
    stamp = callee.stat().st_mtime + 5
    os.utime(callee, (stamp, stamp))
    second = subprocess.run(run, env=env, capture_output=True, text=True, check=True)
    assert second.stdout.strip() == "2"
