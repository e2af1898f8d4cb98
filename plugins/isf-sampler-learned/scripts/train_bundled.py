"""Train the models shipped in ``isf_sampler_learned/models/``, one per gripper.

Grippers: the bundled ``paper-parallel``, ``flat-parallel`` and ``three-finger``, and the
Franka hand (``isf.assets.vendor_gripper("franka-hand")``) tagged by ``isf tag`` with its
suggested contacts and approach, as a user tags it (so the same command gives a gripper with
the same sha256, which finds the model).

Training objects (:data:`TRAIN_OBJECTS`): the built-in shapes, the pybullet and robosuite
benchmark meshes and ten pybullet random objects (``isf.assets``, fetched from pinned wheels),
and five YCB objects from ``../shared/data/ycb`` (or ``$ISF_YCB_DIR``; left out with a note
when absent). ``bench/bench_learned.py`` tests on other objects. Nothing here is committed
but the model files.

Run from the repository root (about 5 minutes per gripper on one core):
    python plugins/isf-sampler-learned/scripts/train_bundled.py [--gripper NAME] [--seed 0]
        [--cache DIR]

``--cache DIR`` keeps each gripper's examples in ``DIR`` (and reuses them when present), so
the models can be refitted without planning again.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import warnings
from pathlib import Path

import isf
from isf_sampler_learned.bundled import MODELS_DIR, tagged_franka_hand
from isf_sampler_learned.training import Examples, collect_examples, train

GRIPPERS = ("paper-parallel", "flat-parallel", "three-finger", "franka-hand")
TRAIN_SHAPES = ("shape:cylinder", "shape:box", "shape:sphere", "shape:capsule", "shape:torus")
TRAIN_ASSETS = tuple(f"asset:{name}" for name in (
    "duck", "mug", "bunny", "bottle", "bread", "can", "cereal", "lemon", "milk",
    *(f"random-{k:03d}" for k in range(10))))
TRAIN_YCB = tuple(f"asset:ycb:{name}" for name in (
    "Banana", "CrackerBox", "MasterChefCan", "MustardBottle", "PowerDrill"))
TRAIN_OBJECTS = TRAIN_SHAPES + TRAIN_ASSETS + TRAIN_YCB
"""Every object a bundled model may have seen (the benchmark must use others)."""


def training_objects() -> list[str]:
    """:data:`TRAIN_OBJECTS` without the YCB ones when their folder is absent."""
    ycb = Path(os.environ.get("ISF_YCB_DIR", Path(__file__).parents[3] / ".." / "shared" /
                              "data" / "ycb"))
    if ycb.is_dir():
        return list(TRAIN_OBJECTS)
    print(f"no YCB folder at {ycb}: training without the YCB objects")
    return list(TRAIN_SHAPES + TRAIN_ASSETS)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gripper", action="append", choices=GRIPPERS,
                        help="train this gripper only (repeatable; default all)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--samples", type=int, default=60)
    parser.add_argument("--cache", type=Path, help="folder to keep and reuse the examples in")
    args = parser.parse_args()
    objects = training_objects()
    warnings.simplefilter("ignore")  # objects far larger than a jaw's opening are expected
    with tempfile.TemporaryDirectory() as folder:
        for name in args.gripper or GRIPPERS:
            gripper = (tagged_franka_hand(Path(folder)) if name == "franka-hand"
                       else isf.load_gripper(name))
            cached = (None if args.cache is None else
                      args.cache / f"{name}-{len(objects)}-objects-seed{args.seed}-"
                      f"samples{args.samples}.npz")
            progress = lambda line, name=name: print(name, line, flush=True)  # noqa: E731
            if cached is not None and cached.exists():
                examples = Examples.load(cached)
            else:
                examples = collect_examples(gripper, objects, samples=args.samples,
                                            seed=args.seed, progress=progress)
                if cached is not None:
                    examples.save(cached)
            model, held = train(gripper, objects, samples=args.samples, seed=args.seed,
                                examples=examples)
            path = model.save(MODELS_DIR / f"{name}.npz")
            print(f"{name}: held-out {held}; wrote {path}", flush=True)


if __name__ == "__main__":
    main()
