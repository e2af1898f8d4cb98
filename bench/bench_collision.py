"""Collision-check cost and verdict agreement: this tree against a baseline tree.

A *corpus* of gripper poses is built once with ``isf.plan`` (60 samples, regret sampler, seed 0)
and saved: the fitted grasps of every (gripper, object) pair below, plus each grasp perturbed
by a random 1-5 mm shift and 2-5 degree turn (about a random axis through the palm frame).
Both trees then check the same poses:

* **after**: this tree's :class:`isf.collision.checker.CollisionChecker`, in this process;
* **before**: the tree named by ``--base`` (a git worktree of the original commit), run as a
  subprocess of this script with that tree first on ``PYTHONPATH`` (``--worker`` mode).

Reported: the median per-check time over ``--repeats`` passes over the timing poses of each
configuration (paper-parallel on the cylinder and the bunny, three-finger on the sphere,
Allegro on ``asset:ycb:TomatoSoupCan``, or a shape when YCB is absent) and, over the whole corpus,
how many poses get a different ``collision_free`` or ``colliding_links``; a disagreement is
*explained* when the baseline's penetration lies within 0.1 mm of the 2 mm tolerance.

The Allegro hand is tagged as the tests do (``isf.registration.suggest_contacts`` and
``tag_urdf`` with ``suggest_approach``) into a temporary folder.

Also reported: the exact tangent-plane estimates per check (``CollisionChecker.estimates``;
"-" for a tree that does not count them).

Run from the repository root (the baseline worktree, by default ``../wt-base`` beside the
repository: ``git worktree add ../wt-base 99ad016``); ``--corpus`` and ``--baseline`` files are
reused when they exist, so iterating re-runs neither the plans nor the slow baseline:
    python bench/bench_collision.py [--base ../wt-base] [--corpus /tmp/corpus.npz]
                                    [--baseline /tmp/before.json] [--repeats 5] [--quick]
"""

from __future__ import annotations

import _common

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

YCB = "asset:ycb:TomatoSoupCan"
#: (gripper, object, in the corpus, timed): the corpus pairs and the timed configurations.
PAIRS = (
    ("paper-parallel", "shape:cylinder", True, True),
    ("paper-parallel", "asset:bunny", True, True),
    ("paper-parallel", YCB, True, False),
    ("three-finger", "shape:cylinder", True, False),
    ("three-finger", "asset:bunny", True, False),
    ("three-finger", YCB, True, False),
    ("three-finger", "shape:sphere", False, True),
    ("allegro-right", YCB, False, True),
)
SAMPLES = 60
NEAR_TOLERANCE = 1e-4  # m: disagreements this close to the tolerance are explained
TOLERANCE = 0.002


def ycb_present() -> bool:
    from isf import assets

    try:
        assets.benchmark_object(YCB.removeprefix("asset:"))
    except Exception:
        return False
    return True


def object_spec(spec: str) -> str:
    """``spec``, or a built-in shape in place of a YCB object when YCB is absent."""
    return spec if not spec.startswith("asset:ycb:") or ycb_present() else "shape:cylinder"


def load_gripper(name: str, workdir: Path):
    import isf

    if name != "allegro-right":
        return isf.load_gripper(name)
    from isf.assets import vendor_gripper
    from isf.registration import suggest_approach, suggest_contacts, tag_urdf

    src = vendor_gripper(name)
    preview = tag_urdf(src, workdir / f"{name}.urdf", suggest_contacts(src, points=64),
                       approach=suggest_approach(src))
    return isf.load_gripper(preview.urdf_path)


def key(gripper: str, obj: str) -> str:
    return f"{gripper}|{obj}"


# --------------------------------------------------------------------------- corpus


