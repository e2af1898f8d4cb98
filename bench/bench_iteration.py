"""Cost of one ISF iteration against its floors: a nearest-neighbour query and Open3D's ICP.

For the paper gripper (``paper-parallel``, 2 x 256 contact points) on two objects of about 2000
surface points (``shape:cylinder`` and the Stanford bunny scaled to a 25 mm middle extent),
measured in the same process, one thread:

(a) ours, lockstep: ``isf.fit_many`` over a fixed set of ``--fits`` starts (uniform-sampler
    proposals, seed 0, so every repeat does the same work); time per ISF iteration = wall (and
    process CPU) time of the whole call / the sum of ``FitResult.iterations``;
(a1) ours, batch of 1 (the paper's sequential loop): one ``isf.fit`` per start, same starts;
    wall = sum of ``FitResult.time`` / sum of iterations (CPU: process time around the calls);
(b) the nearest-neighbour floor for the same query points: ISF queries the contact points of
    the fit's current pyramid level (512, 256, 128 or 64 points for this gripper); the floor is
    ``ObjectSurface.nearest`` on each level's points at the fitted poses (object frame),
    weighted by the share of the ISF iterations that ran on that level, once per fit (the
    batch-of-1 floor) and stacked over all fits in one call divided by the number of fits (the
    lockstep floor: the engine makes one query per round); the full 512-point query,
    ``isf.fitting.correspondence.match`` (nearest + outlier and duplicate filters) and
    ``Gripper.contact_kinematics`` are given beside;
(c) Open3D's point-to-plane ICP on the 512 contact points at the fitted poses (target: the
    object's points with their normals; max correspondence distance 5 mm):
    ``registration_icp(..., ICPConvergenceCriteria(max_iteration=1))`` per call, which builds the
    target's KD-tree and searches correspondences twice, and the marginal cost of one more
    iteration, ``(t(max_iteration=11) - t(max_iteration=1)) / 10`` with the relative stop
    criteria set to 0 so all iterations run. As a check that this reference is well posed, the
    table gives Open3D's fitness after 11 iterations and the share of runs that lost every
    match (point-to-plane ICP is degenerate along a cylinder's axis: Open3D's unregularised
    step then jumps away, and its later iterations search for nothing).

Each figure is the median over ``--repeats`` repeats (>= 5 by default); within a repeat the
micro-benchmarks (b), (c) take the median of many calls. Ratios: ours / (b) and ours / (c), for
the lockstep engine and for the batch of 1. The mean fitting error of both engines is printed
as a check that they did the same work (the paper reports no per-iteration time).

Run from the repository root:  python bench/bench_iteration.py [--quick] [--repeats 5] [--fits 32]
"""

from __future__ import annotations

import _common

import time

import numpy as np

import isf
from isf.fitting.correspondence import match

GRIPPER = "paper-parallel"
MAX_POINTS = 2000
ICP_DISTANCE = 0.005  # m, max correspondence distance of Open3D's ICP (isf's outlier floor)
MARGINAL_EXTRA = 10  # extra ICP iterations for the marginal-cost estimate


def load_objects(quick: bool) -> list[isf.ObjectSurface]:
    objects = [isf.open_object("shape:cylinder", max_points=MAX_POINTS)]
    if not quick:
        bunny, _ = _common.scaled_benchmark_object("bunny", max_points=MAX_POINTS)
        objects.append(bunny)
    return objects


def starts(gripper: isf.Gripper, obj: isf.ObjectSurface, n: int) -> list:
    """``n`` initial poses from the uniform sampler, seed 0 (the same for every repeat)."""
    rng = np.random.default_rng(0)
    sampler = isf.get_sampler("uniform")
    sampler.reset(obj, gripper, rng)
    return sampler.propose(n, rng)


def fit_lockstep(gripper, obj, proposals, config) -> dict:
    """(a): every start in one ``isf.fit_many``; per-iteration wall and CPU time."""
    T = np.stack([p.T_object_gripper for p in proposals])
    q = None if any(p.q is None for p in proposals) else np.stack([p.q for p in proposals])
    c0, t0 = time.process_time(), time.perf_counter()
    results = isf.fit_many(gripper, obj, T, q, config)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return _summary(results, wall, cpu)


