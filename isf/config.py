"""Parameters of one ISF fit (paper section V-A), in SI units.

Reading the paper's parameters in SI
------------------------------------
The paper gives ``L = 4``, ``I0 = 200``, ``eps0 = 0.008``, ``delta_e = 1e-5`` and
``alpha = 0.01`` without units. isf reads them as follows:

* ``alpha = 0.01`` **metres**. :math:`E = E_p + \\alpha^2 E_n` adds squared
  distances (m^2) to squared, dimensionless normal terms, so alpha is a length:
  a normal misalignment with ``(R n^p)^T n^q + 1 = 1`` costs as much as a 1 cm
  point-to-plane offset.
* ``delta_e = 1e-5`` **mm^2**, i.e. ``1e-11`` m^2, **for the paper's ~512 pairs**
  (two fingers of 256 points). Read in m^2 the threshold would be (0.14 mm)^2
  per pair and IPFO would stop after one or two alternations, while the paper's
  Fig. 5b shows IPFO running 7; read in mm^2 IPFO runs to convergence, as in
  the figure. E is a sum over pairs, so a fixed threshold would mean something
  different on every pyramid level; isf stops IPFO when E *per pair* decreases
  by less than ``delta_e / 512``.
* ``eps0 = 0.008`` is dimensionless (a relative change of the displacement,
  see :mod:`isf.fitting.fit`), ``L`` and ``I0`` are counts.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from numbers import Integral, Real

from .exceptions import ConfigError

__all__ = ["LEVELS_LIMIT", "MAX_ITERATIONS_LIMIT", "FitConfig", "check_field", "config_from_text",
           "number_or_text"]

MAX_ITERATIONS_LIMIT = 10_000
"""Largest :attr:`FitConfig.max_iterations` (50 times the paper's 200): a fit keeps a history
row per iteration, for every sample in flight."""

LEVELS_LIMIT = 16
"""Largest :attr:`FitConfig.levels`: beyond about 10 levels every surface keeps a single point."""


def check_field(owner: str, name: str, value, *, integer: bool = False, flag: bool = False,
                low: float | None = None, above: float | None = None,
                high: float | None = None) -> None:
    """Raise :class:`ConfigError` unless ``value`` is a parameter of the kind asked for.

    Args:
        owner, name: the dataclass and field, for the message (``FitConfig.levels``).
        value: the value to check.
        integer: an integer (not a bool); else a finite real number (not a bool).
        flag: a bool (the bounds are ignored).
        low: at least this; above: more than this; high: at most this.
    """
    where = f"{owner}.{name}"
    if flag:
        if not isinstance(value, bool):
            raise ConfigError(f"{where} must be True or False, got {value!r}")
        return
    bounds = [f"{sign} {bound:g}" for sign, bound in ((">=", low), (">", above), ("<=", high))
              if bound is not None]
    wanted = " ".join(["an integer" if integer else "a finite number", " and ".join(bounds)])
    kind = Integral if integer else Real
    if (isinstance(value, bool) or not isinstance(value, kind) or not math.isfinite(value)
            or (low is not None and not value >= low) or (above is not None and not value > above)
            or (high is not None and not value <= high)):
        raise ConfigError(f"{where} must be {wanted}, got {value!r}")

PAPER_PAIRS = 512
"""Pairs the paper's ``delta_e`` refers to (two fingers x 256 points)."""


@dataclass(frozen=True, kw_only=True)
class FitConfig:
    """Parameters of :func:`isf.fit` (Algorithms 1 and 2).

    Attributes:
        levels: pyramid levels ``L``; level ``l`` keeps ``1/2**l`` of each surface's points.
        max_iterations: ``I0``; level ``l`` runs at most ``I0 / 2**l`` ISF iterations.
        tolerance: ``eps0``; level ``l`` stops when the displacement ratio ``eta`` is
            within ``1 +- 2**l * eps0``. A looser one is faster but leaves more fits
            colliding (measured in docs/concepts.md).
        delta_e: ``Delta e``, m^2 for 512 pairs (the paper's 1e-5 mm^2); IPFO stops
            when E per pair drops by less than ``delta_e / 512``.
        normal_weight: ``alpha``, metres; 0 turns the normal-alignment term off.
        max_ipfo_iterations: cap on IPFO palm/finger alternations per ISF iteration.
        max_rotation_step: largest palm rotation of one palm step, radians.
        max_revolute_step: largest change of a revolute joint in one finger step, radians.
        finger_damping: Tikhonov weight added to the finger QP's Hessian (m^2 per unit^2).
        outlier_factor: a pair is an outlier when its distance exceeds this many
            times the median pair distance ...
        outlier_floor: ... and also exceeds this distance, metres.
        outlier_scope: ``"surface"``: the median is taken per contact surface (a finger whose
            tip is still far from the object is pulled in, not dropped as an outlier while the
            others touch); ``"fit"``: over all pairs of the fit, as in the paper.
        reject_duplicates: keep only the closest pair per object point (paper IV-B).
        max_normal_angle: drop pairs whose contact normal is more than this far from the
            reversed object normal, radians (not in the paper; pi turns it off).
        lock_fingers: hold the joints at their initial values (pure palm ICP).
        contact_distance: a contact point is "in contact" within this distance of
            the object, metres (used for the per-surface contact fractions).
        min_pairs: fewer matched pairs than this ends the fit as ``lost_contact``.
    """

    levels: int = 4
    max_iterations: int = 200
    tolerance: float = 0.008
    delta_e: float = 1e-11
    normal_weight: float = 0.01
    max_ipfo_iterations: int = 5
    max_rotation_step: float = 0.3
    max_revolute_step: float = 0.3
    finger_damping: float = 1e-9
    outlier_factor: float = 3.0
    outlier_floor: float = 0.005
    outlier_scope: str = "surface"
    reject_duplicates: bool = True
    max_normal_angle: float = 1.5
    lock_fingers: bool = False
    contact_distance: float = 0.002
    min_pairs: int = 6

    def __post_init__(self) -> None:
        """Refuse values of the wrong type, not finite, or out of range (:class:`ConfigError`)."""
        highs = {"levels": LEVELS_LIMIT, "max_iterations": MAX_ITERATIONS_LIMIT,
                 "max_ipfo_iterations": 1000}
        for name in ("levels", "max_iterations", "max_ipfo_iterations", "min_pairs"):
            check_field("FitConfig", name, getattr(self, name), integer=True, low=1,
                        high=highs.get(name))
        for name in ("tolerance", "delta_e", "normal_weight", "finger_damping", "outlier_floor"):
            check_field("FitConfig", name, getattr(self, name), low=0.0)
        if self.outlier_scope not in ("surface", "fit"):
            raise ConfigError(
                f"FitConfig.outlier_scope must be 'surface' or 'fit', got {self.outlier_scope!r}")
        for name in ("max_rotation_step", "max_revolute_step", "outlier_factor", "contact_distance",
                     "max_normal_angle"):
            check_field("FitConfig", name, getattr(self, name), above=0.0)
        for name in ("reject_duplicates", "lock_fingers"):
            check_field("FitConfig", name, getattr(self, name), flag=True)

    @property
    def ipfo_tolerance(self) -> float:
        """IPFO stop threshold on the decrease of E per pair, m^2."""
        return self.delta_e / PAPER_PAIRS

    def to_dict(self) -> dict:
        """All parameters as a plain dict."""
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict) -> FitConfig:
        """Build from a dict, rejecting unknown keys with the list of valid ones."""
        if not isinstance(values, dict):
            raise ConfigError(f"{cls.__name__}.from_dict takes a dict, got {type(values).__name__}")
        _reject_unknown(cls, values)
        return cls(**values)


