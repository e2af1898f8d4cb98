"""A URDF read by yourdfpy without its log: what ``isf show``, ``isf export`` and the
simulation of ``isf validate`` build their link geometry from.

yourdfpy logs an error for every element it does not know (the ``isf:*`` tags) and for a vendor
file's undeclared XML prefixes (the Robotiq 2F-85 URDF's ``drake:`` elements), and then reads
the file another way that succeeds; isf reads those tags itself
(:mod:`isf.gripper.urdf_tags`), so the messages are noise. :func:`read_urdf` silences the
``yourdfpy`` logger while it reads and restores its level after.
"""

from __future__ import annotations

import logging
from pathlib import Path

__all__ = ["read_urdf"]

_LOGGER = "yourdfpy"


def read_urdf(path: str | Path, **options):
    """``yourdfpy.URDF.load(path, **options)`` with the ``yourdfpy`` logger silenced meanwhile.

    Raises:
        whatever yourdfpy raises on a file it cannot read.
    """
    import yourdfpy

    logger = logging.getLogger(_LOGGER)
    level = logger.level
    logger.setLevel(logging.CRITICAL + 1)
    try:
        return yourdfpy.URDF.load(str(path), **options)
    finally:
        logger.setLevel(level)