def fit_one_by_one(gripper, obj, proposals, config) -> dict:
    """(a1): one ``isf.fit`` per start (batch of 1); per-iteration wall and CPU time."""
    results, cpu = [], 0.0
    for p in proposals:
        c0 = time.process_time()
        results.append(isf.fit(gripper, obj, p.T_object_gripper, p.q, config))
        cpu += time.process_time() - c0
    return _summary(results, sum(r.time for r in results), cpu)


def _summary(results, wall: float, cpu: float) -> dict:
    iterations = sum(r.iterations for r in results)
    levels = np.array([rec.level for r in results for rec in r.history[1:]], dtype=int)  # no start
    return {"per_iteration": wall / max(iterations, 1),
            "cpu_per_iteration": cpu / max(iterations, 1),
            "iterations": iterations / len(results),
            "error": float(np.mean([r.mean_distance for r in results])),
            "levels": levels, "fitted": [(r.T_object_gripper, r.q) for r in results]}


def contact_points_object(gripper: isf.Gripper, T: np.ndarray, q: np.ndarray) -> np.ndarray:
    """All contact points at (T, q) in the object frame, shape (n_points, 3)."""
    points = gripper.contact_kinematics(q).points
    return points @ T[:3, :3].T + T[:3, 3]


def cycle(items: list):
    """A zero-argument function returning the next item of ``items`` on each call."""
    state = {"i": -1}

    def nxt():
        state["i"] = (state["i"] + 1) % len(items)
        return items[state["i"]]

    return nxt


