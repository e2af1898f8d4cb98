"""The sampler contract: :class:`Sampler`, :class:`Proposal`, :class:`Outcome`, and pose helpers.

A sampler proposes initial gripper poses for ISF (paper Alg. 3, "guided
sampling") and may learn from how those proposals turned out. The planner
drives every sampler the same way::

    sampler.reset(obj, gripper, rng)              # once per plan
    while budget_left:
        proposals = sampler.propose(n, rng)       # n initial poses
        outcomes = [fit(p) for p in proposals]    # the planner runs ISF
        sampler.observe(outcomes)                 # optional feedback

Parameters go to the constructor (keyword-only, validated there, raising
:class:`~isf.exceptions.ConfigError`); the object, the gripper and the random
generator arrive at call time. A sampler draws randomness only from the
``rng`` it is handed, never from NumPy's or Python's global state, so a plan
is reproducible from its seed.

Frames: ``T_object_gripper`` is the pose of the gripper frame (the URDF root
link) in the object frame, shape (4, 4), metres.
"""

from __future__ import annotations

import abc
import math
import weakref
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from ..exceptions import ConfigError

if TYPE_CHECKING:
    from ..gripper.model import Gripper
    from ..object.surface import ObjectSurface

__all__ = [
    "NO_CONTACT_ERROR",
    "Outcome",
    "Proposal",
    "Sampler",
    "flag_parameter",
    "grasp_centre",
    "integer_parameter",
    "number_parameter",
    "place_gripper",
    "random_rotation",
]


def _frozen_array(value: Any, dtype: type = float) -> np.ndarray:
    """A read-only float copy of ``value``."""
    arr = np.array(value, dtype=dtype, copy=True)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Proposal:
    """One initial grasp proposed by a sampler.

    The arrays are stored as read-only copies; copy them before editing.

    Attributes:
        T_object_gripper: initial pose of the gripper frame in the object
            frame, shape (4, 4), metres.
        q: initial joint vector, shape (n_joints,), metres or radians; None
            means ``gripper.q_initial``.
        record: JSON-serialisable notes the sampler wants back in
            :meth:`Sampler.observe` and in the planner's results, e.g.
            ``{"cluster": 3}``.
    """

    T_object_gripper: np.ndarray
    q: np.ndarray | None = None
    record: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        T = _frozen_array(self.T_object_gripper)
        if T.shape != (4, 4):
            raise ValueError(f"T_object_gripper must have shape (4, 4), got {T.shape}")
        object.__setattr__(self, "T_object_gripper", T)
        if self.q is not None:
            q = _frozen_array(self.q)
            if q.ndim != 1:
                raise ValueError(f"q must be a 1-D joint vector, got shape {q.shape}")
            object.__setattr__(self, "q", q)
        object.__setattr__(self, "record", dict(self.record))


NO_CONTACT_ERROR = 0.05
"""The :attr:`Outcome.error` the planner reports for a fit where some contact surface does not
touch the object (or, on a scene, the contact surfaces rest on several pieces of it), in place
of its mean distance, metres (a fit that touches reports a few millimetres)."""


@dataclass(frozen=True, eq=False)
class Outcome:
    """What became of one :class:`Proposal` after ISF and the collision check.

    Attributes:
        proposal: the proposal that was fitted.
        error: fitting error of the ISF result (mean point-to-plane distance), metres, lower
            is better; ``NO_CONTACT_ERROR`` when some contact surface does not touch the
            object (on a scene: when the contact surfaces rest on several pieces of it);
            ``inf`` for a failed fit.
        collision_free: True when the fitted gripper does not penetrate the object.
        valid: True when the fitted grasp is one the planner counts as valid
            (:attr:`isf.Grasp.valid`: collision-free, every contact surface touching the
            object and, on a scene, resting on one piece of it). The planner sets it; left
            None (``Outcome(proposal, error, collision_free)``), it is inferred as
            ``collision_free and error < NO_CONTACT_ERROR``. Always a bool once built.
        holds: for a sampler whose :meth:`Sampler.hears_quality` is true, in a plan ranked by
            quality: whether the ranking expects the grasp to hold
            (:func:`isf.quality.grasp_quality.expected_to_hold`), for a valid grasp; None for
            an invalid grasp and whenever the planner did not compute it.

    Raises:
        ValueError: ``error`` is NaN, or ``valid`` is True for a grasp that is not
            collision-free.
    """

    proposal: Proposal
    error: float
    collision_free: bool
    valid: bool | None = None
    holds: bool | None = None

    def __post_init__(self) -> None:
        error = float(self.error)
        if math.isnan(error):
            raise ValueError("Outcome.error is NaN; report a failed fit as float('inf')")
        collision_free = bool(self.collision_free)
        valid = collision_free and error < NO_CONTACT_ERROR if self.valid is None \
            else bool(self.valid)
        if valid and not collision_free:
            raise ValueError("Outcome.valid is True but collision_free is False; a valid grasp "
                             "is collision-free")
        if self.holds is not None and not valid:
            raise ValueError("Outcome.holds is set for a grasp that is not valid; leave it None")
        object.__setattr__(self, "error", error)
        object.__setattr__(self, "collision_free", collision_free)
        object.__setattr__(self, "valid", valid)
        object.__setattr__(self, "holds", None if self.holds is None else bool(self.holds))


