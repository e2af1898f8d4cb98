"""isf's kernel cache: kernels are dropped when a module they depend on changes (isf.compiled.cache)
or when their cached files cannot be loaded (isf.compiled.healing); one process compiles at a
time (isf.compiled.lock); compiling workers die with their parent (isf.compiled.workers)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from isf.compiled.cache import RECORD, module_digests, module_sources, refresh


def write_package(root, files: dict[str, str]):
    """A package ``pkg`` under ``root``; ``files`` maps paths relative to it (without ``.py``,
    ``/`` for subfolders) to sources."""
    package = root / "pkg"
    for name, text in files.items():
        path = package / f"{name}.py"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))
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


def test_digests_follow_subpackages_and_every_import_form(tmp_path):
    package = write_package(tmp_path, {
        "__init__": "",
        "fitting/__init__": "from .engine import run\n",
        "fitting/engine": "from ..search import kdtree\nfrom ..search.grid import cells\n",
        "search/__init__": "",
        "search/kdtree": "import pkg.search.leaf\n",
        "search/leaf": "X = 1\n",
        "search/grid": "def cells(): ...\n",
        "search/apart": "import os\nfrom os import path\n",
        "planning/plan": "def f():\n    from pkg.fitting import run\n",
    })
    assert set(module_sources(package)) == {
        "__init__", "fitting.__init__", "fitting.engine", "search.__init__", "search.kdtree",
        "search.leaf", "search.grid", "search.apart", "planning.plan"}
    before = module_digests(package)
    (package / "search" / "leaf.py").write_text("X = 2\n")  # reached by a plain import
    after = module_digests(package)
    # the nested import inside a function counts too; a module's package __init__ runs with it
    assert {key for key in before if before[key] != after[key]} == {
        "search.leaf", "search.kdtree", "fitting.engine", "fitting.__init__", "planning.plan"}
    (package / "search" / "__init__.py").write_text("Y = 1\n")
    again = module_digests(package)
    assert {key for key in after if after[key] != again[key]} == {  # those importing from pkg.search
        "search.__init__", "search.kdtree", "fitting.engine", "fitting.__init__", "planning.plan"}


def test_refresh_deletes_the_kernels_of_changed_modules_only(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir()
    kernels = ["top.f-3.py311.nbi", "top.f-3.py311.1.nbc", "apart.g-1.py311.nbi", "topper.h-1.py311.nbi"]
    for name in kernels:
        (cache / name).write_bytes(b"")
    folders = {"top": cache, "apart": cache, "topper": cache}
    record = cache / RECORD

    def digests(top):
        return {"top": top, "apart": "1", "topper": "1"}

    assert refresh(digests("1"), folders, record) == ["apart", "top", "topper"]
    for name in kernels:  # no record yet: everything went
        assert not (cache / name).exists()
        (cache / name).write_bytes(b"")
    assert refresh(digests("1"), folders, record) == []  # nothing changed
    assert refresh(digests("2"), folders, record) == ["top"]
    assert sorted(p.name for p in cache.iterdir()) == sorted(
        ["apart.g-1.py311.nbi", "topper.h-1.py311.nbi", RECORD])


def test_refresh_finds_each_module_in_its_own_folder(tmp_path):
    one, two = tmp_path / "one", tmp_path / "two"
    for folder in (one, two):
        folder.mkdir()
        (folder / "kernel.f-3.py311.nbi").write_bytes(b"")  # the same stem in two subpackages
    folders = {"fitting.kernel": one, "collision.kernel": two}
    refresh({"fitting.kernel": "1", "collision.kernel": "1"}, folders, tmp_path / RECORD)
    (one / "kernel.f-3.py311.nbi").write_bytes(b"")
    (two / "kernel.f-3.py311.nbi").write_bytes(b"")
    assert refresh({"fitting.kernel": "2", "collision.kernel": "1"}, folders,
                   tmp_path / RECORD) == ["fitting.kernel"]
    assert not (one / "kernel.f-3.py311.nbi").exists()
    assert (two / "kernel.f-3.py311.nbi").exists()


def test_a_kernel_runs_the_new_code_of_a_kernel_it_calls_from_another_module(tmp_path):
    # numba's own cache checks only the caller's file: without the refresh the second run
    # would print the cached 1
    package = write_package(tmp_path, {
        "__init__": """
            from pathlib import Path
            from isf.compiled.cache import refresh_package
            refresh_package(Path(__file__).parent)
            from .caller import g
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


