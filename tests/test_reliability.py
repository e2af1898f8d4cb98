"""Hostile input (issue: reliability): a bug is never "nothing found", user mistakes are one line
and exit 2 (an ISFError from the API), a meaningless gripper is refused, a pose whose contact
surfaces touch nothing is not a grasp, and output files are safe.

One test per class of failure; each builds its bad input from scratch.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import stat
import subprocess
import sys
import time

import numpy as np
import pytest
from test_gripper_loading import BASE, write

import isf
from isf.cli import main
from isf.exceptions import (
    GripperDescriptionError,
    InvalidInputError,
    ISFError,
    ObjectLoadError,
    ObjectSizeWarning,
    OutputFileError,
    URDFReadError,
)
from isf.gripper.loading import inspect_gripper, load_gripper
from isf.output_files import check_output_path, write_atomically
from isf.planning.span import gripper_span, object_extent, span_mismatch, warn_if_outside_span


def run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "isf", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=600)


def one_line_error(proc, message):
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1 and lines[0].startswith("isf: error:"), proc.stderr
    assert message in lines[0], lines[0]


# ------------------------------------------------------------ 1. a bug is not "nothing found"
def test_an_unexpected_error_exits_3_with_one_line_and_the_traceback_only_with_v(
        monkeypatch, capsys):
    import isf.cli

    def broken(args):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(isf.cli, "_cmd_grippers", broken)
    assert main(["grippers"]) == 3
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err
    assert "a bug in isf" in lines[0] and isf.__version__ in lines[0]
    assert "ZeroDivisionError" in lines[0] and "issue tracker" in lines[0]
    assert main(["-v", "grippers"]) == 3
    err = capsys.readouterr().err
    assert "Traceback" in err and err.strip().splitlines()[-1].startswith("isf: internal error")


@pytest.mark.parametrize("args, message", [
    (["--seed", "-5"], "--seed must be >= 0"),
    (["--table", "1e308"], "--table"),
    (["--table", "nan"], "--table"),
    (["--fit", "max_iterations=100000000"], "<= 10000"),
    (["--fit", "tolerance=inf"], "FitConfig.tolerance"),
    (["--repair", "object_spacing=1e-12"], "RepairConfig.object_spacing"),
    (["--out", "."], "is a folder"),
    (["--samples", "10000000000"], "--samples must be at most"),
    (["--workers", "100000"], "--workers must be at most"),
])
def test_bad_numbers_and_outputs_are_refused_before_planning(tmp_path, args, message):
    proc = run("plan", "-g", "paper-parallel", "-o", "shape:cylinder", "-n", "2",
               *(args if "--out" in args else [*args, "--out", "out.json"]), cwd=tmp_path)
    one_line_error(proc, message)
    assert list(tmp_path.iterdir()) == []


def test_api_arguments_of_the_wrong_type_raise_isf_errors():
    gripper = load_gripper("paper-parallel")
    obj = isf.load_object(np.random.default_rng(0).normal(size=(200, 3)) * 0.02)
    for seed in (-5, "abc", 1.5, True):
        with pytest.raises(InvalidInputError, match="seed"):
            isf.plan(gripper, obj, samples=1, seed=seed)
    with pytest.raises(InvalidInputError, match="config must be an isf.FitConfig"):
        isf.plan(gripper, obj, samples=1, config={"tolerance": 0.01})
    with pytest.raises(InvalidInputError, match="samples must be at most .*isf batch"):
        isf.plan(gripper, obj, samples=10**10)
    with pytest.raises(InvalidInputError, match="workers must be at most"):
        isf.plan(gripper, obj, samples=1, workers=10**5)
    T = np.eye(4)
    with pytest.raises(InvalidInputError, match="obj must be an isf.ObjectSurface"):
        isf.fit(gripper, obj.points, T)
    with pytest.raises(InvalidInputError, match="gripper must be an isf.Gripper"):
        isf.fit("paper-parallel", obj, T)
    with pytest.raises(InvalidInputError, match="config must be an isf.FitConfig"):
        isf.fit(gripper, obj, T, config={"tolerance": 0.01})
    with pytest.raises(InvalidInputError, match="T_object_gripper must be an array of numbers"):
        isf.fit(gripper, obj, "identity")
    with pytest.raises(GripperDescriptionError, match="got NoneType"):
        isf.load_gripper(None)
    with pytest.raises(ISFError, match="FitConfig.levels"):
        isf.FitConfig(levels="4")
    with pytest.raises(ISFError, match="FitConfig.from_dict takes a dict"):
        isf.FitConfig.from_dict([("levels", 4)])


@pytest.mark.parametrize("name, text, message", [
    ("faces.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 100000000000000000000\n", "faces.obj"),
    ("past.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "name vertices it does not have"),
    ("points.pcd", "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS abc\n"
                   "DATA ascii\n0 0 0\n", "POINTS 'abc'"),
    ("count.pcd", "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT a b c\nPOINTS 1\n"
                  "DATA ascii\n0 0 0\n", "COUNT 'a b c'"),
    ("huge.pcd", "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                 "POINTS 100000000000000000000\nDATA binary\n0000", "huge.pcd"),
])
def test_malformed_object_files_raise_object_load_error(tmp_path, name, text, message):
    (tmp_path / name).write_text(text)
    with pytest.raises(ObjectLoadError, match=message):
        isf.load_object(tmp_path / name)


def test_osqp_never_sees_data_it_would_refuse_and_never_prints(capfd):
    from isf.repair.clearance import _solve_osqp

    H, A = np.eye(2), np.eye(2)
    for f, lower, upper in ((np.array([np.inf, 0.0]), -np.ones(2), np.ones(2)),
                            (np.zeros(2), np.ones(2), -np.ones(2)),
                            (np.zeros(2), np.full(2, np.nan), np.ones(2)),
                            (np.zeros(2), np.full(2, np.inf), np.full(2, np.inf))):
        assert _solve_osqp(H, f, A, lower, upper) is None
    assert _solve_osqp(H, np.array([1.0, -1.0]), A, -np.ones(2), np.ones(2)) == pytest.approx(
        [-1.0, 1.0], abs=1e-2)  # min 1/2 |z|^2 + f.z: z = -f
    assert capfd.readouterr().out == ""


def test_an_absurd_table_plans_without_a_word_on_stdout(capfd):
    from isf.collision.checker import Plane

    result = isf.plan("paper-parallel", isf.open_object("shape:cylinder"), samples=2,
                      obstacles=[Plane.table(1e308)])  # every pose is below this table
    assert result.stats.valid == 0
    assert capfd.readouterr().out == ""


ENTITY = '<!DOCTYPE robot [<!ENTITY pad "left_finger">]>\n'


def test_xml_entities_are_refused_by_every_urdf_reader(tmp_path):
    text = BASE.replace('<?xml version="1.0"?>\n', '<?xml version="1.0"?>\n' + ENTITY).replace(
        'link="left_finger" normal', 'link="&pad;" normal')
    path = write(tmp_path, text)
    report = inspect_gripper(path)  # isf inspect
    assert len(report.problems) == 1 and "XML entity 'pad'" in report.problems[0]
    with pytest.raises(GripperDescriptionError, match="XML entity"):  # isf plan
        load_gripper(path)
    from isf.registration import ContactSpec, tag_urdf

    stock = write(tmp_path, text.split("<isf:gripper")[0] + "</robot>\n", "stock.urdf")
    with pytest.raises(ISFError, match="XML entity"):  # isf tag
        tag_urdf(stock, tmp_path / "tagged.urdf", [ContactSpec.parse("name=a link=palm")])
    assert not (tmp_path / "tagged.urdf").exists()
    with pytest.raises(URDFReadError):
        from isf.gripper.urdf_tags import parse_tagged_urdf

        parse_tagged_urdf(text)
    proc = run("plan", "-g", str(path), "-o", "shape:cylinder", "--out", "x.json", cwd=tmp_path)
    one_line_error(proc, "XML entity")


# ------------------------------------------------------------------ 3. Ctrl-C
def test_an_interrupt_inside_a_compiled_kernel_exits_130(monkeypatch, capsys):
    import isf.cli

    def interrupted_kernel(args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            # what Python raises when a signal handler fires while a compiled call returns
            raise SystemError("<built-in function run> returned a result with an exception set")  # noqa: B904 (the context is what Python sets)

    monkeypatch.setattr(isf.cli, "_cmd_grippers", interrupted_kernel)
    assert main(["grippers"]) == 130
    assert capsys.readouterr().err.strip() == "isf: interrupted"


@pytest.fixture
def sigint_handler():
    """Set SIGINT's handler for a test (``sigint_handler(handler)``); the one the test run
    had is put back after it."""
    before = signal.getsignal(signal.SIGINT)
    yield lambda handler: signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGINT, before)


def test_sigint_while_planning_waits_for_a_safe_point(sigint_handler):
    from isf.cli import _Interrupts

    sigint_handler(signal.default_int_handler)  # Python started from an interactive shell
    with pytest.raises(KeyboardInterrupt), _Interrupts() as interrupts:
        os.kill(os.getpid(), signal.SIGINT)  # recorded, not raised inside whatever runs
        interrupts.check()
    with _Interrupts() as interrupts:
        assert not interrupts.pending  # the next run starts clean
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_run_started_with_sigint_ignored_keeps_ignoring_it(sigint_handler):
    from isf.cli import _Interrupts

    sigint_handler(signal.SIG_IGN)  # a background job of a script: the shell ignores it there
    during = None
    try:
        with _Interrupts() as interrupts:
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(100):  # a handler runs when the main thread next checks: wait for it
                if interrupts.pending:
                    break
                time.sleep(0.001)
            recorded = interrupts.pending
            if not recorded:
                with interrupts.immediate():
                    during = signal.getsignal(signal.SIGINT)
    except KeyboardInterrupt:  # escaping a test, it would end pytest's whole run
        pytest.fail("a SIGINT the process ignores was taken for Ctrl-C")
    assert not recorded
    assert during is signal.SIG_IGN  # not the handler that exits at once
    assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN


# ------------------------------------------------------------ 4. a wrong gripper is refused
@pytest.mark.parametrize("old, new, message", [
    ('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>', "has length 0, not 1"),
    ('<axis xyz="0 1 0"/>', '<axis xyz="0 2 0"/>', "has length 2, not 1"),
    ('<axis xyz="0 1 0"/>', '<axis xyz="0 nan 0"/>', "<axis xyz>='0 nan 0' must be 3 finite"),
    ('<origin xyz="0 0 0.05"/><axis xyz="0 1 0"/>', '<origin xyz="0 inf 0.05"/><axis xyz="0 1 0"/>',
     "joint 'left_joint' <origin xyz>='0 inf 0.05' must be 3 finite"),
    ('<limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>',
     '<limit lower="0.04" upper="0" effort="1" velocity="1"/></joint>', "lower=0.04 >= upper=0"),
    ('<mimic joint="left_joint"', '<mimic joint="right_joint"', "which is not an actuated joint"),
    ('<mimic joint="left_joint"', '<mimic joint="thumb"', "'thumb', which does not exist"),
    ('<box size="0.01 0.01 0.04"/>', '<mesh filename="cube.stl" scale="0.001 0 0.001"/>',
     "has a zero factor"),
    ('link="left_finger" normal', 'link="left_fingr" normal', "'left_fingr', which does not exist"),
])
def test_a_meaningless_gripper_is_refused_without_urdfdom_lines(tmp_path, old, new, message):
    import trimesh

    trimesh.creation.box(extents=[10, 10, 10]).export(tmp_path / "cube.stl")
    assert old in BASE
    path = write(tmp_path, BASE.replace(old, new, 1))
    problems = inspect_gripper(path).problems
    assert any(message in p for p in problems), problems
    with pytest.raises(GripperDescriptionError):
        load_gripper(path)


def test_urdfdom_lines_do_not_reach_the_terminal(tmp_path):
    path = write(tmp_path, BASE.replace('<axis xyz="0 1 0"/>', '<axis xyz="0 nan 0"/>', 1))
    proc = run("inspect", str(path))
    assert proc.returncode == 1 and "must be 3 finite" in proc.stdout
    assert proc.stderr == ""  # urdfdom's "Error: Malformed axis element ..." is logged instead


# ------------------------------------------------------ 5. grasps that are not grasps
def test_gripper_span_and_object_extent_are_analytic(tmp_path):
    # BASE: pads 1 cm thick, facing each other at y = +-(q - 5 mm), q in [0, 40] mm
    gripper = load_gripper(write(tmp_path, BASE))
    span = gripper_span(gripper)
    assert span.smallest == pytest.approx(0.01, abs=1e-4)  # q = 0: |2 q - 1 cm|
    assert span.largest == pytest.approx(0.07, abs=1e-4)  # q = 40 mm
    box = isf.open_object("shape:box")  # axis-aligned: its principal widths are its sides
    extent = object_extent(box)
    dims = sorted(np.ptp(box.points, axis=0))
    assert extent.smallest == pytest.approx(dims[0], rel=1e-3)
    assert extent.largest == pytest.approx(dims[-1], rel=1e-3)


def test_an_object_out_of_the_grippers_span_is_named_with_units(tmp_path):
    gripper = load_gripper(write(tmp_path, BASE))
    cube_mm = isf.load_object(np.random.default_rng(1).uniform(0, 1, (500, 3)))  # 1 mm as m
    message = span_mismatch(gripper, cube_mm)
    assert "larger than" in message and "--units" in message and "7 cm" in message
    assert "\n" not in message
    tiny = isf.load_object(np.random.default_rng(1).uniform(0, 0.002, (500, 3)))
    assert "smaller than" in span_mismatch(gripper, tiny)
    assert span_mismatch(gripper, isf.open_object("shape:cylinder")) is None
    with pytest.warns(ObjectSizeWarning, match="--units"):
        warn_if_outside_span(gripper, cube_mm)


def test_a_plan_with_no_touching_grasp_reports_no_valid_grasp_and_exits_1(tmp_path):
    # a 1 mm tetrahedron written in millimetres, read as metres: a 1 m object
    (tmp_path / "tet.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
                                      "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    proc = run("plan", "-g", "paper-parallel", "-o", "tet.obj", "-n", "3", "--out", "p.json",
               "--quiet", cwd=tmp_path)
    assert proc.returncode == 1, proc.stderr
    assert "no valid grasp found: 0/3 valid" in proc.stdout
    warning = [ln for ln in proc.stderr.splitlines() if ln.startswith("isf: warning:")]
    assert len(warning) == 1 and "--units" in warning[0]
    data = json.loads((tmp_path / "p.json").read_text())
    assert data["stats"]["valid"] == 0
    assert not any(g["collision_free"] and all(g["error"]["surface_contact"].values())
                   for g in data["grasps"])


# ------------------------------------------------------------------- 7. output files
def test_output_files_follow_the_umask_and_are_atomic(tmp_path, monkeypatch):
    old = os.umask(0o027)
    try:
        written = write_atomically(tmp_path / "a.json", b"{}")
    finally:
        os.umask(old)
    assert stat.S_IMODE(written.stat().st_mode) == 0o640
    (tmp_path / "b.json").write_text("old")

    def full_disk(src, dst):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "replace", full_disk)
    with pytest.raises(OutputFileError, match="No space left on device"):
        write_atomically(tmp_path / "b.json", b"new")
    assert (tmp_path / "b.json").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "b.json"]


def test_outputs_onto_folders_links_and_fifos_are_refused(tmp_path):
    (tmp_path / "target.json").write_text("{}")
    (tmp_path / "link.json").symlink_to(tmp_path / "target.json")
    os.mkfifo(tmp_path / "fifo.json")
    (tmp_path / "folder").mkdir()
    for name, kind in (("link.json", "symbolic link"), ("fifo.json", "FIFO"),
                       ("folder", "folder")):
        with pytest.raises(OutputFileError, match=kind):
            check_output_path(tmp_path / name)
    with pytest.raises(OutputFileError, match="does not exist"):
        check_output_path(tmp_path / "missing" / "x.json")
    proc = run("plan", "-g", "paper-parallel", "-o", "shape:cylinder", "--out", "link.json",
               cwd=tmp_path)
    one_line_error(proc, "symbolic link")
    assert (tmp_path / "target.json").read_text() == "{}"


def test_tag_refuses_a_folder_as_out_or_export_before_writing_anything(tmp_path):
    stock = write(tmp_path, BASE.split("<isf:gripper")[0] + "</robot>\n", "stock.urdf")
    (tmp_path / "folder").mkdir()
    proc = run("tag", str(stock), "--out", "folder", cwd=tmp_path)
    one_line_error(proc, "is a folder")
    proc = run("tag", str(stock), "--out", "tagged.urdf", "--export", "folder", cwd=tmp_path)
    one_line_error(proc, "is a folder")
    proc = run("tag", str(stock), "--out", "tagged.urdf", "--export", "view.xyz", cwd=tmp_path)
    one_line_error(proc, ".xyz")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder", "stock.urdf"]
    assert list((tmp_path / "folder").iterdir()) == []