def _reject_unknown(cls: type, keys) -> None:
    """Raise ConfigError naming the keys that are not fields of dataclass ``cls``."""
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(keys) - known)
    if unknown:
        raise ConfigError(f"unknown {cls.__name__} keys {unknown}; valid keys are {sorted(known)}")


_TEXT_TYPES = {"int": int, "float": float, "str": str}


def number_or_text(text: str) -> int | float | str:
    """A ``KEY=VALUE`` word's value whose type nobody declared (a sampler's parameters, a batch
    manifest's words): an integer or a number when it reads as one, else the text itself."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            continue
    return text


def config_from_text(cls: type, values: dict[str, str]):
    """A parameter dataclass (:class:`FitConfig`, :class:`isf.RepairConfig`) from text, e.g.
    command-line words ``KEY=VALUE``: each value read as its field's type (``true``/``false``
    for flags), the rest left at their defaults.

    Raises:
        ConfigError: an unknown key (the message lists the valid ones), a value that does not
            read as its field's type, or a value the dataclass rejects.
    """
    _reject_unknown(cls, values)
    types = {f.name: f.type for f in fields(cls)}
    typed = {}
    for key, text in values.items():
        if types[key] == "bool":
            if text.lower() not in ("true", "false"):
                raise ConfigError(f"{cls.__name__}.{key} takes true or false, got {text!r}")
            typed[key] = text.lower() == "true"
            continue
        try:
            typed[key] = _TEXT_TYPES[types[key]](text)
        except ValueError:
            raise ConfigError(
                f"{cls.__name__}.{key} takes {'an integer' if types[key] == 'int' else 'a number'}, "
                f"got {text!r}") from None
    return cls(**typed)
