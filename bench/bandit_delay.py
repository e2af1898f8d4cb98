"""Does planning several samples at once cost the regret bandit grasps? Paired collision-free counts.

With ``batch_size=B`` (lockstep) or ``workers=W`` (threads) the regret sampler hears each outcome
up to B - 1 (2W - 1) samples late. This script runs the Table I set (``bench/table1.py``'s
objects, gripper, sampler and paper settings: random orientations, no repair) for every seed in
``--seeds`` in each mode of ``--modes`` (a batch size, or ``wN`` for N worker threads) and
prints, per object, the mean collision-free count and mean fitting error per mode and the mean
paired difference to the last mode (the reference, 1 by default), with its standard error over
all (object, seed) pairs. The counts are deterministic
for a seed, so the machine's load does not matter (the times are not reported).

Run from the repository root:
    python bench/bandit_delay.py [--seeds 6] [--modes 8,w2,1] [--objects bunny,duck]
"""

from __future__ import annotations

import _common

import statistics
import time

import isf
from table1 import DEFAULT_OBJECTS, GRIPPER, MAX_POINTS, paper_sampler


def main() -> None:
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=1, budget=0.0)
    parser.add_argument("--seeds", type=int, default=6, help="seeds 0..N-1 (default 6)")
    parser.add_argument("--modes", default="8,w2,1",
                        help="comma-separated modes: a batch size or wN (N worker threads); the "
                             "last is the reference (default 8,w2,1)")
    parser.add_argument("--objects", default=",".join(DEFAULT_OBJECTS))
    args = parser.parse_args()
    try:
        sizes = [_common.Mode.parse(m) for m in args.modes.split(",")]
    except ValueError as err:
        parser.error(f"--modes: {err}")
    _common.use_cpus(max(m.workers for m in sizes))
    names = args.objects.split(",")
    seeds = 1 if args.quick else args.seeds
    started, header = time.perf_counter(), _common.machine_description()
    gripper = isf.load_gripper(GRIPPER)
    counts: dict[tuple[str, int, _common.Mode], tuple[int, float]] = {}
    for name in names:
        obj, _ = _common.scaled_benchmark_object(name, max_points=MAX_POINTS)
        for seed in range(seeds):
            for b in sizes:
                row = _common.plan_once(gripper, obj, 60, seed, batch_size=b.batch_size,
                                        workers=b.workers, sampler=paper_sampler(),
                                        repair_collisions=False)
                counts[(name, seed, b)] = (row["free"], row["error"])
            print(f"# {name} seed {seed}: " + ", ".join(
                f"{b.label} {counts[(name, seed, b)][0]:g}" for b in sizes), flush=True)
    ref = sizes[-1]
    rows, pairs = [], {b: [] for b in sizes[:-1]}
    for name in names:
        cells = [name, f"0-{seeds - 1}"]
        for b in sizes:
            cells.append(f"{statistics.fmean(counts[(name, s, b)][0] for s in range(seeds)):.1f}")
        for b in sizes[:-1]:
            diff = [counts[(name, s, b)][0] - counts[(name, s, ref)][0] for s in range(seeds)]
            pairs[b] += diff
            cells.append(f"{statistics.fmean(diff):+.1f}")
        for b in sizes:
            cells.append(_common.fmt(1e3 * statistics.fmean(counts[(name, s, b)][1]
                                                         for s in range(seeds))))
        rows.append(cells)
    total = ["**all pairs**", f"{len(names) * seeds} runs per size"] + [""] * len(sizes)
    for b in sizes[:-1]:
        total.append(f"**{_common.mean_and_error(pairs[b])}**")
    rows.append(total + [""] * len(sizes))
    table = _common.markdown_table(
        ["object", "seeds"] + [f"collision-free, {b.label}" for b in sizes]
        + [f"{b.label} - {ref.label} (mean; all pairs: +- standard error)" for b in sizes[:-1]]
        + [f"mean fit error (mm), {b.label}" for b in sizes], rows)
    note = (f"Gripper `{GRIPPER}`, 60 samples, regret sampler with random orientations and "
            f"no starts at the centre of mass, no repair, objects as in bench/table1.py; "
            f"seeds 0..{seeds - 1}; reference {ref.label} (B: samples in lockstep in one thread, W: worker threads).")
    _common.finish("bandit_delay: collision-free grasps vs delayed feedback, paired by seed",
                   ["### Collision-free grasps vs. batch size and worker threads", note, table], started, header,
                   args.out)


if __name__ == "__main__":
    main()
