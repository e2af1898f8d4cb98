"""The docs' stories replayed from their own code blocks: the sampler plugin tutorial
(docs/samplers.md), the Python walkthrough (docs/quickstart.md), the command-line tagging step
of the registration tutorial (docs/tutorial-register.md) and the plan summary the quickstart
describes. (The registration tutorial's Python blocks run in tests/test_registration.py.)

Each block is taken from the page as it is published, so an edit that breaks a page's code
breaks a test. What the blocks produce is checked against something the page did not write:
the plugin's own package (its source file and its pyproject), the library's results, the
JSON file the same command writes.
"""

from __future__ import annotations

import json
import re
import shlex
import sys
import types
from pathlib import Path

import numpy as np
import pytest

import isf
from isf.cli import main

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PLUGIN = ROOT / "plugins" / "isf-sampler-normal"


def blocks(page: str, language: str) -> list[str]:
    """The fenced ``language`` code blocks of a docs page, in order."""
    text = (DOCS / page).read_text(encoding="utf-8")
    return re.findall(rf"^```{language}\n(.*?)^```", text, flags=re.DOTALL | re.MULTILINE)


def run_blocks(codes: list[str], name: str, namespace: dict | None = None) -> dict:
    namespace = {"__name__": f"__{name}__"} if namespace is None else namespace
    for k, code in enumerate(codes):
        exec(compile(code, f"{name}[block {k}]", "exec"), namespace)
    return namespace


# ----------------------------------------------------------------- the sampler plugin tutorial
@pytest.fixture
def tutorial_sampler(monkeypatch):
    """The sampler class of the tutorial's step 3, importable as ``isf_sampler_normal`` (the
    name step 4 imports), as the tutorial's reader would have it."""
    code = [b for b in blocks("samplers.md", "python") if "class NormalSampler" in b]
    assert len(code) == 1
    module = types.ModuleType("isf_sampler_normal")
    exec(compile(code[0], "samplers.md[step 3]", "exec"), module.__dict__)
    monkeypatch.setitem(sys.modules, "isf_sampler_normal", module)
    return module.NormalSampler


def test_the_plugin_tutorial_passes_its_own_conformance_test(tutorial_sampler):
    """Step 4's test, run on step 3's class, passes: the tutorial's sampler keeps the
    contract (the conformance kit raises on the first broken rule)."""
    tests = [b for b in blocks("samplers.md", "python") if "def test_conformance" in b]
    assert len(tests) == 1
    namespace = run_blocks(tests, "samplers.md[step 4]")
    assert namespace["NormalSampler"] is tutorial_sampler
    namespace["test_conformance"]()


def test_the_plugin_tutorial_is_the_plugin(tutorial_sampler):
    """Step 3's class proposes exactly what the plugin package's own class proposes, seed for
    seed, on a gripper with an approach axis and on one without; step 2's entry point is the
    plugin's pyproject's."""
    from isf.testing import canonical_gripper, canonical_object

    source = (PLUGIN / "isf_sampler_normal" / "__init__.py").read_text(encoding="utf-8")
    plugin = types.ModuleType("plugin_source")
    exec(compile(source, "isf_sampler_normal/__init__.py", "exec"), plugin.__dict__)
    obj = canonical_object("box")
    for gripper in (canonical_gripper(), canonical_gripper(approach=None)):
        proposals = []
        for cls in (tutorial_sampler, plugin.NormalSampler):
            sampler = cls()
            sampler.reset(obj, gripper, np.random.default_rng(4))
            proposals.append(sampler.propose(5, np.random.default_rng(9)))
        for a, b in zip(*proposals):
            np.testing.assert_array_equal(a.T_object_gripper, b.T_object_gripper)
            assert a.record == b.record
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    toml = blocks("samplers.md", "toml")
    assert len(toml) == 1
    declared = tomllib.loads(toml[0])["project"]["entry-points"]["isf.samplers"]
    shipped = tomllib.loads((PLUGIN / "pyproject.toml").read_text())["project"]
    assert declared == shipped["entry-points"]["isf.samplers"] == {
        "normal": "isf_sampler_normal:NormalSampler"}


def test_the_sampler_page_opening_block_runs():
    """The registry block at the top of docs/samplers.md: the regret sampler with the page's
    parameters."""
    code = [b for b in blocks("samplers.md", "python") if "available_samplers()" in b]
    namespace = run_blocks(code, "samplers.md[registry]")
    sampler = namespace["sampler"]
    assert (sampler.name, sampler.n_clusters, sampler.gamma) == ("regret", 8, 0.2)


