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
    as prototypes arrive (0.0 before the first; the nearest's when every weight would underflow).

    A key's sums are brought up to date when it is looked up again: the prototypes added and the
    potentials changed since, applied in order with the operations an update of every key at each
    event would do (the same bits), but only for the keys seen again."""

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
        self._pnorm_buf = np.empty(0, dtype=np.int64)  # each prototype's squared norm
        self._num_buf = np.empty(0, dtype=np.float64)
        self._den_buf = np.empty(0, dtype=np.float64)
        self._ref_buf = np.empty(0, dtype=np.float64)  # squared distance the weights are relative to
        self._synced_buf = np.empty(0, dtype=np.int64)  # how many of the events each key's sums include
        # the events, in order: (prototype, added?, its potential if added, else the potential's change)
        self._events: list[tuple[int, bool, float]] = []
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
        self._events.append((self._n - 1, True, float(potential)))

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
        """Give prototype ``index`` (insertion order) a new potential (each stored key applies it when looked up)."""
        if self._proto_buf is None or not 0 <= index < self._n:
            raise IndexError(f"no prototype {index}; the field holds {self.prototypes}")
        old = float(self._pot_buf[index])
        new = float(potential)
        if new == old:
            return
        self._pot_buf[index] = new
        self._values.clear()
        self._low, self._high = float(self.potentials.min()), float(self.potentials.max())
        self._events.append((index, False, new - old))

    def _catch_up(self, row: int) -> None:
        """Apply to key ``row``'s sums the events since it was last brought up to date, in order: an
        added prototype rebases the sums if it is the key's nearest (``exp(-(ref - sq) s)``, so no
        weight underflows) and adds its weight; a changed potential adds ``w (new - old)``."""
        assert self._feat_buf is not None and self._proto_buf is not None
        events = self._events[int(self._synced_buf[row]):]
        protos = np.fromiter((e[0] for e in events), dtype=np.intp, count=len(events))
        added = np.fromiter((e[1] for e in events), dtype=bool, count=len(events))
        values = np.fromiter((e[2] for e in events), dtype=np.float64, count=len(events))
        sq = self._distances(self._proto_buf[protos], self._pnorm_buf[protos], self._feat_buf[row])
        # the key's nearest squared distance before and after each event (a change moves no prototype)
        refs = np.minimum.accumulate(np.concatenate([self._ref_buf[row: row + 1], np.where(added, sq, np.inf)]))
        before, after = refs[:-1], refs[1:]
        closer = added & (sq < before)
        rescale = np.ones_like(sq)
        rescale[closer] = exp(-(before[closer] - sq[closer]) * self._scale)
        w = exp(-(sq - after) * self._scale)
        terms = w * values
        num, den = float(self._num_buf[row]), float(self._den_buf[row])
        for rebase, r, weight, term, add in zip(closer.tolist(), rescale.tolist(), w.tolist(), terms.tolist(),
                                                added.tolist(), strict=True):
            if rebase:
                num, den = num * r, den * r
            num += term
            if add:
                den += weight
        self._num_buf[row], self._den_buf[row], self._ref_buf[row] = num, den, float(after[-1])
        self._synced_buf[row] = len(self._events)

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
            self._num_buf = self._grown(self._num_buf, row)
            self._den_buf = self._grown(self._den_buf, row)
            self._ref_buf = self._grown(self._ref_buf, row)
            self._synced_buf = self._grown(self._synced_buf, row)
            self._feat_buf[row] = f[0]
            self._num_buf[row], self._den_buf[row], self._ref_buf[row] = num, den, ref
            self._synced_buf[row] = len(self._events)
            self._k += 1
        elif self._synced_buf[row] < len(self._events):
            self._catch_up(row)
        # called every env step: plain floats, and the documented bound kept exact
        value = min(max(float(self._num_buf[row]) / float(self._den_buf[row]), self._low), self._high)
        self._values[key] = value
        return value
