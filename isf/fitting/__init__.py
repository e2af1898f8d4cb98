"""Iterative surface fitting (paper Algorithms 1 and 2): :func:`fit`, :func:`fit_many` and the engine.

:class:`~isf.fitting.engine.LockstepFitter` runs any number of fits together; its rounds are
compiled (:mod:`isf.fitting.engine_kernel`): correspondences (:mod:`isf.fitting.correspondence`),
IPFO on per-link moments (:mod:`isf.fitting.moment_kernels`, ``_ipfo_kernel``) with the finger
step's bounded QP (``_finger_step``, ``_box_qp``) and the stop rule.
"""

from .engine import LockstepFitter
from .fit import fit, fit_many

__all__ = ["LockstepFitter", "fit", "fit_many"]
