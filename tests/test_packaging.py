"""A plain, non-editable wheel carries the bundled grippers, and they load from it."""

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import isf

REPO = Path(__file__).resolve().parents[1]


def test_public_names_resolve_and_are_sorted():
    assert list(isf.__all__) == sorted(isf.__all__)
    for name in isf.__all__:
        assert getattr(isf, name) is not None


def test_wheel_installs_and_loads_bundled_grippers(tmp_path):
    dist = tmp_path / "dist"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                    "-w", str(dist), str(REPO)], check=True, capture_output=True, timeout=300)
    (wheel,) = dist.glob("isf-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    for gripper in ("paper-parallel", "flat-parallel", "three-finger"):
        assert f"isf/_bundled_grippers/{gripper}/{gripper}.urdf" in names
    assert "isf/planning/plan.schema.json" in names
    assert "isf/py.typed" in names  # PEP 561: type checkers read isf's annotations
    packages = {name.rsplit("/", 1)[0] for name in names if name.endswith("/__init__.py")}
    assert {"isf/fitting", "isf/collision", "isf/repair", "isf/search", "isf/gripper",
            "isf/object", "isf/planning", "isf/registration", "isf/samplers",
            "isf/compiled"} <= packages

    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site),
                    str(wheel)], check=True, capture_output=True, timeout=300)
    code = ("import isf, isf.gripper.bundled; print(isf.__file__); print(isf.gripper.bundled.bundled_gripper_dir()); "
            "print(sorted(isf.gripper.bundled.bundled_grippers())); "
            "g = isf.load_gripper('paper-parallel'); print(g.n_points)")
    env = dict(os.environ, PYTHONPATH=str(site))
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=300, check=True).stdout.splitlines()
    assert out[0].startswith(str(site))  # the installed copy, not the checkout
    assert out[1].startswith(str(site))
    assert out[2] == "['flat-parallel', 'paper-parallel', 'three-finger']"
    assert int(out[3]) > 0
