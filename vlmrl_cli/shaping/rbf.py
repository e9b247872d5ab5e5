"""RBF smoothing of milestone potentials over the visual prototype cache (Section 3.2), exact on
every CPU for integer features (no numpy ``exp`` or BLAS ``dot``; see docs/method.md)."""

from __future__ import annotations

import math

import numpy as np

from vlmrl_cli.core.fp import exp, fsum

_INT64_MAX = np.iinfo(np.int64).max


def squared_distances(points: np.ndarray, feature: np.ndarray, unit: float = 1.0,
                      spread: int | None = None) -> np.ndarray:
    """``||points_i - feature||^2 / unit^2`` for each row: ``(N, D)``, ``(D,)`` -> ``(N,)`` float64,
    exact for integers; ``spread``: the width every integer entry lies within (skips a check).

    Example:
        >>> squared_distances(np.array([[0, 0], [3, 4]]), np.array([0, 0]), unit=5.0).tolist()
        [0.0, 1.0]
    """
    if np.issubdtype(points.dtype, np.integer) and np.issubdtype(feature.dtype, np.integer):
        diff = points.astype(np.int64, copy=False) - feature.astype(np.int64, copy=False)[None, :]
        known_safe = spread is not None and spread**2 * diff.shape[1] <= _INT64_MAX
        if diff.size and not known_safe and int(np.abs(diff).max()) ** 2 * diff.shape[1] > _INT64_MAX:
            raise ValueError("integer features too large for an exact int64 squared distance")
        # einsum sums the int64 products without a (N, D) temporary; integer sums are exact
        return np.einsum("ij,ij->i", diff, diff).astype(np.float64) / (unit * unit)
    fdiff = np.asarray(points, dtype=np.float64) - np.asarray(feature, dtype=np.float64)[None, :]
    return (fdiff * fdiff).sum(axis=1) / (unit * unit)


