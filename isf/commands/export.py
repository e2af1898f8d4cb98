"""``isf export``: the object and the gripper at one grasp as a mesh scene file (docs/viewer.md)."""

from __future__ import annotations

import argparse

from .show import add_source_options, source_options

EXIT_OK = 0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("export", help="write the object and a grasp's gripper as a mesh scene (glb, ply, obj)",
                              description=(
        "Write the object and the gripper's link meshes at the grasp of rank N of PLAN (a grasp "
        "file of 'isf plan') as one scene in the object frame, metres: .glb (nodes 'object' and "
        "'gripper' with one child per link mesh), .ply (one mesh) or .obj, for Blender, "
        "MeshLab or RViz. A point-cloud object (a scene plan) exports to .glb only."))
    p.add_argument("plan", help="the grasp file (JSON)")
    p.add_argument("--rank", type=int, default=1, metavar="N", help="the grasp's rank (default 1, the best)")
    p.add_argument("--out", required=True, metavar="FILE", help="the .glb, .ply or .obj file to write")
    add_source_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..registration.preview import check_export_path
    from ..viewer import export_grasp, load_sources, open_plan, require_viewer

    require_viewer("export", ("yourdfpy",))
    check_export_path(args.out)
    plan = open_plan(args.plan)
    grasp = plan.grasp(args.rank)
    path = export_grasp(load_sources(plan, source_options(args)), grasp, args.out,
                        geometry=args.geometry)
    print(f"wrote {path}: grasp {args.rank} of {plan.path.name}")
    return EXIT_OK