_DOUBLER = {
    "__init__": """
        from isf.compiled.kernels import kernel
        from isf.compiled.leaf import leaf

        @leaf
        def twice(x):
            return 2.0 * x

        @kernel
        def f(x):
            return twice(x) + 1.0
    """,
}


def _run(tmp_path, code: str, cache) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(tmp_path), "NUMBA_CACHE_DIR": str(cache)}
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          check=True)


@pytest.mark.parametrize("part", ["kernel file", "index"])
def test_a_truncated_cache_entry_is_dropped_and_compiled_again(tmp_path, part):
    write_package(tmp_path, _DOUBLER)
    cache, run = tmp_path / "cache", ("import pkg; print(pkg.f(3.0), "
                                       "sum(pkg.f.stats.cache_misses.values()))")
    assert _run(tmp_path, run, cache).stdout.split()[0] == "7.0"  # 2 * 3 + 1
    pattern = "__init__.f-*.py*.1.nbc" if part == "kernel file" else "__init__.f-*.py*.nbi"
    (entry,) = cache.rglob(pattern)
    entry.write_bytes(entry.read_bytes()[:len(entry.read_bytes()) // 3])  # a write cut short
    healed = _run(tmp_path, run, cache)
    assert healed.stdout.split()[0] == "7.0"
    notice = [line for line in healed.stderr.splitlines() if "unreadable" in line]
    assert len(notice) == 1 and " f (" in notice[0], healed.stderr  # one line, naming the kernel
    again = _run(tmp_path, run, cache)  # compiled and saved again: loaded, silently
    assert again.stdout.split() == ["7.0", "0"] and again.stderr == ""


def test_a_second_process_waits_for_the_compiling_one_and_loads_its_kernels(tmp_path):
    write_package(tmp_path, _DOUBLER)
    cache = tmp_path / "cache"
    code = """
import sys, time
from pathlib import Path
from isf.compiled.lock import compile_lock
with compile_lock(Path(sys.argv[1])):
    print("locked", flush=True)
    time.sleep(float(sys.argv[2]))  # long enough for the other process to try
    import pkg
    print(pkg.f(3.0), sum(pkg.f.stats.cache_misses.values()), flush=True)
"""
    env = {**os.environ, "PYTHONPATH": str(tmp_path), "NUMBA_CACHE_DIR": str(cache)}
    first = subprocess.Popen([sys.executable, "-c", code, str(cache), "1.0"], env=env,
                             stdout=subprocess.PIPE, text=True)
    assert first.stdout.readline().strip() == "locked"
    second = subprocess.run([sys.executable, "-c", code, str(cache), "0"], env=env,
                            capture_output=True, text=True, check=True)
    first_out, _ = first.communicate(timeout=120)
    assert first.returncode == 0
    assert first_out.split() == ["7.0", "1"]  # compiled f
    assert second.stdout.split() == ["locked", "7.0", "0"]  # waited, then loaded f


@pytest.mark.parametrize("threads", [1, 2])
def test_a_worker_dies_with_its_parent(tmp_path, threads):
    """On Linux a single-threaded parent forks its worker, a parent running two threads starts
    a fresh Python; either way the worker ends when the parent is killed."""
    (tmp_path / "forever.py").write_text("import time\ndef run():\n    time.sleep(600)\n")
    other_thread = "threading.Thread(target=time.sleep, args=(600,), daemon=True).start()\n"
    parent = subprocess.Popen(
        [sys.executable, "-c", "import threading, time\nfrom isf.compiled.workers import start_worker\n"
         + other_thread * (threads - 1)
         + "print(start_worker('forever:run').pid, flush=True)\ntime.sleep(600)"],
        env={**os.environ, "PYTHONPATH": str(tmp_path)}, stdout=subprocess.PIPE, text=True)
    worker = int(parent.stdout.readline())
    time.sleep(1.0)  # the worker runs its body
    assert _alive(worker)
    if sys.platform.startswith("linux"):
        command = Path(f"/proc/{worker}/cmdline").read_bytes()
        assert (b"serve(" in command) == (threads > 1)  # a fork runs the parent's command line
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 30
    while _alive(worker) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _alive(worker)


def _alive(pid: int) -> bool:
    """Whether the process ``pid`` runs (a zombie, dead but not yet reaped, does not)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    return "\nState:\tZ" not in status
