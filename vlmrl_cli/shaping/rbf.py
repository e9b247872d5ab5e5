"""RBF smoothing of discrete milestone potentials over a visual prototype cache (Section 3.2)."""

from __future__ import annotations

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
