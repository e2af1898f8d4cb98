"""Registering a stock gripper URDF (``isf tag``): suggest its contact surfaces and approach,
write a tagged copy and show what every tag selects.

``spec`` holds :class:`ContactSpec` (one ``<isf:contact>`` to write), ``suggestion`` proposes
contacts and the approach from the kinematic tree and the fingertip geometry, ``urdf_editing``
writes the copy (:func:`tag_urdf`) and ``preview`` describes the result (:class:`TagPreview`).
"""

from ..exceptions import RegistrationError
from .preview import EXPORT_FORMATS, SurfacePreview, TagPreview, check_export_path
from .spec import ContactSpec
from .suggestion import (
    SuggestedTCP,
    suggest_approach,
    suggest_closing,
    suggest_contacts,
    suggest_tcp,
)
from .urdf_editing import tag_urdf

__all__ = [
    "ContactSpec",
    "EXPORT_FORMATS",
    "RegistrationError",
    "SuggestedTCP",
    "SurfacePreview",
    "TagPreview",
    "check_export_path",
    "suggest_approach",
    "suggest_closing",
    "suggest_contacts",
    "suggest_tcp",
    "tag_urdf",
]
