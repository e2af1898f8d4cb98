"""``isf show``'s page in a real browser: Debian's Chromium, headless, driven by Playwright.

Skipped (with the reason) when Playwright is not importable or no Chromium is found; set
``ISF_REQUIRE_BROWSER=1`` (as CI does) to fail instead of skipping. The browser comes from the
system's packages (``apt-get install chromium chromium-driver``), never from ``playwright
install``; ``ISF_CHROMIUM`` names another executable.
"""

from __future__ import annotations

import io
import json
import os
import shutil

import numpy as np
import pytest

import isf
from isf.planning.plan_json import write_plan_json
from isf.viewer import load_sources, open_plan, write_report

CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update"]


def _chromium() -> str | None:
    for candidate in (os.environ.get("ISF_CHROMIUM"), "/usr/bin/chromium",
                      shutil.which("chromium"), shutil.which("chromium-browser")):
        if candidate and os.path.isfile(candidate) and os.access(candidate, os.X_OK):
            return candidate
    return None


def _missing(reason: str):
    if os.environ.get("ISF_REQUIRE_BROWSER"):
        pytest.fail(f"{reason}, and ISF_REQUIRE_BROWSER is set")
    pytest.skip(reason)


@pytest.fixture(scope="module")
def browser():
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _missing("playwright is not importable (pip install playwright; no 'playwright install')")
    executable = _chromium()
    if executable is None:
        _missing("no Chromium found (apt-get install chromium chromium-driver, or set ISF_CHROMIUM)")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, headless=True, args=CHROMIUM_ARGS)
        yield browser
        browser.close()


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """A report of a small plan of the paper's gripper on isf's cylinder, and the plan file."""
    folder = tmp_path_factory.mktemp("report")
    result = isf.plan("paper-parallel", isf.open_object("shape:cylinder"), samples=8, seed=1)
    plan = open_plan(write_plan_json(result, folder / "grasps.json"))
    out = folder / "report.html"
    write_report(plan, load_sources(plan), out)
    return out, json.loads(plan.path.read_text())


def _pixels(png: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=float)


def test_report_in_chromium(browser, report):
    out, plan = report
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    errors, requests = [], []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("request", lambda r: requests.append(r.url))
    page.goto(out.as_uri())
    page.wait_for_selector("body[data-ready='1']", timeout=120_000)
    page.wait_for_timeout(500)
    view = page.locator("#view")
    first = _pixels(view.screenshot())

    # the 3D canvas is drawn: not one flat colour, and the object and gripper cover some of it
    assert first.std() > 10.0
    assert np.mean(np.abs(first - 255.0).sum(axis=2) > 30) > 0.02

    # choosing grasp 2 moves the gripper: the picture changes, the plot has its iterations
    page.click("tr[data-index='1']")
    page.wait_for_function("document.body.dataset.chosen === '2'")
    page.wait_for_timeout(500)
    second = _pixels(view.screenshot())
    assert np.mean(np.abs(second - first).sum(axis=2) > 30) > 0.001
    convergence = plan["grasps"][1]["convergence"]
    shown = page.evaluate("document.getElementById('plot').data[0]")
    assert len(shown["x"]) == len(shown["y"]) == len(convergence["level"])
    np.testing.assert_allclose(shown["y"], 1000 * np.asarray(convergence["mean_distance"]), rtol=1e-6)

    assert not errors, errors
    assert all(u.startswith(("file:", "data:")) for u in requests), requests
    page.close()