def floors(gripper, obj, fitted, levels, config, calls: int) -> dict:
    """(b): nearest, match and contact_kinematics on the fitted configurations.

    Args:
        fitted: (T, q) of every fit.
        levels: the pyramid level of every ISF iteration (weights of the per-level queries).

    Every value is a (wall, CPU) pair of medians, seconds.
    """
    clouds = [contact_points_object(gripper, T, q) for T, q in fitted]
    qs = [q for _, q in fitted]
    next_cloud, next_q = cycle(clouds), cycle(qs)
    share = np.bincount(levels, minlength=config.levels) / max(len(levels), 1)
    single, stacked = np.zeros(2), np.zeros(2)
    for level in np.flatnonzero(share):
        mask = gripper.level_mask(int(level))
        parts = [c[mask] for c in clouds]
        queries = cycle(parts)
        one = _common.time_calls(lambda: obj.nearest(next(queries)), calls)  # noqa: B023 (timed here)
        all_fits = np.concatenate(parts)
        many = _common.time_calls(lambda: obj.nearest(all_fits), max(calls // 8, 5))  # noqa: B023 (timed here)
        single += share[level] * np.array(one)
        stacked += share[level] * np.array(many) / len(parts)
    points = float(sum(share[level] * gripper.level_mask(int(level)).sum()
                       for level in range(config.levels)))
    return {
        "nearest_same": tuple(single), "nearest_stacked": tuple(stacked),
        "query_points": points,
        "nearest": _common.time_calls(lambda: obj.nearest(next_cloud()), calls),
        "match": _common.time_calls(lambda: match(
            obj, next_cloud(), outlier_factor=config.outlier_factor,
            outlier_floor=config.outlier_floor, reject_duplicates=config.reject_duplicates),
            calls),
        "kinematics": _common.time_calls(lambda: gripper.contact_kinematics(next_q()), calls),
        "clouds": clouds,
    }


def open3d_icp(o3d, obj, clouds, calls: int) -> dict:
    """(c): Open3D point-to-plane ICP on the same points; (wall, CPU) pairs, seconds."""
    reg = o3d.pipelines.registration
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(obj.points))
    target.normals = o3d.utility.Vector3dVector(obj.normals)
    sources = [o3d.geometry.PointCloud(o3d.utility.Vector3dVector(c)) for c in clouds]
    estimation = reg.TransformationEstimationPointToPlane()
    identity = np.eye(4)

    def runner(iterations: int):
        criteria = reg.ICPConvergenceCriteria(relative_fitness=0.0, relative_rmse=0.0,
                                              max_iteration=iterations)
        nxt = cycle(sources)
        return lambda: reg.registration_icp(nxt(), target, ICP_DISTANCE, identity, estimation,
                                            criteria)

    one = _common.time_calls(runner(1), calls)
    many = _common.time_calls(runner(1 + MARGINAL_EXTRA), max(calls // 2, 5))
    marginal = tuple(max(m - o, 0.0) / MARGINAL_EXTRA for m, o in zip(many, one))
    # Is the reference well posed? Point-to-plane ICP has no answer along symmetry directions
    # (a cylinder's axis): Open3D's unregularised step then jumps away and loses every match.
    run = runner(1 + MARGINAL_EXTRA)
    results = [run() for _ in sources]
    fitness = float(np.median([r.fitness for r in results]))
    lost = float(np.mean([r.fitness == 0.0 or not np.all(np.isfinite(r.transformation))
                          or np.linalg.norm(r.transformation[:3, 3]) > 1.0 for r in results]))
    return {"call": one, "marginal": marginal, "fitness": fitness, "lost": lost}


QUANTITIES = ("ours", "ours_b1", "nearest_stacked", "nearest_same", "nearest", "match",
              "kinematics", "o3d_call", "o3d_marginal")


def bench_object(gripper, obj, args, o3d) -> dict:
    config = isf.FitConfig()
    proposals = starts(gripper, obj, args.fits)
    nan2 = (np.nan, np.nan)

    def one_repeat(_seed: int) -> dict:
        a = fit_lockstep(gripper, obj, proposals, config)
        a1 = fit_one_by_one(gripper, obj, proposals, config)
        b = floors(gripper, obj, a["fitted"], a["levels"], config, args.calls)
        c = open3d_icp(o3d, obj, b["clouds"], args.calls) if o3d else {
            "call": nan2, "marginal": nan2, "fitness": np.nan, "lost": np.nan}
        print(f"#   {obj.name}: {1e3 * a['per_iteration']:.3f} ms per ISF iteration in lockstep, "
              f"{1e3 * a1['per_iteration']:.3f} ms one fit at a time", flush=True)
        pairs = {"ours": (a["per_iteration"], a["cpu_per_iteration"]),
                 "ours_b1": (a1["per_iteration"], a1["cpu_per_iteration"]),
                 "nearest_same": b["nearest_same"], "nearest_stacked": b["nearest_stacked"],
                 "nearest": b["nearest"], "match": b["match"], "kinematics": b["kinematics"],
                 "o3d_call": c["call"], "o3d_marginal": c["marginal"]}
        out = {"iterations": a["iterations"], "iterations_b1": a1["iterations"],
               "error": a["error"], "error_b1": a1["error"], "query_points": b["query_points"],
               "o3d_fitness": c["fitness"], "o3d_lost": c["lost"]}
        for key, (wall, cpu) in pairs.items():
            out[key], out[key + "_cpu"] = wall, cpu
        return out

    runs, _ = _common.run_repeats(one_repeat, args.repeats, _common.budget_or_none(args))
    row = _common.median_row(runs, [], args.repeats, key="ours")
    row["object"], row["points"] = obj.name, obj.n_points
    return row


def _pair(r: dict, key: str, scale: float = 1e3) -> str:
    """``"wall / CPU"`` of quantity ``key`` (ms by default)."""
    return f"{_common.fmt(r[key] * scale)} / {_common.fmt(r[key + '_cpu'] * scale)}"


def _ratio(r: dict, ours: str, key: str) -> str:
    return (f"{_common.fmt(r[ours] / r[key])} / "
            f"{_common.fmt(r[ours + '_cpu'] / r[key + '_cpu'])}")


def _met(r: dict, ours: str, target: float, o3d) -> str:
    if o3d is None:
        return "-"
    if r["o3d_lost"] > 0:
        return (f"not judged: Open3D lost every match in {100 * r['o3d_lost']:.0f} % of its runs "
                "(degenerate reference)")
    return (f"wall: {_common.verdict(r[ours] / r['o3d_call'], target)}; CPU: "
            f"{_common.verdict(r[ours + '_cpu'] / r['o3d_call_cpu'], target)}")


def report(rows: list[dict], args, o3d) -> list[str]:
    main = [[
        r["object"], r["points"], f"{args.fits} x {r['timing'].n}",
        f"{r['iterations']:.1f} / {r['iterations_b1']:.1f}",
        f"{_common.fmt(r['error'] * 1e3)} / {_common.fmt(r['error_b1'] * 1e3)}",
        r["timing"].spread(1e3), *(_pair(r, k) for k in QUANTITIES),
        f"{r['query_points']:.0f}",
        f"{_common.fmt(r['o3d_fitness'])} / {100 * r['o3d_lost']:.0f} %",
    ] for r in rows]
    table1 = _common.markdown_table(
        ["object", "points", "fits x repeats", "ISF iterations per fit (lockstep / batch of 1)",
         "mean fit error (mm; lockstep / batch of 1)",
         "ours, lockstep: ms per ISF iteration, wall, median (min-max)",
         "ours, lockstep (ms, wall / CPU)",
         "ours, batch of 1 (ms, wall / CPU)",
         "nearest, same points, stacked over the fits, per fit (ms, wall / CPU)",
         "nearest, same points, one fit per call (ms, wall / CPU)",
         "nearest, 512 pts (ms, wall / CPU)", "match(), 512 pts (ms, wall / CPU)",
         "contact_kinematics, 512 pts (ms, wall / CPU)",
         "Open3D ICP call, max_iteration=1, 512 pts (ms, wall / CPU)",
         "Open3D marginal ICP iteration (ms, wall / CPU)",
         "mean query points per ISF iteration",
         "Open3D after 11 iterations: fitness / runs that lost all matches"], main)
    target = _common.TARGETS["iteration_vs_open3d"]
    ratios = []
    for ours, label, floor in (("ours", "lockstep", "nearest_stacked"),
                               ("ours_b1", "batch of 1", "nearest_same")):
        ratios += [[
            r["object"], label, _ratio(r, ours, floor), _ratio(r, ours, "nearest"),
            _ratio(r, ours, "o3d_call"), _ratio(r, ours, "o3d_marginal"), f"<= {target:g}",
            _met(r, ours, target, o3d),
        ] for r in rows]
    table2 = _common.markdown_table(
        ["object", "engine", "ours / nearest on the same points (lockstep: stacked) (wall / CPU)",
         "ours / nearest, 512 pts (wall / CPU)",
         "ours / Open3D ICP call, max_iteration=1 (wall / CPU)",
         "ours / Open3D marginal iteration (wall / CPU)", "target (vs the max_iteration=1 call)",
         "met?"], ratios)
    notes = (
        f"Gripper `{GRIPPER}` ({args.fits} fits per repeat from uniform-sampler starts, seed 0, "
        "default `FitConfig`). Ours, lockstep = wall (CPU) time of one `isf.fit_many` over all "
        "starts / the sum of `FitResult.iterations`; ours, batch of 1 = sum of `FitResult.time` "
        "(process CPU time around the `isf.fit` calls) / the sum of iterations. Nearest on the "
        "same points: `ObjectSurface.nearest` on each pyramid level's contact points at the "
        "fitted poses, weighted by the share of ISF iterations on that level (mean query "
        "size in the table); for the lockstep engine all fits' points in one call, divided by "
        f"the number of fits. Micro-benchmarks: median of {args.calls} calls per repeat "
        f"(stacked queries: {max(args.calls // 8, 5)}; Open3D marginal: "
        f"{max(args.calls // 2, 5)} calls of {1 + MARGINAL_EXTRA} iterations minus the "
        "1-iteration call, / 10), then the median over repeats. Open3D "
        f"{o3d.__version__ if o3d else '(not installed: columns empty)'}, "
        f"max correspondence distance {ICP_DISTANCE * 1e3:g} mm; when its runs lose all "
        "matches (a degenerate point-to-plane problem, e.g. along a cylinder's axis) its "
        "iterations are not representative work. The paper reports no per-iteration time "
        f"(only {_common.PAPER['t_total_60']} s per 60 samples in Matlab)."
    )
    return ["### Per ISF iteration vs. its floors", notes, table1, table2]


def main() -> None:
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=5, budget=0)
    parser.add_argument("--fits", type=int, default=32,
                        help="starts fitted per repeat, all in one fit_many (default 32)")
    parser.add_argument("--calls", type=int, default=200,
                        help="timed calls per micro-benchmark and repeat (default 200)")
    args = parser.parse_args()
    if args.quick:
        args.fits, args.calls = min(args.fits, 8), min(args.calls, 30)
        args.repeats = min(args.repeats, 2)
    started = time.perf_counter()
    header = _common.machine_description()
    o3d = _common.import_open3d()
    if o3d is None:
        print("# open3d is not installed: the Open3D columns stay empty "
              "(pip install open3d libusb-package)")
    deadline = _common.Deadline(args.deadline)
    gripper = isf.load_gripper(GRIPPER)
    rows = [bench_object(gripper, obj, args, o3d) for obj in load_objects(args.quick)
            if deadline.allows(f"object {obj.name}")]
    _common.finish("bench_iteration: cost of one ISF iteration",
                   report(rows, args, o3d) + deadline.note(), started, header, args.out)


if __name__ == "__main__":
    main()
