"""``isf show``: the report's size and its load time in headless Chromium (docs/viewer.md).

A page of plotly.js alone (the floor), then three pages, each of a 60-sample plan: a YCB mesh
sampled to 20k surface points (the page draws its triangles), the same surface as a 20k-point
cloud (the page draws its points), and a scene (a box on a table seen by one camera, as a point
cloud: the page draws the points, the table and the unseen space). Load time: from the
navigation to the page's script having drawn the first
grasp (``body[data-ready]``), median of ``--repeats`` loads in a fresh page, Chromium launched
as tests/test_viewer_browser.py launches it.

    ISF_BENCH_CPU=none python bench/bench_viewer.py [--object PATH] [--gripper NAME] [--repeats 3]

(``ISF_BENCH_CPU=none``: Chromium inherits the script's CPU pinning otherwise.)
"""

from __future__ import annotations

import _common  # first: pins the thread pools

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import isf
from isf.planning.plan_json import write_plan_json
from isf.viewer import PlanSources, open_plan, write_report

CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update"]


def box_scene_cloud(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Points a camera at (0.4, -0.3, 0.5) sees of a 6 x 6 x 10 cm box on a table (scene frame,
    z up, 2 mm spacing), and the camera's pose ``T_scene_camera``."""
    rng = np.random.default_rng(seed)
    table = rng.uniform(-0.25, 0.25, (30000, 2))
    table = table[~((np.abs(table[:, 0]) < 0.03) & (np.abs(table[:, 1]) < 0.03))]
    faces = [np.column_stack([rng.uniform(-0.03, 0.03, 1500), rng.uniform(-0.03, 0.03, 1500),
                              np.full(1500, 0.10)]),
             np.column_stack([np.full(2500, 0.03), rng.uniform(-0.03, 0.03, 2500),
                              rng.uniform(0, 0.10, 2500)]),
             np.column_stack([rng.uniform(-0.03, 0.03, 2500), np.full(2500, -0.03),
                              rng.uniform(0, 0.10, 2500)])]
    points = np.vstack([np.column_stack([table, np.zeros(len(table))]), *faces])
    eye, target = np.array([0.4, -0.3, 0.5]), np.array([0.0, 0.0, 0.05])
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, np.cross(z, x), z, eye
    return points, T


def load_times(page_path: Path, repeats: int) -> list[float]:
    from playwright.sync_api import sync_playwright

    times = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path="/usr/bin/chromium", headless=True,
                                    args=CHROMIUM_ARGS)
        for _ in range(repeats):
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            start = time.perf_counter()
            page.goto(page_path.as_uri(), wait_until="commit", timeout=300_000)
            page.wait_for_selector("body[data-ready='1']", timeout=300_000)
            times.append(time.perf_counter() - start)
            page.close()
        browser.close()
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--object", default="/work/shared/data/ycb/TomatoSoupCan.obj")
    parser.add_argument("--gripper", default="three-finger")
    parser.add_argument("--points", type=int, default=20000)
    parser.add_argument("--samples", type=int, default=60)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    folder = Path(tempfile.mkdtemp(prefix="bench-viewer-"))
    gripper = isf.load_gripper(args.gripper)
    mesh = _common.object_with_points(args.object, 1.0, args.points, Path(args.object).stem)
    cloud = isf.ObjectSurface(mesh.points, mesh.normals, mesh.spacing, name=mesh.name)
    plan_path = write_plan_json(isf.plan(gripper, mesh, samples=args.samples, seed=0),
                                folder / "object.json")
    points, T = box_scene_cloud()
    scene = isf.load_scene(points, T_scene_camera=T, cloud_frame="scene", table="auto")
    scene_path = write_plan_json(isf.plan(gripper, scene, samples=args.samples, seed=0),
                                 folder / "scene.json")
    cases = [
        (f"{mesh.name}, mesh ({len(mesh.mesh_faces)} triangles)", plan_path,
         PlanSources(gripper, mesh)),
        (f"{mesh.name}, cloud ({cloud.n_points} points)", plan_path, PlanSources(gripper, cloud)),
        (f"scene: box on a table ({scene.surface.n_points} points)", scene_path,
         PlanSources(gripper, scene.surface, scene)),
    ]
    print(_common.machine_description())
    print(f"\n{args.gripper}, {args.samples} samples per plan; load: median of {args.repeats}\n")
    print("| page | grasps | size, MB | plotly.js, MB | load, s (min-max) |")
    print("|---|---|---|---|---|")
    from plotly.offline import get_plotlyjs

    bundle = len(get_plotlyjs().encode("utf-8")) / 1e6
    baseline = folder / "plotly-only.html"  # plotly.js alone, drawing one empty 3D scene
    baseline.write_text(f"<!DOCTYPE html><html><body><div id=v></div><script>{get_plotlyjs()}"
                        "</script><script>Plotly.newPlot('v', [{type: 'scatter3d', x: [0], y: [0], "
                        "z: [0]}]).then(() => {document.body.dataset.ready = '1';});</script>"
                        "</body></html>")
    times = load_times(baseline, args.repeats)
    print(f"| plotly.js alone, one empty 3D scene | - | {baseline.stat().st_size / 1e6:.2f} | "
          f"{bundle:.2f} | {statistics.median(times):.2f} ({min(times):.2f}-{max(times):.2f}) |")
    for name, path, sources in cases:
        out = folder / (path.stem + ("-cloud" if "cloud" in name else "") + ".html")
        summary = write_report(open_plan(path), sources, out)
        times = load_times(out, args.repeats)
        print(f"| {name} | {summary.grasps} | {summary.size / 1e6:.2f} | {bundle:.2f} | "
              f"{statistics.median(times):.2f} ({min(times):.2f}-{max(times):.2f}) |")


if __name__ == "__main__":
    main()
