"""``isf validate``: test a plan's best grasps in MuJoCo physics (the optional extra ``isf[sim]``)."""

from __future__ import annotations

import json
from pathlib import Path

__all__ = ["add_parser", "run"]


def add_parser(subparsers) -> None:
    """Add the ``validate`` subcommand's parser."""
    p = subparsers.add_parser(
        "validate", help="test a plan's best grasps in physics (MuJoCo; pip install 'isf[sim]')",
        description=(
            "Simulate the best K grasps of PLAN.json in MuJoCo: the fingers close from slightly "
            "open with bounded force (gravity off), then the gripper holds the object against "
            "gravity along +x, -x, +y, -y, +z and -z of the object frame. Each grasp gets a "
            "'validation' (held, slipped, ejected or penetrating, by direction) in the plan "
            "file (docs/validate.md)."))
    p.add_argument("plan", metavar="PLAN.json", help="a plan file written by 'isf plan'")
    p.add_argument("--top", type=int, default=5, metavar="K", help="grasps to test (default 5)")
    p.add_argument("--friction", type=float, default=None,
                   help="Coulomb friction coefficient of the contacts (default: the one the plan "
                        "was ranked with, else 0.5)")
    p.add_argument("--mass", type=float, default=None, metavar="KG",
                   help="object mass, kg, uniform density (default: the one the plan was ranked "
                        "with, else 0.3)")
    p.add_argument("--finger-force", type=float, default=20.0, metavar="N",
                   help="normal force each contact surface can press with, N: a parallel "
                        "gripper squeezes with it from each jaw (default 20)")
    p.add_argument("--part-tolerance", type=float, default=0.001, metavar="M",
                   help="how far the simulated convex parts may stand off the object's and the "
                        "gripper's meshes, m: smaller is more faithful and slower (default 0.001)")
    p.add_argument("--gripper", "-g", default=None,
                   help="bundled gripper name or URDF path (default: the plan's)")
    p.add_argument("--object", "-o", default=None,
                   help="the object's mesh file or spec (default: the plan's)")
    p.add_argument("--out", default=None, metavar="PLAN.json",
                   help="where to write the validated plan (default: PLAN.json itself)")
    p.set_defaults(run=run)


def run(args) -> int:
    """Validate, write the plan, print one line per grasp; exit 0 (1 when no grasp held)."""
    from ..exceptions import InvalidInputError
    from ..output_files import write_atomically
    from ..simulation import SimulationSettings, validate_plan

    path = Path(args.plan)
    try:
        plan = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise InvalidInputError(f"cannot read plan file {str(path)!r}: {error}") from None
    if not isinstance(plan, dict) or "grasps" not in plan:
        raise InvalidInputError(f"{str(path)!r} is not a plan file written by 'isf plan'")
    settings = SimulationSettings.for_plan(plan, friction=args.friction, mass=args.mass,
                                           finger_force=args.finger_force,
                                           part_tolerance=args.part_tolerance)
    result = validate_plan(plan, top=args.top, settings=settings, gripper=args.gripper,
                           object_spec=args.object)
    out = Path(args.out) if args.out else path
    write_atomically(out, (json.dumps(result.plan, indent=2) + "\n").encode("utf-8"), "plan file")
    print(f"{'rank':>4}  {'outcome':<11}  held  by direction (+x -x +y -y +z -z)")
    for grasp, v in zip(result.plan["grasps"], result.results):
        marks = " ".join(d.outcome.value[0].upper() for d in v.directions) or "-"
        print(f"{grasp['rank']:>4}  {v.outcome.value:<11}  {v.held_directions}/6   {marks}")
    held = sum(v.outcome.value == "held" for v in result.results)
    print(f"{held} of {len(result.results)} grasps held in all six directions "
          f"(friction {settings.friction}, {settings.mass} kg); written to {out}")
    return 0 if held else 1
