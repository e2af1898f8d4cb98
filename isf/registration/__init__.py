"""Registering a stock gripper URDF: tag its contact surfaces in a copy and show the selection (``isf tag``).
"""

from .tagging import ContactSpec, RegistrationError, SurfacePreview, TagPreview, suggest_approach, suggest_contacts, tag_urdf

__all__ = ["ContactSpec", "RegistrationError", "SurfacePreview", "TagPreview", "suggest_approach", "suggest_contacts", "tag_urdf"]