class RBFField:
    """``sum_i w_i phi_i / sum_i w_i``, ``w_i = exp(-||f - f_i||^2 / (2 bandwidth^2))``, per frame key
    as prototypes arrive (0.0 before the first; the nearest's when every weight would underflow)."""

    def __init__(self, bandwidth: float, dim: int, unit: float = 1.0) -> None:
        if not (math.isfinite(bandwidth) and bandwidth > 0):
            raise ValueError(f"bandwidth must be > 0 (feature-distance units), got {bandwidth}")
        self.bandwidth = float(bandwidth)
        self.unit = float(unit)
        self._scale = 1.0 / (2.0 * self.bandwidth * self.bandwidth)
        self._dim = dim
        # buffers of doubling capacity; only the first ``_n`` prototype rows and ``_k`` key rows are live
        self._n = 0
        self._k = 0
        self._proto_buf: np.ndarray | None = None  # (capacity, D), the dtype of the first feature
        self._pot_buf = np.empty(0, dtype=np.float64)
        self._index: dict[str, int] = {}
        self._feat_buf: np.ndarray | None = None  # (capacity, D)
        self._knorm_buf = np.empty(0, dtype=np.int64)  # each key's squared norm (integer features)
        self._pnorm_buf = np.empty(0, dtype=np.int64)  # each prototype's squared norm
        self._num_buf = np.empty(0, dtype=np.float64)
        self._den_buf = np.empty(0, dtype=np.float64)
        self._ref_buf = np.empty(0, dtype=np.float64)  # squared distance the weights are relative to
        self._low, self._high = math.inf, -math.inf  # range of the prototype potentials
        # each key's value until the next prototype or potential change: a dict lookup per env step
        self._values: dict[str, float] = {}
        self._entry_low, self._entry_high = 0, 0  # range of every integer feature entry seen

    @property
    def prototypes(self) -> int:
        return self._n

    @property
    def potentials(self) -> np.ndarray:
        """The prototypes' potentials, (N,), in insertion order (a view)."""
        return self._pot_buf[: self._n]

    @property
    def features(self) -> np.ndarray:
        """The prototypes' features, (N, D), in insertion order (a view)."""
        return np.empty((0, self._dim)) if self._proto_buf is None else self._proto_buf[: self._n]

    @staticmethod
    def _grown(buf: np.ndarray, used: int) -> np.ndarray:
        """``buf`` with room for one more row (capacity doubled when full; rows kept)."""
        if used < buf.shape[0]:
            return buf
        bigger = np.empty((max(64, 2 * used), *buf.shape[1:]), dtype=buf.dtype)
        bigger[:used] = buf[:used]
        return bigger

    def _row(self, feature: np.ndarray) -> np.ndarray:
        f = np.asarray(feature)
        if f.shape != (self._dim,):
            raise ValueError(f"expected a feature of shape ({self._dim},), got {f.shape}")
        integer = bool(np.issubdtype(f.dtype, np.integer))
        if self._proto_buf is not None and integer != bool(np.issubdtype(self._proto_buf.dtype, np.integer)):
            raise ValueError("features must all be integers (exact distances) or all floats, not a mix")
        row = f.astype(np.int64 if integer else np.float64)[None, :]
        if integer and row.size:
            first = self._proto_buf is None and self._feat_buf is None
            low, high = int(row.min()), int(row.max())
            self._entry_low = low if first else min(self._entry_low, low)
            self._entry_high = high if first else max(self._entry_high, high)
        return row

    def _spread(self) -> int | None:
        """The width of the range of every integer entry seen (None for float features)."""
        if self._proto_buf is not None and not np.issubdtype(self._proto_buf.dtype, np.integer):
            return None
        return self._entry_high - self._entry_low

    def add_prototype(self, feature: np.ndarray, potential: float) -> None:
        row = self._row(feature)
        self._values.clear()
        if self._proto_buf is None:
            self._proto_buf = np.empty((0, self._dim), dtype=row.dtype)
        self._proto_buf = self._grown(self._proto_buf, self._n)
        self._pnorm_buf = self._grown(self._pnorm_buf, self._n)
        self._pot_buf = self._grown(self._pot_buf, self._n)
        self._proto_buf[self._n] = row[0]
        self._pnorm_buf[self._n] = self._norm(row[0])
        self._pot_buf[self._n] = float(potential)
        self._n += 1
        self._low = min(self._low, float(potential))
        self._high = max(self._high, float(potential))
        if self._feat_buf is None:
            return
        k = self._k
        ref, num, den = self._ref_buf[:k], self._num_buf[:k], self._den_buf[:k]
        sq = self._key_distances(row[0])
        closer = np.flatnonzero(sq < ref)
        # rebase keys whose nearest prototype is the new one, so no weight underflows (the others'
        # factor would be exp(-0.0) = 1.0 exactly, so they are left as they are)
        rescale = exp(-(ref[closer] - sq[closer]) * self._scale)
        num[closer] *= rescale
        den[closer] *= rescale
        ref[closer] = sq[closer]
        w = exp(-(sq - ref) * self._scale)
        num += w * float(potential)
        den += w

    def _key_distances(self, proto: np.ndarray) -> np.ndarray:
        """``squared_distances(keys, proto)``: see ``_distances``."""
        assert self._feat_buf is not None
        return self._distances(self._feat_buf[: self._k], self._knorm_buf[: self._k], proto)

    def _distances(self, rows: np.ndarray, norms: np.ndarray, f: np.ndarray) -> np.ndarray:
        """``squared_distances(rows, f)``, the same numbers: as ``|r|^2 - 2 r.f + |f|^2`` from the stored
        ``norms`` for non-negative integer features too small for an int64 sum to overflow."""
        if (np.issubdtype(rows.dtype, np.integer) and self._entry_low >= 0
                and 2 * self._dim * self._entry_high**2 <= _INT64_MAX):
            g = f.astype(np.int64, copy=False)
            exact = norms - 2 * np.einsum("ij,j->i", rows, g) + int(np.einsum("i,i->", g, g))
            return exact.astype(np.float64) / (self.unit * self.unit)
        return squared_distances(rows, f, self.unit, self._spread())

    @staticmethod
    def _norm(row: np.ndarray) -> int:
        """The squared norm of an integer row (exact while ``_distances``' bound holds, else unused)."""
        return int(np.einsum("i,i->", row, row)) if np.issubdtype(row.dtype, np.integer) else 0

    def set_potential(self, index: int, potential: float) -> None:
        """Give prototype ``index`` (insertion order) a new potential, updating every stored key."""
        if self._proto_buf is None or not 0 <= index < self._n:
            raise IndexError(f"no prototype {index}; the field holds {self.prototypes}")
        old = float(self._pot_buf[index])
        new = float(potential)
        if new == old:
            return
        self._pot_buf[index] = new
        self._values.clear()
        self._low, self._high = float(self.potentials.min()), float(self.potentials.max())
        if self._feat_buf is None:
            return
        k = self._k
        sq = self._key_distances(self._proto_buf[index])
        self._num_buf[:k] += exp(-(sq - self._ref_buf[:k]) * self._scale) * (new - old)

    def value(self, key: str, feature: np.ndarray) -> float:
        known = self._values.get(key)
        if known is not None:
            return known
        if self._proto_buf is None:
            return 0.0
        row = self._index.get(key)
        if row is None:
            f = self._row(feature)
            sq = self._distances(self._proto_buf[: self._n], self._pnorm_buf[: self._n], f[0])
            ref = float(sq.min())
            w = exp(-(sq - ref) * self._scale)
            num, den = fsum(w * self._pot_buf[: self._n]), fsum(w)  # exactly rounded
            row = self._k
            self._index[key] = row
            if self._feat_buf is None:
                self._feat_buf = np.empty((0, self._dim), dtype=f.dtype)
            self._feat_buf = self._grown(self._feat_buf, row)
            self._knorm_buf = self._grown(self._knorm_buf, row)
            self._num_buf = self._grown(self._num_buf, row)
            self._den_buf = self._grown(self._den_buf, row)
            self._ref_buf = self._grown(self._ref_buf, row)
            self._feat_buf[row] = f[0]
            self._knorm_buf[row] = self._norm(f[0])
            self._num_buf[row], self._den_buf[row], self._ref_buf[row] = num, den, ref
            self._k += 1
        # called every env step: plain floats, and the documented bound kept exact
        value = min(max(float(self._num_buf[row]) / float(self._den_buf[row]), self._low), self._high)
        self._values[key] = value
        return value
