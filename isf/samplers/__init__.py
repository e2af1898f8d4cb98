"""Initial-pose samplers: the contract, the registry and the built-in samplers.

Samplers are found by name through the ``isf.samplers`` entry-point group
(built-ins included); see ``docs/samplers.md`` for writing a plugin.
"""

from ..exports import lazy_exports

_SOURCES = {  # each public name -> the module of this package that defines it (loaded on use)
    "ENTRY_POINT_GROUP": "registry",
    "ORIENTATIONS": "orientation",
    "NO_CONTACT_ERROR": "base",
    "Outcome": "base",
    "Proposal": "base",
    "RegretSampler": "regret",
    "Sampler": "base",
    "SamplerInfo": "registry",
    "UniformSampler": "uniform",
    "available_samplers": "registry",
    "flag_parameter": "base",
    "get_sampler": "registry",
    "grasp_centre": "base",
    "integer_parameter": "base",
    "number_parameter": "base",
    "place_gripper": "base",
    "random_rotation": "base",
    "refresh_samplers": "registry",
    "register_sampler": "registry",
}

__all__ = sorted(_SOURCES)  # noqa: PLE0605 (computed: the keys above)
__getattr__, __dir__ = lazy_exports(__name__, _SOURCES)