class Sampler(abc.ABC):
    """Base class of every initial-pose sampler (built-in or plugin).

    Subclasses set the class attributes :attr:`name` (the entry-point name,
    ``[a-z0-9_]+``) and :attr:`description` (one line), take their parameters
    as keyword-only constructor arguments, and implement :meth:`propose`.
    Override :meth:`reset` to precompute per-object state (call
    ``super().reset(...)`` to keep :attr:`obj` and :attr:`gripper`), and
    :meth:`observe` to learn from outcomes. Check a new sampler with
    :func:`isf.testing.check_sampler`.

    Attributes:
        obj: the object of the current plan (set by :meth:`reset`).
        gripper: the gripper of the current plan (set by :meth:`reset`).
    """

    #: The public name, ``[a-z0-9_]+``, equal to the entry-point name.
    name: ClassVar[str] = ""
    #: One line, shown by ``isf samplers``.
    description: ClassVar[str] = ""

    obj: ObjectSurface | None = None
    gripper: Gripper | None = None

    def reset(self, obj: ObjectSurface, gripper: Gripper, rng: np.random.Generator) -> None:
        """Start a new plan: forget earlier outcomes and precompute what the object needs.

        Args:
            obj: object surface, object frame, metres.
            gripper: the gripper to place.
            rng: the plan's random generator; the only source of randomness.
        """
        self.obj = obj
        self.gripper = gripper

    @abc.abstractmethod
    def propose(self, n: int, rng: np.random.Generator) -> list[Proposal]:
        """Propose ``n`` initial grasps.

        Args:
            n: number of proposals, >= 1.
            rng: the plan's random generator; the only source of randomness.

        Returns:
            exactly ``n`` proposals.

        Raises:
            RuntimeError: when called before :meth:`reset`.
        """

    def observe(self, outcomes: Sequence[Outcome]) -> None:  # noqa: B027 (optional hook)
        """Learn from fitted proposals; the default ignores them.

        Args:
            outcomes: results for proposals this sampler made since :meth:`reset`.
        """

    def in_flight_limit(self) -> int | None:
        """How many proposals this sampler wants awaiting outcomes at once right now.

        A planner fitting several samples at once (:func:`isf.plan` with ``batch_size > 1``)
        asks before each proposal and waits for outcomes while this many are in flight.
        None (the default) sets no limit; a sampler that needs feedback before it can
        propose well (e.g. while exploring) returns a small number, at least 1.
        """
        return None

    def hears_quality(self) -> bool:
        """Whether this sampler wants :attr:`Outcome.holds`, the quality ranking's verdict on
        each valid grasp. When true, a plan ranked by quality computes each valid grasp's
        quality as its outcome arrives instead of all at the end (the same records, one grasp
        at a time). False (the default) leaves ``holds`` None."""
        return False

    def _require_reset(self) -> tuple[ObjectSurface, Gripper]:
        """The current object and gripper, or a RuntimeError when :meth:`reset` was not called."""
        if self.obj is None or self.gripper is None:
            raise RuntimeError(
                f"{type(self).__name__}: call reset(obj, gripper, rng) before propose()/observe()"
            )
        return self.obj, self.gripper

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


