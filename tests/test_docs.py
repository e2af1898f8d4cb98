"""The documentation site builds in strict mode, and the strict build really fails on a broken link.

Both builds run ``python -m sphinx -W --keep-going`` (any warning is an error) in a subprocess;
they are started together so that they overlap in time. The toolchain (sphinx, myst-parser,
furo) comes with the ``test`` extra. The pages also describe the present: none narrates the
order of work in numbered sessions.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import isf
from isf.cli import _parser

if sys.version_info < (3, 11):
    pytest.skip("the docs toolchain (Sphinx 9, myst-parser 5) needs Python >= 3.11",
                allow_module_level=True)

DOCS = Path(__file__).resolve().parents[1] / "docs"
BUILD_TIMEOUT = 300  # s; far above a normal build

BROKEN_LINK = "missing-page.md"
BROKEN_FUNC = "isf.no_such_function"

_ORDINALS = ("first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth|eleventh|twelfth|"
             "thirteenth|fourteenth|fifteenth|sixteenth|seventeenth|eighteenth|nineteenth|"
             "twentieth|\\d+(?:st|nd|rd|th)")
NARRATION = re.compile(rf"\b(?:{_ORDINALS})\s+session\b", re.IGNORECASE)
"""A numbered work session ("the ninth session"): history, which lives in git."""


def _start(src: Path, out: Path) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-E", "-j", "1", "-q",
           "-b", "html", str(src), str(out)]
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def _finish(proc: subprocess.Popen) -> tuple[int, str]:
    try:
        stdout, stderr = proc.communicate(timeout=BUILD_TIMEOUT)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        pytest.fail(f"sphinx build took more than {BUILD_TIMEOUT} s")
    return proc.returncode, stdout + stderr


@pytest.fixture(scope="module")
def builds(tmp_path_factory):
    """Start the clean build of docs/ and the build of a deliberately broken copy."""
    tmp = tmp_path_factory.mktemp("docs")
    broken = tmp / "broken-src"
    shutil.copytree(DOCS, broken, ignore=shutil.ignore_patterns("_build"))
    page = broken / "quickstart.md"
    injected = f"See [this page]({BROKEN_LINK}) and {{py:func}}`{BROKEN_FUNC}`."
    page.write_text(page.read_text(encoding="utf-8") + f"\n## Broken on purpose\n\n{injected}\n",
                    encoding="utf-8")
    procs = {
        "clean": (_start(DOCS, tmp / "clean"), tmp / "clean"),
        "broken": (_start(broken, tmp / "broken"), tmp / "broken"),
    }
    yield procs
    for proc, _ in procs.values():
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def test_docs_build_strict_without_warnings(builds):
    proc, out = builds["clean"]
    code, log = _finish(proc)
    assert code == 0, f"strict docs build failed:\n{log}"
    assert "WARNING" not in log and "ERROR" not in log, log

    # every Markdown page became an HTML page (pages outside every toctree would have warned)
    for page in DOCS.glob("*.md"):
        assert (out / f"{page.stem}.html").is_file(), page.name

    # the CLI reference shows the usage of every subcommand the parser has, and no other
    cli = (out / "cli.html").read_text(encoding="utf-8")
    sub = next(a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction))
    documented = set(re.findall(r"usage: isf (\w+)", cli))
    assert documented == set(sub.choices), (documented, set(sub.choices))
    for option in ("--gripper", "--samples", "--table", "--contact", "--tip-fraction"):
        assert option in cli, option

    # the API reference documents the public names the package exports
    api = (out / "api.html").read_text(encoding="utf-8")
    for name in isf.__all__:
        if name.startswith("_"):
            continue
        anchors = (f'id="isf.{name}"', f'id="isf.samplers.{name}"', f'id="isf.exceptions.{name}"')
        assert any(a in api for a in anchors), f"isf.{name} is not in the API reference"


def test_strict_build_fails_on_broken_references(builds):
    proc, _ = builds["broken"]
    code, log = _finish(proc)
    assert code != 0, f"a broken link and a broken py reference did not fail the build:\n{log}"
    warnings = [line for line in log.splitlines() if "WARNING" in line or "ERROR" in line]
    assert any(BROKEN_LINK in w for w in warnings), log
    assert any(BROKEN_FUNC in w for w in warnings), log
    assert len(warnings) == 2, "only the two injected errors should be reported:\n" + log



def test_pages_describe_the_present():
    assert NARRATION.search("as the Ninth session found") and NARRATION.search("12th session")
    assert not NARRATION.search("a long-running session")
    pages = [*sorted(DOCS.glob("*.md")), DOCS.parent / "README.md"]
    hits = [f"{page.name}:{n}: {line.strip()}" for page in pages
            for n, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1)
            if NARRATION.search(line)]
    assert not hits, "pages narrate numbered sessions:\n" + "\n".join(hits)
