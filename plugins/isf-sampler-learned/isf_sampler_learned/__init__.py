"""isf sampler plugin ``learned``: starts ranked by a model trained on earlier ISF outcomes.

Registered through the ``isf.samplers`` entry point (see ``pyproject.toml``); isf never
imports this package directly. Use it as ``isf.samplers.get_sampler("learned")`` or
``isf plan --sampler learned [--sampler-param model=FILE]``; train a model with
``python -m isf_sampler_learned train``.
"""

from __future__ import annotations

from .features import FEATURE_VERSION, gripper_sha256
from .model import LearnedModel, ModelFileError, load_model
from .sampler import LearnedSampler, NoModelWarning

__all__ = [
    "FEATURE_VERSION",
    "LearnedModel",
    "LearnedSampler",
    "ModelFileError",
    "NoModelWarning",
    "__version__",
    "gripper_sha256",
    "load_model",
]

__version__ = "0.1.0"
