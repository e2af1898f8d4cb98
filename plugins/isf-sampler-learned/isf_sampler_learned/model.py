"""The model: an additive logistic regression on hinge features, stored as a numpy ``.npz``.

Each feature ``x_j`` (see :mod:`isf_sampler_learned.features`) is standardised,
``z_j = (x_j - mean_j) / std_j``, and expanded into ``z_j`` and hinges
``max(0, z_j - k)`` at knots ``k`` placed at its training quantiles, so the model can learn a
band (e.g. an object extent that fits the opening) rather than only a slope. Two heads share
that basis ``B(x)``:

- ``valid``: ``P(valid | x) = sigmoid(B(x) . w_valid)``, fitted by Newton's method with an L2
  penalty on labels "collision-free and every contact surface touching";
- ``error``: ``B(x) . w_error`` predicts ``log10`` of the fitting error (metres) of the valid
  examples (ridge regression).

A model file is a ``.npz`` read with ``allow_pickle=False``: plain numeric and text arrays,
nothing executable, so a file from anywhere is safe to load. It records its format, the
feature definition (:data:`~isf_sampler_learned.features.FEATURE_VERSION`) and the sha256 of
the gripper it was trained for (:func:`~isf_sampler_learned.features.gripper_sha256`);
:func:`load_model` refuses a file made for another gripper or another feature definition.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from isf.exceptions import InvalidInputError

from .features import FEATURE_NAMES, FEATURE_VERSION

__all__ = ["L2", "MODEL_FORMAT", "LearnedModel", "ModelFileError", "fit_model", "load_model"]

L2 = 1.0
"""The default L2 penalty of both heads on the non-intercept weights (:func:`fit_model`)."""

MODEL_FORMAT = "isf-learned-sampler-model/1"
_QUANTILES = (0.2, 0.4, 0.6, 0.8)
_NEWTON_STEPS = 50


class ModelFileError(InvalidInputError):
    """A sampler model file cannot be read, or was made for another gripper or feature set."""


@dataclass(frozen=True, eq=False)
class LearnedModel:
    """A trained model (see the module docstring).

    Attributes:
        gripper_sha256: sha256 of the gripper it was trained for.
        gripper_name: that gripper's name, for messages.
        mean: feature means, shape (F,).
        std: feature standard deviations, shape (F,).
        knots: hinge knots per standardised feature, shape (F, K).
        w_valid: weights of the validity head, shape (P,).
        w_error: weights of the error head (log10 metres), shape (P,).
        error_spread: standard deviation of the valid examples' log10 errors.
        info: JSON-serialisable notes: training objects, seed, examples, held-out accuracy.
        feature_version: the feature definition the weights belong to.
    """

    gripper_sha256: str
    gripper_name: str
    mean: np.ndarray
    std: np.ndarray
    knots: np.ndarray
    w_valid: np.ndarray
    w_error: np.ndarray
    error_spread: float
    info: dict = field(default_factory=dict)
    feature_version: str = FEATURE_VERSION

    def basis(self, features: np.ndarray) -> np.ndarray:
        """The hinge basis of ``features`` (M, F): shape (M, P)."""
        return _basis(features, self.mean, self.std, self.knots)

    def p_valid(self, features: np.ndarray) -> np.ndarray:
        """Probability that each start fits to a valid grasp, shape (M,)."""
        return _sigmoid(self.basis(features) @ self.w_valid)

    def log_error(self, features: np.ndarray) -> np.ndarray:
        """Predicted log10 fitting error (metres) should the start fit validly, shape (M,)."""
        return self.basis(features) @ self.w_error

    def save(self, path: str | os.PathLike) -> Path:
        """Write the model to ``path`` (a ``.npz``; the suffix is added when missing)."""
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("wb") as stream:
            np.savez(
                stream,
                format=np.array(MODEL_FORMAT),
                feature_version=np.array(self.feature_version),
                feature_names=np.array(FEATURE_NAMES),
                gripper_sha256=np.array(self.gripper_sha256),
                gripper_name=np.array(self.gripper_name),
                mean=self.mean, std=self.std, knots=self.knots,
                w_valid=self.w_valid, w_error=self.w_error,
                error_spread=np.array(self.error_spread),
                info=np.array(json.dumps(self.info, sort_keys=True, allow_nan=False)),
            )
        return path


def load_model(path: str | os.PathLike, gripper_sha256: str | None = None) -> LearnedModel:
    """Read a model file, checking it against the feature definition and, when given, the
    gripper.

    Args:
        path: a file written by :meth:`LearnedModel.save`.
        gripper_sha256: the digest of the gripper it must belong to, or None to skip that check.

    Raises:
        ModelFileError: the file is missing or unreadable, not a model, made for another
            feature definition, or made for another gripper.
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            fields = {key: data[key] for key in data.files}
    except (OSError, ValueError, EOFError) as err:
        raise ModelFileError(
            f"cannot read sampler model {path} ({type(err).__name__}); pass a .npz written by "
            "'python -m isf_sampler_learned train'"
        ) from None
    if str(fields.get("format", "")) != MODEL_FORMAT:
        raise ModelFileError(f"{path} is not an isf learned-sampler model ({MODEL_FORMAT}); "
                             "train one with 'python -m isf_sampler_learned train'")
    version = str(fields["feature_version"])
    if version != FEATURE_VERSION or tuple(fields["feature_names"].tolist()) != FEATURE_NAMES:
        raise ModelFileError(
            f"sampler model {path} uses features {version!r}, this plugin computes "
            f"{FEATURE_VERSION!r}: retrain it with 'python -m isf_sampler_learned train'"
        )
    name, digest = str(fields["gripper_name"]), str(fields["gripper_sha256"])
    if gripper_sha256 is not None and digest != gripper_sha256:
        raise ModelFileError(
            f"sampler model {path} was trained for gripper {name!r} (sha256 {digest[:12]}...), "
            f"not this one (sha256 {gripper_sha256[:12]}...): train one for this gripper"
        )
    return LearnedModel(
        gripper_sha256=digest, gripper_name=name,
        mean=fields["mean"], std=fields["std"], knots=fields["knots"],
        w_valid=fields["w_valid"], w_error=fields["w_error"],
        error_spread=float(fields["error_spread"]), info=json.loads(str(fields["info"])),
        feature_version=version,
    )


