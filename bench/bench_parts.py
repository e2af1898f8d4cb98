"""How faithful is the physics test's object? The convex parts of ``isf validate`` on the YCB objects.

MuJoCo collides convex parts (:func:`isf.simulation.object_body.convex_parts`): where they stand
outside the mesh, the simulated object is fatter than the real one, and a grasp whose pads
touch the mesh reads as sunk into it. For each of the ten YCB objects (real size, and scaled as
``bench_hold.py`` scales them for ``paper-parallel-scaled``) and each collision mesh of the
bundled grippers and the Franka hand, this prints the number of parts, the time to make them
(CoACD in a child process; 0 when the disk cache had them, so run with an empty
``ISF_CACHE_DIR`` to time it), and the *standoff*: the distance to the mesh of points sampled
evenly (4000, seed 0) on the parts' surfaces that lie outside the mesh (exact distances from coal; outside by the
mesh's generalised winding number), its maximum and 99th percentile, in mm. A point of one part
inside another part counts too, so the figures bound the standoff of the parts' union from
above.

``--tolerance M`` decomposes with another part tolerance (default
:data:`isf.simulation.object_body.PART_TOLERANCE`, 1 mm; 0.005 gives CoACD's default
threshold, 0.05, on every object of 20 cm or less).

Usage:
    python bench/bench_parts.py [--objects Banana,CrackerBox] [--grippers] [--samples 4000]
                                [--tolerance M]
"""

from __future__ import annotations

import _common  # first: pins the threads

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

import isf
from bench_hold import OBJECTS, load, scaled_object
from isf.simulation.object_body import (PART_TOLERANCE, coacd_threshold, convex_parts,
                                         distances_to_mesh)

GRIPPERS = ("paper-parallel", "flat-parallel", "three-finger", "franka-hand", "allegro-right")


def winding_numbers(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The generalised winding number of a closed, outward-oriented mesh at each point (P,):
    1 inside, 0 outside (the solid angles of its triangles, Van Oosterom and Strackee)."""
    out = np.zeros(len(points))
    for start in range(0, len(points), 64):
        a, b, c = (vertices[faces[:, k]][None] - points[start:start + 64, None] for k in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum("pfi,pfi->pf", a, np.cross(b, c))
        div = (la * lb * lc + np.einsum("pfi,pfi->pf", a, b) * lc
               + np.einsum("pfi,pfi->pf", b, c) * la + np.einsum("pfi,pfi->pf", c, a) * lb)
        out[start:start + 64] = np.arctan2(det, div).sum(axis=1) / (2.0 * np.pi)
    return out


def standoff(vertices: np.ndarray, faces: np.ndarray,
             parts: tuple[tuple[np.ndarray, np.ndarray], ...], samples: int) -> tuple[float, float]:
    """Largest and 99th-percentile distance (m) from the mesh of the parts' surface points
    that lie outside it."""
    hulls = [trimesh.Trimesh(v, f) for v, f in parts]
    area = sum(h.area for h in hulls)
    points = np.concatenate([trimesh.sample.sample_surface(h, max(50, int(samples * h.area / area)),
                                                           seed=k)[0]
                             for k, h in enumerate(hulls)])
    distance = distances_to_mesh(points, vertices, faces)
    out = distance[winding_numbers(points, vertices, faces) < 0.5]
    return (float(out.max()), float(np.percentile(out, 99))) if len(out) else (0.0, 0.0)


def row(label: str, vertices: np.ndarray, faces: np.ndarray, samples: int,
        tolerance: float) -> list[str]:
    mesh = trimesh.Trimesh(vertices, faces, process=True)
    mesh.merge_vertices()  # as convex_parts reads it
    vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    start = time.perf_counter()
    parts = convex_parts(vertices, faces, tolerance)
    seconds = time.perf_counter() - start
    most, p99 = standoff(vertices, faces, parts, samples)
    side = float(np.ptp(vertices, axis=0).max())
    return [label, f"{side * 100:.1f}", f"{coacd_threshold(vertices, tolerance):.3f}", str(len(parts)),
            f"{seconds:.1f}", f"{most * 1e3:.2f}", f"{p99 * 1e3:.2f}"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", default=",".join(OBJECTS))
    parser.add_argument("--grippers", action="store_true", help="also the grippers' meshes")
    parser.add_argument("--samples", type=int, default=4000)
    parser.add_argument("--tolerance", type=float, default=PART_TOLERANCE, metavar="M")
    args = parser.parse_args()
    print(_common.machine_description())
    print(f"\npart tolerance = {args.tolerance * 1e3:g} mm\n")
    rows = []
    folder = Path(tempfile.mkdtemp(prefix="isf-parts-"))
    paper = load("paper-parallel", folder)
    for name in args.objects.split(","):
        obj = isf.open_object(f"asset:ycb:{name}")
        rows.append(row(name, obj.mesh_vertices, obj.mesh_faces, args.samples, args.tolerance))
        print(" | ".join(rows[-1]), flush=True)
        scaled, scale = scaled_object(paper, f"asset:ycb:{name}")
        rows.append(row(f"{name} (x{scale:.2f})", scaled.mesh_vertices, scaled.mesh_faces,
                        args.samples, args.tolerance))
        print(" | ".join(rows[-1]), flush=True)
    if args.grippers:
        for gripper_name in GRIPPERS:
            gripper = load(gripper_name, folder)
            for element in gripper.geometries:
                if len(element.faces) >= 4:
                    rows.append(row(f"{gripper_name} {element.name}", element.vertices,
                                    element.faces, args.samples, args.tolerance))
                    print(" | ".join(rows[-1]), flush=True)
    print()
    print(_common.markdown_table(["mesh", "largest side (cm)", "CoACD threshold", "parts",
                                  "seconds", "standoff max (mm)", "standoff p99 (mm)"], rows))


if __name__ == "__main__":
    main()
