"""A fingerprint of isf's plans and fits: sha256 digests of their results, bit for bit.

A change that must not alter any result (a refactor, a move of code, a faster kernel with the
same arithmetic) is checked by running this script before and after it and comparing the
digests: every grasp's pose, joints, errors, contact points, collision report and fit history
enter them as raw float64 bytes, so any difference in any bit changes a digest.

The plans cover the bundled grippers on the shapes isf makes itself (always available), with
and without the collision repair, one fit at a time and in lockstep batches, plus ``isf.fit``
and ``isf.fit_many`` from fixed starts; the YCB banana and mustard bottle join when
``../shared/data/ycb`` is present.

Run from the repository root:
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python scripts/plan_fingerprint.py [--out FILE]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

import isf

YCB = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "ycb"


def _digest_fit(h, fit) -> None:
    """Feed every number of a :class:`isf.FitResult` into the hash ``h``."""
    for array in (fit.q, fit.contact_points, fit.object_points):
        h.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
    h.update(repr((fit.mean_distance, fit.normal_misalignment, fit.error, fit.n_pairs,
                   sorted(fit.surface_contact.items()), fit.iterations, str(fit.status))).encode())
    for record in fit.history:
        h.update(repr((record.level, record.iteration, record.mean_distance, record.error,
                       record.n_pairs, tuple(record.ipfo_errors))).encode())
        h.update(np.ascontiguousarray(record.q, dtype=np.float64).tobytes())


def _digest_plan(result) -> str:
    h = hashlib.sha256()
    for grasp in result.grasps:
        h.update(np.ascontiguousarray(grasp.T_object_gripper, dtype=np.float64).tobytes())
        h.update(repr((grasp.collision_free, grasp.sample_index, sorted(grasp.joints.items()),
                       repr(grasp.collision))).encode())
        _digest_fit(h, grasp.fit)
    h.update(repr((result.stats.samples, result.stats.collision_free, result.stats.valid)).encode())
    return h.hexdigest()


def _cases():
    """(name, gripper, object spec, plan keyword arguments) of every plan fingerprinted."""
    objects = {"cylinder": "shape:cylinder", "box": "shape:box", "torus": "shape:torus"}
    if YCB.is_dir():
        objects["banana"] = str(YCB / "Banana.obj")
        objects["mustard"] = str(YCB / "MustardBottle.obj")
    for gripper in ("paper-parallel", "flat-parallel", "three-finger"):
        for name, spec in objects.items():
            yield f"{gripper}/{name}", gripper, spec, {"samples": 12, "seed": 3}
        yield f"{gripper}/cylinder/no-repair", gripper, "shape:cylinder", {
            "samples": 12, "seed": 5, "repair_collisions": False}
        yield f"{gripper}/box/batch4", gripper, "shape:box", {"samples": 12, "seed": 7, "batch_size": 4}
        yield f"{gripper}/cylinder/uniform-table", gripper, "shape:cylinder", {
            "samples": 12, "seed": 11, "sampler": "uniform", "obstacles": [isf.Plane.table(z=-0.05)]}


def fingerprint() -> dict[str, str]:
    """Digest of each plan case and of the direct fits, by case name."""
    digests: dict[str, str] = {}
    grippers = {name: isf.load_gripper(name) for name in ("paper-parallel", "flat-parallel", "three-finger")}
    for case, gripper, spec, kwargs in _cases():
        obj = isf.open_object(spec)
        digests[case] = _digest_plan(isf.plan(grippers[gripper], obj, **kwargs))
    obj = isf.open_object("shape:cylinder")
    rng = np.random.default_rng(0)
    starts = np.repeat(np.eye(4)[None], 6, axis=0)
    starts[:, :3, 3] = rng.uniform(-0.03, 0.03, (6, 3))
    for name, gripper in grippers.items():
        h = hashlib.sha256()
        _digest_fit(h, isf.fit(gripper, obj, T_object_gripper=starts[0]))
        for fit in isf.fit_many(gripper, obj, T_object_gripper=starts):
            _digest_fit(h, fit)
        digests[f"{name}/fits"] = h.hexdigest()
    return digests


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, help="also write the digests as JSON to this file")
    parser.add_argument("--compare", type=Path, help="compare with digests written by --out; "
                        "exit 1 on any difference")
    args = parser.parse_args(argv)
    digests = fingerprint()
    for case, digest in digests.items():
        print(f"{digest[:16]}  {case}")
    if args.out:
        args.out.write_text(json.dumps(digests, indent=1, sort_keys=True))
    if args.compare:
        expected = json.loads(args.compare.read_text())
        differ = sorted(case for case in expected.keys() | digests.keys()
                        if expected.get(case) != digests.get(case))
        print(f"{len(expected) - len(differ)} of {len(expected)} cases identical"
              + (f"; differ: {', '.join(differ)}" if differ else ""))
        return 1 if differ else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