def perturbed(T: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``T`` moved by a random 1-5 mm shift and turned 2-5 degrees about a random axis."""
    from scipy.spatial.transform import Rotation

    axis = rng.normal(size=3)
    turn = Rotation.from_rotvec(axis / np.linalg.norm(axis) * np.radians(rng.uniform(2, 5)))
    shift = rng.normal(size=3)
    out = T.copy()
    out[:3, :3] = turn.as_matrix() @ T[:3, :3]
    out[:3, 3] += shift / np.linalg.norm(shift) * rng.uniform(0.001, 0.005)
    return out


def build_corpus(path: Path, workdir: Path, quick: bool) -> None:
    import isf

    arrays, rng = {}, np.random.default_rng(1)
    for gname, ospec, in_corpus, _timed in PAIRS:
        gripper = load_gripper(gname, workdir)
        obj = isf.open_object(object_spec(ospec))
        t0 = time.perf_counter()
        result = isf.plan(gripper, obj, samples=20 if quick else SAMPLES, seed=0)
        T = np.array([g.T_object_gripper for g in result.grasps])
        q = np.array([g.q for g in result.grasps])
        if in_corpus:
            T = np.concatenate([T, [perturbed(t, rng) for t in T]])
            q = np.concatenate([q, q])
        print(f"# corpus {gname} on {ospec}: {len(T)} poses ({time.perf_counter() - t0:.0f} s)",
              flush=True)
        arrays[key(gname, ospec) + "|T"], arrays[key(gname, ospec) + "|q"] = T, q
    np.savez(path, **arrays)


# --------------------------------------------------------------------------- worker


def run_worker(corpus: Path, out: Path, repeats: int) -> None:
    """Check every pose of ``corpus`` with the ``isf`` on the path; write verdicts and timings."""
    import isf
    from isf.collision.checker import CollisionChecker

    data = np.load(corpus)
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for gname, ospec, in_corpus, timed in PAIRS:
            gripper = load_gripper(gname, Path(tmp))
            obj = isf.open_object(object_spec(ospec))
            t0 = time.perf_counter()
            checker = CollisionChecker(gripper, obj, tolerance=TOLERANCE)
            setup = time.perf_counter() - t0
            T, q = data[key(gname, ospec) + "|T"], data[key(gname, ospec) + "|q"]
            reports = [checker.check(t, j) for t, j in zip(T, q)]
            estimates = getattr(checker, "estimates", None)  # counted by newer trees only
            row = {"setup": setup, "n": len(T), "estimates": None if estimates is None else estimates / len(T),
                   "free": [r.collision_free for r in reports],
                   "links": [list(r.colliding_links) for r in reports],
                   "penetration": [r.penetration for r in reports],
                   "clearance": [r.clearance for r in reports]}
            if timed:
                n_fitted = len(T) // 2 if in_corpus else len(T)  # time the fitted grasps only
                per_check, per_check_cpu = [], []
                for _ in range(repeats):
                    t0, c0 = time.perf_counter(), time.process_time()
                    for t, j in zip(T[:n_fitted], q[:n_fitted]):
                        checker.check(t, j)
                    per_check.append((time.perf_counter() - t0) / n_fitted)
                    per_check_cpu.append((time.process_time() - c0) / n_fitted)
                row["per_check"], row["per_check_cpu"] = per_check, per_check_cpu
            results[key(gname, ospec)] = row
            print(f"# {isf.__file__}: {gname} on {ospec} done", file=sys.stderr, flush=True)
    out.write_text(json.dumps(results))


def worker_results(base: Path | None, corpus: Path, repeats: int, tmp: Path,
                   reuse: Path | None = None) -> dict:
    """Results of ``--worker`` with ``base`` (or this tree when None) first on PYTHONPATH; read
    from ``reuse`` instead when that file exists (written there otherwise)."""
    if reuse is not None and reuse.exists():
        return json.loads(reuse.read_text())
    tree = base if base is not None else _common.REPO
    out = reuse or tmp / f"{tree.name}.json"
    env = dict(os.environ, PYTHONPATH=str(tree))
    subprocess.run([sys.executable, __file__, "--worker", str(corpus), "--worker-out", str(out),
                    "--repeats", str(repeats)], check=True, env=env)
    return json.loads(out.read_text())


# --------------------------------------------------------------------------- report


def agreement(before: dict, after: dict) -> tuple[list[list[object]], list[str]]:
    rows, notes = [], []
    for gname, ospec, in_corpus, _ in PAIRS:
        if not in_corpus:
            continue
        b, a = before[key(gname, ospec)], after[key(gname, ospec)]
        differ = explained = 0
        for i in range(b["n"]):
            if b["free"][i] == a["free"][i] and b["links"][i] == a["links"][i]:
                continue
            differ += 1
            near = abs(b["penetration"][i] - TOLERANCE) <= NEAR_TOLERANCE
            explained += near
            notes.append(f"- {gname} on {ospec}, pose {i}: before free={b['free'][i]} "
                         f"links={b['links'][i]} penetration={b['penetration'][i] * 1e3:.3f} mm; "
                         f"after free={a['free'][i]} links={a['links'][i]} penetration="
                         f"{a['penetration'][i] * 1e3:.3f} mm"
                         f"{' (within 0.1 mm of the tolerance)' if near else ' (UNEXPLAINED)'}")
        pen = np.abs(np.subtract(b["penetration"], a["penetration"]))
        both = [(x, y) for x, y in zip(b["clearance"], a["clearance"]) if x > 0 or y > 0]
        clr = np.abs(np.subtract(*zip(*both))) if both else np.zeros(1)
        rows.append([gname, ospec, b["n"], sum(not f for f in b["free"]), differ, explained,
                     f"{np.median(pen) * 1e3:.3f} / {pen.max() * 1e3:.3f}",
                     f"{np.median(clr) * 1e3:.3f} / {clr.max() * 1e3:.3f}"])
    return rows, notes


def timing_rows(before: dict, after: dict) -> list[list[object]]:
    rows = []
    for gname, ospec, _, timed in PAIRS:
        if not timed:
            continue
        b, a = before[key(gname, ospec)], after[key(gname, ospec)]
        tb, ta = statistics.median(b["per_check"]), statistics.median(a["per_check"])
        cb, ca = statistics.median(b["per_check_cpu"]), statistics.median(a["per_check_cpu"])
        estimates = [f"{r['estimates']:.0f}" if r.get("estimates") is not None else "-" for r in (b, a)]
        rows.append([gname, object_spec(ospec), a["n"] // (2 if b["n"] > 60 else 1),
                     len(a["per_check"]), f"{tb * 1e3:.2f}", f"{ta * 1e3:.2f}",
                     f"{cb * 1e3:.2f}", f"{ca * 1e3:.2f}", f"{cb / ca:.1f}x",
                     f"{b['setup'] * 1e3:.0f} / {a['setup'] * 1e3:.0f}", " / ".join(estimates)])
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", type=Path, default=_common.REPO.parent / "wt-base",
                        help="worktree of the original commit (default ../wt-base: git worktree "
                             "add ../wt-base 99ad016)")
    parser.add_argument("--corpus", type=Path, default=None,
                        help="pose corpus file: reused when it exists, else built and saved")
    parser.add_argument("--repeats", type=int, default=5, help="timing passes (median reported)")
    parser.add_argument("--quick", action="store_true", help="20 samples per plan, not 60")
    parser.add_argument("--baseline", type=Path, default=None,
                        help="baseline results file: reused when it exists, else written (saves "
                             "re-running the slow baseline while iterating)")
    parser.add_argument("--out", default=None, help="also write the markdown report here")
    parser.add_argument("--worker", type=Path, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--worker-out", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker is not None:
        run_worker(args.worker, args.worker_out, args.repeats)
        return
    started = time.perf_counter()
    header = _common.machine_description()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        corpus = args.corpus or tmp / "corpus.npz"
        if not corpus.exists():
            build_corpus(corpus, tmp, args.quick)
        before = worker_results(args.base.resolve(), corpus, args.repeats, tmp, args.baseline)
        after = worker_results(None, corpus, args.repeats, tmp)
    rows, notes = agreement(before, after)
    objects = "YCB present" if ycb_present() else "YCB absent: ycb:* replaced by shape:cylinder"
    sections = [
        f"Baseline: `{args.base}`; objects: {objects}.",
        "### Time per check (median over passes of the mean per check over the fitted grasps)",
        _common.markdown_table(["gripper", "object", "poses", "passes", "before ms (wall)",
                                "after ms (wall)", "before ms (CPU)", "after ms (CPU)",
                                "speed-up (CPU)", "setup ms before / after",
                                "estimates per check before / after (whole corpus)"],
                               timing_rows(before, after)),
        "Wall time counts waiting for a core on a shared machine; CPU time (process time) does not.",
        "### Verdict agreement over the corpus (fitted grasps + perturbed copies)",
        _common.markdown_table(["gripper", "object", "poses", "colliding (before)",
                                "verdicts differ", "of which within 0.1 mm of tolerance",
                                "|penetration diff| mm median / max",
                                "|clearance diff| mm median / max"], rows),
        "Disagreements:\n\n" + ("\n".join(notes) if notes else "none"),
    ]
    _common.finish("Collision checks: before / after", sections, started, header, args.out)


if __name__ == "__main__":
    main()
