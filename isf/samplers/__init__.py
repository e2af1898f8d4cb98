"""Initial-pose samplers: the contract, the registry and the built-in samplers.

Samplers are found by name through the ``isf.samplers`` entry-point group
(built-ins included); see ``docs/samplers.md`` for writing a plugin.
"""

from .base import Outcome, Proposal, Sampler, grasp_centre, place_gripper, random_rotation
from .orientation import ORIENTATIONS
from .registry import (
    ENTRY_POINT_GROUP,
    SamplerInfo,
    available_samplers,
    get_sampler,
    refresh_samplers,
    register_sampler,
)
from .regret import RegretSampler
from .uniform import UniformSampler

__all__ = [
    "ENTRY_POINT_GROUP",
    "ORIENTATIONS",
    "Outcome",
    "Proposal",
    "RegretSampler",
    "Sampler",
    "SamplerInfo",
    "UniformSampler",
    "available_samplers",
    "get_sampler",
    "grasp_centre",
    "place_gripper",
    "random_rotation",
    "refresh_samplers",
    "register_sampler",
]
