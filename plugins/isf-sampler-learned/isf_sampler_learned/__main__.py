"""``python -m isf_sampler_learned train``: train a model for a gripper from isf's own plans.

    python -m isf_sampler_learned train --gripper G --objects SPEC [SPEC ...] --out model.npz
        [--samples 60] [--seed 0] [--samplers uniform,regret] [--holdout 4]

``G`` is a bundled gripper name or a tagged URDF; each ``SPEC`` is what ``isf plan --object``
takes (a file, ``shape:NAME`` or ``asset:NAME``). Prints one line per plan, the held-out
accuracy, and the file written. Exit codes: 0 done, 2 a user error (one line on stderr).
"""

from __future__ import annotations

import argparse
import sys

from isf.exceptions import ISFError

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    parser = argparse.ArgumentParser(prog="python -m isf_sampler_learned")
    commands = parser.add_subparsers(dest="command", required=True)
    p = commands.add_parser("train", help="train a sampler model for a gripper")
    p.add_argument("--gripper", required=True, help="bundled gripper name or tagged URDF")
    p.add_argument("--objects", required=True, nargs="+", help="object specs (as isf plan)")
    p.add_argument("--out", required=True, help="model file to write (.npz)")
    p.add_argument("--samples", type=int, default=60, help="samples per plan (default 60)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first plan (default 0)")
    p.add_argument("--samplers", default="uniform,regret",
                   help="comma-separated samplers that propose the starts (default uniform,regret)")
    p.add_argument("--holdout", type=int, default=4,
                   help="every N-th object is held out to measure accuracy (default 4)")
    p.add_argument("--package-dir", action="append", default=[], metavar="PACKAGE=FOLDER",
                   help="folder of a package:// URI in the gripper's URDF (repeatable)")
    args = parser.parse_args(argv)
    try:
        return _train(args)
    except ISFError as err:
        print(f"{parser.prog}: error: {err}", file=sys.stderr)
        return 2


def _train(args: argparse.Namespace) -> int:
    import isf
    from isf.exceptions import InvalidInputError

    from .training import train

    if args.samples < 1 or args.holdout < 2:
        raise InvalidInputError("--samples must be >= 1 and --holdout >= 2")
    package_dirs = dict(item.split("=", 1) for item in args.package_dir if "=" in item)
    gripper = isf.load_gripper(args.gripper, **({"package_dirs": package_dirs}
                                                 if package_dirs else {}))
    samplers = [s for s in args.samplers.split(",") if s]
    model, held = train(gripper, args.objects, samplers=samplers, samples=args.samples,
                        seed=args.seed, holdout=args.holdout, progress=print)
    if held is None:
        print("held-out accuracy: not measured (give at least --holdout objects)")
    else:
        print(f"held-out accuracy: {held.accuracy:.3f} on {held.examples} starts of unseen "
              f"objects (majority label: {held.base_rate:.3f}); valid among the model's top "
              f"10 %: {held.top_decile_valid:.3f} (all: {held.valid_rate:.3f})")
        auc = "n/a" if held.object_auc is None else f"{held.object_auc:.3f}"
        print(f"within each held-out object (mean): AUC {auc}, valid among its top 10 %: "
              f"{held.object_top_decile_valid:.3f} (all: {held.object_valid_rate:.3f})")
    path = model.save(args.out)
    print(f"wrote {path} (gripper {gripper.name}, sha256 {model.gripper_sha256[:12]}...)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