def test_the_orientation_helpers_the_page_lists_exist():
    """Every helper docs/samplers.md names in ``isf.samplers.orientation`` is public there."""
    import isf.samplers.orientation as orientation

    text = (DOCS / "samplers.md").read_text(encoding="utf-8")
    for name in ("approach_direction", "initial_rotations", "facing_rotations",
                 "resolve_approach"):
        assert f"`{name}(" in text and name in orientation.__all__


# ----------------------------------------------------------------- the Python walkthrough
def test_the_quickstart_python_walkthrough(capsys):
    """The quickstart's Python blocks run in order; what they print and return is what the
    page says: a plan on the cylinder with a collision-free best grasp, a hand fit whose
    history starts at the start pose and ends at the fit's final state, and grasps whose
    ``repaired`` flag and surface contact are there to read."""
    namespace = run_blocks(blocks("quickstart.md", "python"), "quickstart.md")
    printed = capsys.readouterr().out
    assert namespace["best"].collision_free
    fit = namespace["fit"]
    assert fit.history[0].iteration == 0 and len(fit.history) == fit.iterations + 1
    np.testing.assert_array_equal(fit.history[0].T_object_gripper, np.eye(4))
    np.testing.assert_array_equal(fit.history[-1].q, fit.q)
    assert "True" in printed
    hand_plan = namespace["hand_plan"]
    assert len(hand_plan.grasps) == 12
    assert all(set(g.fit.surface_contact) == {s.name for s in namespace["hand"].surfaces}
               for g in hand_plan.grasps)


# ----------------------------------------------------------------- the command line
def test_isf_tag_with_the_tutorials_points_writes_the_tutorials_copy(tmp_path, monkeypatch):
    """The registration tutorial's shell command (``isf tag ... --points 64``) writes the same
    contact tags as its Python steps 2 and 3 (suggest_contacts(points=64), tag_urdf)."""
    from isf.assets import vendor_gripper
    from isf.exceptions import AssetFetchError
    from isf.registration import suggest_approach, suggest_contacts, tag_urdf

    try:
        src = vendor_gripper("franka-hand")
    except AssetFetchError as exc:
        pytest.skip(f"franka-hand is not cached and cannot be fetched: {exc}")
    command = [b for b in blocks("tutorial-register.md", "bash") if "isf tag" in b]
    assert len(command) == 1
    words = shlex.split(command[0].replace("\\\n", " "))
    words = [str(src) if w.startswith("$(") else w for w in words]
    assert words[:2] == ["isf", "tag"] and "--points" in words
    monkeypatch.chdir(tmp_path)
    assert main(words[1:]) == 0
    assert (tmp_path / "franka_hand_isf_preview.ply").is_file()
    by_cli = (tmp_path / "franka_hand_isf.urdf").read_text()
    (tmp_path / "python").mkdir()
    tag_urdf(src, tmp_path / "python" / "franka_hand_isf.urdf", suggest_contacts(src, points=64),
             approach=suggest_approach(src))
    by_python = (tmp_path / "python" / "franka_hand_isf.urdf").read_text()

    def contacts(text):
        return re.findall(r"<isf:contact .*?/>", text)

    assert len(contacts(by_cli)) == 2 and contacts(by_cli) == contacts(by_python)


def test_the_plan_summary_shows_each_surfaces_contact(tmp_path, capsys):
    """``isf plan`` prints, per grasp, the share of each contact surface's points touching the
    object (percent; a surface touching anywhere shows at least 1), in the surface order its
    legend names: the numbers the grasp file holds."""
    out = tmp_path / "grasps.json"
    code = main(["plan", "--gripper", "three-finger", "--object", "shape:cylinder", "--scale",
                 "3", "--samples", "8", "--seed", "1", "--top", "8", "--out", str(out)])
    assert code in (0, 1)
    printed = capsys.readouterr()
    text = printed.out + printed.err
    data = json.loads(out.read_text())
    surfaces = [s.name for s in isf.load_gripper("three-finger").surfaces]
    assert f"({'/'.join(surfaces)})" in text
    rows = [line.split() for line in text.splitlines()
            if re.match(r"\s+\d+\s+(valid|collides|no contact)\s", line)]
    assert len(rows) == 8
    for row, grasp in zip(rows, data["grasps"]):
        cell = next(word for word in row if re.fullmatch(r"\d+(/\d+)+", word))
        contact = grasp["error"]["surface_contact"]
        shares = [round(100 * contact[name]) if contact[name] > 0 else -1 for name in surfaces]
        assert cell == "/".join(str(max(1, k) if k >= 0 else 0) for k in shares)
