"""Fixtures shared by the test modules: the bundled grippers and isf's own shapes, loaded once
per session (tests must not modify them)."""

from __future__ import annotations

import pytest

import isf


@pytest.fixture(scope="session")
def paper_gripper() -> isf.Gripper:
    """The paper's parallel gripper (bundled ``paper-parallel``)."""
    return isf.load_gripper("paper-parallel")


@pytest.fixture(scope="session")
def hand() -> isf.Gripper:
    """The bundled three-finger hand."""
    return isf.load_gripper("three-finger")


@pytest.fixture(scope="session")
def cylinder() -> isf.ObjectSurface:
    """isf's ``shape:cylinder``, sized for the parallel grippers."""
    return isf.open_object("shape:cylinder")


@pytest.fixture(scope="session")
def hand_cylinder() -> isf.ObjectSurface:
    """``shape:cylinder`` scaled to the three-finger hand's grasp (a closed mesh, 1500 points)."""
    return isf.open_object("shape:cylinder", scale=3.0, max_points=1500)
