"""RBF smoothing of discrete milestone potentials over a visual prototype cache (Section 3.2)."""

from __future__ import annotations

import math

import numpy as np


def rbf_potential(
    feature: np.ndarray,
    proto_features: np.ndarray,
    proto_potentials: np.ndarray,
    bandwidth: float,
) -> float:
    """Kernel-weighted mean of prototype potentials (Nadaraya-Watson with a Gaussian kernel).

    ``feature`` has shape ``(D,)``, ``proto_features`` ``(N, D)`` (the same feature units, see
    ``features.frame_features``), ``proto_potentials`` ``(N,)`` (dimensionless potentials) and
    ``bandwidth`` is in feature-distance units. Weights are
    ``w_i = exp(-||f - f_i||^2 / (2 bandwidth^2))`` and the result is
    ``sum_i w_i phi_i / sum_i w_i``, so it always lies within ``[min phi_i, max phi_i]``.
    With no prototype (``N = 0``) the potential is 0.0. The exponent is shifted by the nearest
    prototype's squared distance (which cancels in the ratio), so when every raw weight would
    underflow the result is the nearest prototype's potential instead of 0/0.

    Example:
        >>> f = np.array([[0.0], [1.0]])
        >>> round(rbf_potential(np.array([0.0]), f, np.array([0.0, 1.0]), bandwidth=0.1), 12)
        0.0
        >>> rbf_potential(np.array([0.5]), f, np.array([0.0, 1.0]), bandwidth=0.1)
        0.5
    """
    if bandwidth <= 0:
        raise ValueError(f"bandwidth must be > 0, got {bandwidth}")
    protos = np.asarray(proto_features, dtype=np.float64)
    potentials = np.asarray(proto_potentials, dtype=np.float64)
    if protos.shape[0] == 0:
        return 0.0
    if protos.ndim != 2 or potentials.shape != (protos.shape[0],):
        raise ValueError(
            f"expected proto_features (N, D) and proto_potentials (N,), got {protos.shape} and {potentials.shape}"
        )
    diff = protos - np.asarray(feature, dtype=np.float64)[None, :]
    sq = np.einsum("nd,nd->n", diff, diff)
    logw = -(sq - sq.min()) / (2.0 * bandwidth * bandwidth)
    w = np.exp(logw)  # the nearest prototype has weight 1, so the sum is >= 1
    value = float(np.dot(w, potentials) / w.sum())
    # Rounding can put the mean an ulp outside the hull; clip keeps the documented bound exact.
    return float(np.clip(value, potentials.min(), potentials.max()))


class RBFField:
    """``rbf_potential`` for many frames while prototypes arrive one at a time, at O(1) a query.

    Each queried key keeps the numerator and denominator of its kernel-weighted mean relative
    to its nearest prototype so far; a new prototype updates every stored key in one
    vectorised step (cost (keys, D)) instead of invalidating them. ``value`` returns what
    ``rbf_potential`` would over the current prototypes, up to floating-point rounding.

    Example:
        >>> field = RBFField(bandwidth=0.1, dim=1)
        >>> field.value("a", np.array([0.5]))
        0.0
        >>> field.add_prototype(np.array([0.0]), 0.0); field.add_prototype(np.array([1.0]), 1.0)
        >>> field.value("a", np.array([0.5]))
        0.5
    """

    def __init__(self, bandwidth: float, dim: int) -> None:
        if bandwidth <= 0:
            raise ValueError(f"bandwidth must be > 0, got {bandwidth}")
        self.bandwidth = float(bandwidth)
        self._scale = 1.0 / (2.0 * self.bandwidth * self.bandwidth)
        self._protos = np.empty((0, dim), dtype=np.float64)
        self._potentials = np.empty(0, dtype=np.float64)
        self._index: dict[str, int] = {}
        self._feats = np.empty((0, dim), dtype=np.float64)
        self._num = np.empty(0, dtype=np.float64)
        self._den = np.empty(0, dtype=np.float64)
        self._ref = np.empty(0, dtype=np.float64)  # squared distance the weights are relative to
        self._low, self._high = math.inf, -math.inf  # range of the prototype potentials

    @property
    def prototypes(self) -> int:
        return int(self._potentials.shape[0])

    def add_prototype(self, feature: np.ndarray, potential: float) -> None:
        f = np.asarray(feature, dtype=np.float64)
        self._protos = np.vstack([self._protos, f[None, :]])
        self._potentials = np.append(self._potentials, float(potential))
        self._low = min(self._low, float(potential))
        self._high = max(self._high, float(potential))
        if not self._index:
            return
        diff = self._feats - f[None, :]
        sq = np.einsum("md,md->m", diff, diff)
        closer = sq < self._ref
        # rebase keys whose nearest prototype is the new one, so no weight underflows
        # (the others get exp(0) = 1; clipping first keeps exp from overflowing on them)
        rescale = np.exp(-np.maximum(self._ref - sq, 0.0) * self._scale)
        self._num *= rescale
        self._den *= rescale
        self._ref = np.where(closer, sq, self._ref)
        w = np.exp(-(sq - self._ref) * self._scale)
        self._num += w * float(potential)
        self._den += w

    def value(self, key: str, feature: np.ndarray) -> float:
        if not self.prototypes:
            return 0.0
        row = self._index.get(key)
        if row is None:
            f = np.asarray(feature, dtype=np.float64)
            diff = self._protos - f[None, :]
            sq = np.einsum("nd,nd->n", diff, diff)
            ref = float(sq.min())
            w = np.exp(-(sq - ref) * self._scale)
            row = self._num.shape[0]
            self._index[key] = row
            self._feats = np.vstack([self._feats, f[None, :]])
            self._num = np.append(self._num, float(np.dot(w, self._potentials)))
            self._den = np.append(self._den, float(w.sum()))
            self._ref = np.append(self._ref, ref)
        # called every env step: plain floats, and the documented bound kept exact
        value = float(self._num[row]) / float(self._den[row])
        return min(max(value, self._low), self._high)
