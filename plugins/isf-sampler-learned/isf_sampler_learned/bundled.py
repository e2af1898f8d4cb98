"""The models shipped in the package (``isf_sampler_learned/models/*.npz``), found by gripper.

Each bundled file is matched to a gripper by the sha256 it records
(:func:`~isf_sampler_learned.features.gripper_sha256`), so a renamed or moved gripper file
still finds its model, and an edited one does not get a stale model.
"""

from __future__ import annotations

import functools
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .model import LearnedModel, load_model

if TYPE_CHECKING:
    from isf.gripper.model import Gripper

__all__ = ["MODELS_DIR", "bundled_model", "bundled_models", "tagged_franka_hand"]

MODELS_DIR = Path(__file__).parent / "models"


@functools.cache
def bundled_models() -> dict[str, Path]:
    """``{gripper sha256: model file}`` of the bundled models."""
    found = {}
    for path in sorted(MODELS_DIR.glob("*.npz")):
        with np.load(path, allow_pickle=False) as data:
            found[str(data["gripper_sha256"])] = path
    return found


@functools.cache
def bundled_model(gripper_sha256: str) -> LearnedModel | None:
    """The bundled model trained for the gripper with this digest, or None."""
    path = bundled_models().get(gripper_sha256)
    return None if path is None else load_model(path, gripper_sha256=gripper_sha256)


def tagged_franka_hand(folder: str | Path) -> Gripper:
    """The Franka hand the bundled ``franka-hand`` model was trained for: the vendor URDF
    (``isf.assets.vendor_gripper("franka-hand")``) tagged by ``isf tag`` with its suggested
    contacts and approach, written to ``folder/franka-hand.urdf``.

    A user who tags the hand with the same command gets the same gripper sha256, so
    ``model="auto"`` finds the model.
    """
    import isf
    from isf.assets import vendor_gripper

    out = Path(folder) / "franka-hand.urdf"
    subprocess.run([sys.executable, "-m", "isf", "tag", str(vendor_gripper("franka-hand")),
                    "--out", str(out)], check=True, capture_output=True, text=True)
    return isf.load_gripper(out)
