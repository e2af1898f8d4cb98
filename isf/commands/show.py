"""``isf show``: a plan file as one self-contained HTML page (docs/viewer.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

EXIT_OK = 0


def add_source_options(p: argparse.ArgumentParser) -> None:
    """The options that name a plan's gripper and object when its file does not find them."""
    g = p.add_argument_group("gripper and object", "by default those the plan file names "
                             "(its provenance when recorded)")
    g.add_argument("--gripper", "-g", default=None, help="bundled gripper name or tagged URDF")
    g.add_argument("--object", "-o", default=None, metavar="OBJECT",
                   help="the object's mesh/cloud file, shape:NAME or asset:NAME (for a scene "
                        "plan: the depth image or cloud)")
    g.add_argument("--units", choices=("m", "cm", "mm"), default=None, help="units of the object file")
    g.add_argument("--scale", type=float, default=None, help="extra scale factor of the object")
    g.add_argument("--intrinsics", default=None, metavar="FX,FY,CX,CY",
                   help="a scene depth image's intrinsics, pixels")
    g.add_argument("--depth-scale", type=float, default=None, metavar="S",
                   help="metres per unit of the scene file")
    g.add_argument("--cloud-frame", choices=("camera", "scene"), default=None,
                   help="the frame of a scene point cloud's coordinates")
    p.add_argument("--geometry", choices=("collision", "visual"), default="collision",
                   help="draw the URDF's collision (default: what isf checks) or visual meshes")


def source_options(args: argparse.Namespace):
    """The :class:`isf.viewer.SourceOptions` of :func:`add_source_options`' options."""
    from ..viewer import SourceOptions

    return SourceOptions(gripper=args.gripper, object_spec=args.object, units=args.units,
                         scale=args.scale, intrinsics=args.intrinsics,
                         depth_scale=args.depth_scale, cloud_frame=args.cloud_frame)


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("show", help="write a plan's grasps as an offline HTML page",
                              description=(
        "Write PLAN (a grasp file of 'isf plan') as one HTML file that opens from disk without "
        "a network: the object, the gripper's link meshes at each grasp, its contact points "
        "coloured by distance, the list of grasps (click one to show it) and each grasp's ISF "
        "convergence plot. The gripper and object are loaded again from the names in the file "
        "(docs/viewer.md)."))
    p.add_argument("plan", help="the grasp file (JSON)")
    p.add_argument("--out", default=None, metavar="FILE",
                   help="the HTML file to write (default: PLAN with suffix .html)")
    p.add_argument("--top", type=int, default=None, metavar="K", help="show only the best K grasps")
    add_source_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..exceptions import InvalidInputError
    from ..output_files import check_output_path
    from ..viewer import load_sources, open_plan, require_viewer, write_report

    require_viewer("show")
    if args.top is not None and args.top < 1:
        raise InvalidInputError(f"--top {args.top}: give a positive number of grasps")
    out = Path(args.out) if args.out else Path(args.plan).with_suffix(".html")
    check_output_path(out, "report file")
    plan = open_plan(args.plan)
    summary = write_report(plan, load_sources(plan, source_options(args)), out, top=args.top,
                           geometry=args.geometry)
    print(f"wrote {out}: {summary.grasps} grasps, {summary.size / 1e6:.1f} MB")
    return EXIT_OK
