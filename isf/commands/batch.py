"""``isf batch``: many plans from a manifest, on Dask, resumable, into a Parquet dataset."""

from __future__ import annotations

import argparse
import logging
import sys

EXIT_OK, EXIT_SOME_FAILED = 0, 1


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("batch", help="run the plans of a manifest on Dask into a dataset",
                              description=(
        "Run every task of MANIFEST (YAML or CSV: gripper, object or scene, parameters; or a "
        "cross product of objects x grippers x seeds; docs/batch.md) on a Dask cluster and write "
        "a Parquet dataset into DIR: one row per grasp (DIR/grasps), one per task "
        "(DIR/tasks.parquet), and each task's plan file (DIR/plans). A failing task is recorded "
        "with its error and the others go on. Rerun on the same DIR, it skips the finished "
        "tasks and runs the others once. Exit code 1 when some task failed."))
    p.add_argument("manifest", help="the tasks: a .yaml/.yml or .csv file")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="processes of the local Dask cluster, one thread each (default: the cores)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run on this running Dask scheduler (e.g. tcp://host:8786) instead of a "
                        "local cluster; 'synchronous': in this process, one task after another")
    p.add_argument("--retries", type=int, default=1, metavar="N",
                   help="times a task is run again when its worker process dies (default 1)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress and no summary")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..exceptions import InvalidInputError

    try:
        from ..batch import run_batch
    except ImportError as err:  # pyarrow or pandas missing
        raise InvalidInputError(f"isf batch needs {err.name}: pip install 'dask[distributed]' "
                                "pyarrow pandas") from None

    if not args.verbose:  # Dask logs every worker's start and stop at INFO
        logging.getLogger("distributed").setLevel(logging.ERROR)
    summary = run_batch(args.manifest, args.out, workers=args.workers, scheduler=args.scheduler,
                        retries=args.retries, progress=None if args.quiet else sys.stderr)
    if not args.quiet:
        print(summary.format())
    return EXIT_OK if summary.ok else EXIT_SOME_FAILED