def fit_model(features: np.ndarray, valid: np.ndarray, error: np.ndarray, *,
              gripper_sha256: str, gripper_name: str, l2: float = L2,
              info: dict | None = None) -> LearnedModel:
    """Fit both heads (deterministic: no randomness).

    Args:
        features: examples' features, shape (M, F).
        valid: their labels, shape (M,), bool.
        error: their fitting errors, metres, shape (M,) (only valid ones are used).
        gripper_sha256: digest of the gripper the examples came from.
        gripper_name: its name.
        l2: L2 penalty of both heads on the non-intercept weights.
        info: notes stored with the model.

    Raises:
        InvalidInputError: fewer than 10 examples, or shapes that disagree.
    """
    features = np.asarray(features, dtype=float)
    valid = np.asarray(valid, dtype=bool)
    error = np.asarray(error, dtype=float)
    if features.ndim != 2 or features.shape[1] != len(FEATURE_NAMES) or len(features) < 10 \
            or valid.shape != (len(features),) or error.shape != (len(features),):
        raise InvalidInputError(
            f"fit_model needs at least 10 examples of {len(FEATURE_NAMES)} features with one "
            f"label and error each, got features {features.shape}, valid {valid.shape}"
        )
    mean = features.mean(axis=0)
    std = np.where(features.std(axis=0) > 1e-9, features.std(axis=0), 1.0)
    z = (features - mean) / std
    knots = np.quantile(z, _QUANTILES, axis=0).T
    B = _basis(features, mean, std, knots)
    penalty = np.full(B.shape[1], l2)
    penalty[0] = 0.0
    w_valid = _logistic(B, valid.astype(float), penalty)
    good = valid & np.isfinite(error) & (error > 0)
    log_error = np.log10(error[good]) if good.any() else np.zeros(0)
    if good.sum() >= 2:
        Bg = B[good]
        w_error = np.linalg.solve(Bg.T @ Bg + np.diag(penalty + 1e-9), Bg.T @ log_error)
        spread = float(max(log_error.std(), 1e-3))
    else:
        w_error = np.zeros(B.shape[1])
        spread = 1.0
    return LearnedModel(gripper_sha256=gripper_sha256, gripper_name=gripper_name, mean=mean,
                        std=std, knots=knots, w_valid=w_valid, w_error=w_error,
                        error_spread=spread, info=dict(info or {}))


def _basis(features: np.ndarray, mean: np.ndarray, std: np.ndarray,
           knots: np.ndarray) -> np.ndarray:
    """``[1, z_j, max(0, z_j - k_jl) ...]`` per example, shape (M, 1 + F * (1 + K))."""
    z = (np.asarray(features, dtype=float).reshape(-1, len(mean)) - mean) / std
    hinges = np.maximum(z[:, :, None] - knots[None, :, :], 0.0)
    return np.column_stack([np.ones(len(z)), z, hinges.reshape(len(z), -1)])


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def _logistic(B: np.ndarray, y: np.ndarray, penalty: np.ndarray) -> np.ndarray:
    """L2-penalised logistic regression weights by Newton's method, shape (P,)."""
    w = np.zeros(B.shape[1])
    for _ in range(_NEWTON_STEPS):
        p = _sigmoid(B @ w)
        gradient = B.T @ (p - y) + penalty * w
        hessian = (B * (p * (1 - p))[:, None]).T @ B + np.diag(penalty + 1e-9)
        step = np.linalg.solve(hessian, gradient)
        w -= step
        if np.abs(step).max() < 1e-8:
            break
    return w
