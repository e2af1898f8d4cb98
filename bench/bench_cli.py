"""What a command-line run costs: its start-up, and several objects in one run against one each.

Every measurement runs in fresh processes, as a user's commands do:

* ``import isf`` and ``isf.warming.warm_up()`` (loading the compiled kernels from numba's
  cache), timed inside a fresh interpreter;
* ``isf plan`` of the ``--objects`` (default: the five shapes isf makes) in one run, writing one
  JSON each with ``--out-dir``, against one ``isf plan`` per object: wall time of the whole
  commands, and their ratio within each repeat.

Both ways plan the same grasps (same gripper, samples and seed); the script checks that the
files agree. Medians over ``--repeats`` repeats.

Run from the repository root:
    python bench/bench_cli.py [--repeats 5] [--objects asset:bunny,shape:box] [--samples 60]
"""

from __future__ import annotations

import _common

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

GRIPPER = "paper-parallel"
OBJECTS = "shape:cylinder,shape:box,shape:sphere,shape:capsule,shape:torus"
START_UP = ("import json, time; t0 = time.perf_counter(); import isf; t1 = time.perf_counter(); "
            "from isf.warming import warm_up; warm_up(); t2 = time.perf_counter(); "
            "print(json.dumps({'import': t1 - t0, 'kernels': t2 - t1}))")


def _run(command: list[str]) -> float:
    """Wall time of ``command``, seconds; exits with its stderr when it fails."""
    start = time.perf_counter()
    proc = subprocess.run(command, capture_output=True, text=True)
    if proc.returncode not in (0, 1):  # 1: a plan without a collision-free grasp
        raise SystemExit(f"{' '.join(command)} failed:\n{proc.stderr}")
    return time.perf_counter() - start


def _plan(objects: list[str], samples: int, out: list[str]) -> list[str]:
    flags = [flag for spec in objects for flag in ("--object", spec)]
    return [sys.executable, "-m", "isf", "plan", "--gripper", GRIPPER, *flags,
            "--samples", str(samples), "--rank", "fit", "--no-centring",
            "--sampler-param", "com_share=0", "--quiet", *out]


def _plan_file(path: Path) -> tuple[str, list]:
    """The object named in a plan's JSON, and its grasps' poses."""
    data = json.loads(path.read_text())
    return data["object"], [g["T_object_gripper"] for g in data["grasps"]]


def repeat(objects: list[str], samples: int, folder: Path) -> dict:
    """One repeat: the start-up, one run for all objects, one run per object."""
    start_up = subprocess.run([sys.executable, "-c", START_UP], capture_output=True, text=True,
                              check=True)
    row = json.loads(start_up.stdout.strip().splitlines()[-1])
    together = folder / "together"
    row["together"] = _run(_plan(objects, samples, ["--out-dir", str(together)]))
    planned = dict(_plan_file(path) for path in together.iterdir())
    row["apart"] = 0.0
    for i, spec in enumerate(objects):
        single = folder / f"single-{i}.json"
        row["apart"] += _run(_plan([spec], samples, ["--out", str(single)]))
        name, poses = _plan_file(single)
        if planned.get(name) != poses:
            raise SystemExit(f"{spec}: the run of all objects planned other grasps than its own")
    return row


def main() -> None:
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=5, budget=0)
    parser.add_argument("--objects", default=OBJECTS,
                        help=f"comma-separated object specs of isf plan (default {OBJECTS})")
    parser.add_argument("--samples", type=int, default=60, help="samples per plan (default 60)")
    args = parser.parse_args()
    objects = args.objects.split(",")
    if args.quick:
        objects, args.repeats = objects[:2], min(args.repeats, 2)
    started = time.perf_counter()
    header = _common.machine_description()
    rows = []
    for r in range(args.repeats):
        with tempfile.TemporaryDirectory() as folder:
            rows.append(repeat(objects, args.samples, Path(folder)))
        print(f"#   repeat {r}: {len(objects)} objects in one run {rows[-1]['together']:.2f} s, "
              f"in {len(objects)} runs {rows[-1]['apart']:.2f} s", flush=True)
    timing = {key: _common.Timing(tuple(row[key] for row in rows), args.repeats)
              for key in ("import", "kernels", "together", "apart")}
    ratio = _common.Timing(tuple(row["apart"] / row["together"] for row in rows), args.repeats)
    table = _common.markdown_table(["what", "seconds, median (min-max)"], [
        ["`import isf`, fresh interpreter", timing["import"].spread()],
        ["`isf.warming.warm_up()` after it (loading the cached kernels)",
         timing["kernels"].spread()],
        [f"`isf plan` of the {len(objects)} objects in one run (`--out-dir`)",
         timing["together"].spread()],
        [f"`isf plan` once per object ({len(objects)} runs)", timing["apart"].spread()],
        ["ratio of the two, per repeat (runs per object / one run)", ratio.spread()],
    ])
    text = (f"Gripper `{GRIPPER}`, {args.samples} samples, seed 0, one thread, objects: "
            f"{', '.join(f'`{o}`' for o in objects)}; {args.repeats} repeats, each in fresh "
            "processes. The plans of both ways are the same (checked).")
    _common.finish("bench_cli: start-up of a command-line run, and several objects in one run",
                   ["### Command-line runs", text, table], started, header, args.out)


if __name__ == "__main__":
    main()
