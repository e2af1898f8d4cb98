"""Objects: an object's surface as points with outward normals, loaded from a mesh, a cloud or
a spec.

:class:`ObjectSurface` (module :mod:`isf.object.surface`); :func:`load_object` reads meshes and
point clouds (:mod:`isf.object.loading`, with the readers, mesh sampling and cloud normals);
:func:`open_object` also takes ``shape:NAME`` and ``asset:NAME`` specs (:mod:`isf.object.specs`).
"""

from .loading import load_object
from .specs import open_object
from .surface import ObjectSurface

__all__ = ["ObjectSurface", "load_object", "open_object"]