def random_rotation(rng: np.random.Generator, size: int | None = None) -> np.ndarray:
    """Rotation matrices drawn uniformly (Haar measure) from SO(3).

    A unit quaternion with i.i.d. normal components is uniform on the 3-sphere,
    hence its rotation is uniform on SO(3).

    Args:
        rng: random generator.
        size: number of rotations, or None for a single one.

    Returns:
        proper rotation(s), shape (3, 3), or (size, 3, 3) when ``size`` is given.
    """
    quat = rng.standard_normal((1 if size is None else size, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    w, x, y, z = quat.T
    R = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )
    return R[0] if size is None else R


def grasp_centre(gripper: Gripper) -> np.ndarray:
    """Mean of the gripper's contact points at ``q_initial``, gripper frame (computed once per
    gripper).

    Returns:
        the grasp centre, shape (3,), metres (a read-only array).
    """
    centre = _GRASP_CENTRES.get(gripper)
    if centre is None:
        points, _ = gripper.contact_points(gripper.q_initial)
        centre = _GRASP_CENTRES[gripper] = points.mean(axis=0)
        centre.flags.writeable = False
    return centre


_GRASP_CENTRES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
""":func:`grasp_centre` of each gripper object alive."""


def flag_parameter(value: Any, sampler: str, key: str) -> bool:
    """A sampler's yes/no parameter: a bool, 0 or 1, or the text ``true``/``false`` (any case),
    as ``isf plan --sampler-param KEY=VALUE`` passes it.

    Raises:
        ConfigError: any other value, in one line naming ``sampler`` and ``key``.
    """
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)) and value in (0, 1):
        return bool(value)
    if isinstance(value, str) and value.lower() in ("true", "false"):
        return value.lower() == "true"
    raise ConfigError(f"{sampler}: {key} must be true or false, got {value!r}")


def integer_parameter(value: Any, sampler: str, key: str, low: int) -> int:
    """A sampler's whole-number parameter, at least ``low``.

    Raises:
        ConfigError: a bool, a non-integer or a value below ``low``, in one line naming
            ``sampler`` and ``key``.
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or value < low:
        raise ConfigError(f"{sampler}: {key} must be an integer >= {low}, got {value!r}")
    return int(value)


def number_parameter(value: Any, sampler: str, key: str, low: float = 0.0,
                     below: float | None = None) -> float:
    """A sampler's real-number parameter: finite, at least ``low`` and, when ``below`` is given,
    less than it.

    Raises:
        ConfigError: a bool, a non-number, a NaN or infinity, or a value out of range, in one
            line naming ``sampler``, ``key`` and the range.
    """
    number = isinstance(value, (int, float, np.integer, np.floating)) \
        and not isinstance(value, (bool, np.bool_))
    if not number or not np.isfinite(value) or value < low \
            or (below is not None and value >= below):
        allowed = f"a finite number >= {low:g}" if below is None else f"a number in [{low:g}, {below:g})"
        raise ConfigError(f"{sampler}: {key} must be {allowed}, got {value!r}")
    return float(value)


def place_gripper(
    gripper: Gripper, centre_object: np.ndarray, R_object_gripper: np.ndarray
) -> np.ndarray:
    """Gripper pose that puts its grasp centre at a point of the object frame.

    Solves ``R @ c + p = centre_object`` for the translation ``p``, with ``c``
    the :func:`grasp_centre`.

    Args:
        gripper: the gripper.
        centre_object: where the grasp centre goes, object frame, shape (3,)
            or (n, 3), metres.
        R_object_gripper: gripper orientation in the object frame, shape
            (3, 3) or (n, 3, 3).

    Returns:
        ``T_object_gripper``, shape (4, 4), or (n, 4, 4) for batched input.
    """
    R = np.asarray(R_object_gripper, dtype=float)
    centre = np.asarray(centre_object, dtype=float)
    batched = R.ndim == 3 or centre.ndim == 2
    R = np.broadcast_to(R, np.broadcast_shapes(R.shape[:-2], centre.shape[:-1]) + (3, 3))
    centre = np.broadcast_to(centre, R.shape[:-1])
    T = np.zeros(R.shape[:-2] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = centre - R @ grasp_centre(gripper)
    T[..., 3, 3] = 1.0
    return T if batched else T.reshape(4, 4)
