"""Statistics of the taxonomy probe: small pure functions over arrays whose shapes are stated.

Positions are in x units (track [-1.2, 0.6]), boxes are (x0, y0, x1, y1) in image pixels of
the 600x400 frame, potentials are unitless. Missing answers are NaN (arrays) or None (labels).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

from vlmrl_cli.vlm.parsers import Box, ParseStatus

# Statuses where the model's text itself failed (NO_ANSWER is the transcript's gap, not the model's).
FORMAT_FAILURES = frozenset({ParseStatus.FORMAT_COLLAPSE, ParseStatus.EMPTY, ParseStatus.AMBIGUOUS})
# Below this a potential difference counts as zero: the potentials are sums of a few decimals.
DPHI_ZERO_TOL = 1e-9


def absolute_error(predicted: Sequence[float] | np.ndarray, truth: Sequence[float] | np.ndarray) -> np.ndarray:
    """|predicted - truth| elementwise; shapes (n,) -> (n,), NaN where predicted is NaN (x units)."""
    return np.abs(np.asarray(predicted, dtype=float) - np.asarray(truth, dtype=float))


def finite_pairs(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pairs of two (n,) arrays where both values are finite, as two (m,) arrays, m <= n."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    keep = np.isfinite(x) & np.isfinite(y)
    return x[keep], y[keep]


def spearman(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> float:
    """Spearman rank correlation of two (n,) arrays over the pairs where both are finite.

    NaN when fewer than two such pairs remain or either side is constant (no ranking to compare).

    Example:
        >>> spearman([1, 2, 3], [10, 20, 30]), math.isnan(spearman([1, 1, 1], [1, 2, 3]))
        (1.0, True)
    """
    x, y = finite_pairs(a, b)
    if x.size < 2 or np.all(x == x[0]) or np.all(y == y[0]):
        return math.nan
    return float(stats.spearmanr(x, y).statistic)


def spearman_ci(rho: float, n: int, level: float = 0.95) -> tuple[float, float]:
    """Confidence interval of a Spearman correlation ``rho`` over ``n`` pairs (Fisher z, Bonett-Wright variance).

    z = atanh(rho) is taken as normal with variance (1 + rho^2 / 2) / (n - 3) (Bonett & Wright 2000,
    Psychometrika 65:23-28), and the bounds are mapped back with tanh. (NaN, NaN) when the interval is
    undefined: rho NaN, n < 4, or |rho| = 1 (a perfect ranking has no Fisher z).

    Example:
        >>> lo, hi = spearman_ci(0.0, 103)
        >>> round(lo, 3), round(hi, 3)
        (-0.194, 0.194)
    """
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    if not math.isfinite(rho) or n < 4 or abs(rho) >= 1:
        return math.nan, math.nan
    half = float(stats.norm.ppf(0.5 + level / 2)) * math.sqrt((1 + rho * rho / 2) / (n - 3))
    z = math.atanh(rho)
    return math.tanh(z - half), math.tanh(z + half)


def iou(a: Box, b: Box) -> float:
    """Intersection over union of two boxes (x0, y0, x1, y1) in pixels; in [0, 1], 0 if either is empty.

    Example:
        >>> iou((0, 0, 10, 10), (5, 0, 15, 10))
        0.3333333333333333
    """
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    area_a = max(0.0, a[2] - a[0]) * max(0.0, a[3] - a[1])
    area_b = max(0.0, b[2] - b[0]) * max(0.0, b[3] - b[1])
    union = area_a + area_b - inter
    if not union > 0 or not math.isfinite(union):
        return 0.0
    return float(min(1.0, max(0.0, inter / union)))


def box_centre(box: Box) -> tuple[float, float]:
    """Centre (column, row) of a box, in pixels."""
    return (box[0] + box[2]) / 2.0, (box[1] + box[3]) / 2.0


def centre_error_px(a: Box, b: Box) -> float:
    """Euclidean distance between the centres of two boxes, in pixels."""
    (ca, ra), (cb, rb) = box_centre(a), box_centre(b)
    return float(math.hypot(ca - cb, ra - rb))


def format_failure_rate(statuses: Iterable[ParseStatus]) -> float:
    """Fraction of answered queries whose text could not be parsed (collapse, empty, ambiguous).

    NO_ANSWER (no text existed) is left out of the denominator; NaN when nothing was answered.
    """
    answered = [s for s in statuses if s is not ParseStatus.NO_ANSWER]
    if not answered:
        return math.nan
    return sum(s in FORMAT_FAILURES for s in answered) / len(answered)


def mcq_accuracy(predicted: Sequence[str | None], truth: Sequence[str]) -> float:
    """Fraction of (n,) predictions equal to the (n,) true zones; None counts as wrong. NaN if n=0."""
    if len(predicted) != len(truth):
        raise ValueError(f"{len(predicted)} predictions for {len(truth)} true labels; pass one per frame.")
    if not truth:
        return math.nan
    return sum(p == t for p, t in zip(predicted, truth, strict=True)) / len(truth)


# --- the consequence on the potential ------------------------------------------------------

def label_potential(label: str | None, mapping: Mapping[str, float]) -> float:
    """Raw potential Phi_raw of an MCQ label under the task's label ``mapping``; NaN for None.

    Example:
        >>> label_potential("HIGH", {"LOW": 0.0, "HIGH": 1.0}), math.isnan(label_potential(None, {}))
        (1.0, True)
    """
    return math.nan if label is None else float(mapping[label])


def position_potential(x: float | None, low: float, high: float) -> float:
    """A float answer's potential: ``x`` normalised to [0, 1] over the range ``[low, high]`` (the
    task's track); NaN for None.

    Example:
        >>> position_potential(-0.3, -1.2, 0.6)
        0.5
    """
    return math.nan if x is None else (x - low) / (high - low)


def box_potential(box: Box | None, width: float) -> float:
    """A box answer's potential: the box centre column normalised to [0, 1] by the frame ``width``."""
    return math.nan if box is None else box_centre(box)[0] / width


@dataclass(frozen=True)
class DeltaPhiStats:
    """What a VLM-derived potential does to PBRS over consecutive states of a sweep.

    Fractions are over the ``n_pairs`` consecutive pairs where both potentials are available;
    ``phi_unavailable`` is over the states. All NaN when no pair is usable.
    """

    n_states: int
    n_pairs: int
    phi_unavailable: float
    dead_zone: float
    dead_zone_while_truth_moves: float
    sign_disagreement: float
    mean_abs_dphi_error: float

    def as_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in self.__dict__.items()}


def delta_phi_stats(phi_vlm: Sequence[float] | np.ndarray, phi_true: Sequence[float] | np.ndarray) -> DeltaPhiStats:
    """Compare dPhi = Phi(s_{i+1}) - Phi(s_i) of the VLM with the truth over consecutive states.

    ``phi_vlm`` and ``phi_true`` have shape (n,), the states sorted along the track; NaN in
    ``phi_vlm`` marks an unparsed answer (Phi unavailable); pairs touching one are skipped.

    - ``dead_zone``: fraction of pairs with dPhi == 0 (the shaping term is flat);
    - ``dead_zone_while_truth_moves``: fraction with dPhi == 0 but true dPhi != 0;
    - ``sign_disagreement``: fraction with sign(dPhi) != sign(true dPhi) (noise);
    - ``mean_abs_dphi_error``: mean |dPhi - true dPhi| (potential units).

    Example:
        >>> s = delta_phi_stats([0.0, 0.0, 0.1], [0.0, 0.1, 0.1])
        >>> s.dead_zone, s.sign_disagreement
        (0.5, 1.0)
    """
    vlm = np.asarray(phi_vlm, dtype=float)
    true = np.asarray(phi_true, dtype=float)
    if vlm.shape != true.shape or vlm.ndim != 1:
        raise ValueError(f"phi_vlm {vlm.shape} and phi_true {true.shape} must be equal (n,) arrays.")
    n = int(vlm.size)
    unavailable = float(np.mean(~np.isfinite(vlm))) if n else math.nan
    d_vlm, d_true = np.diff(vlm), np.diff(true)
    keep = np.isfinite(d_vlm) & np.isfinite(d_true)
    d_vlm, d_true = d_vlm[keep], d_true[keep]
    if d_vlm.size == 0:
        return DeltaPhiStats(n, 0, unavailable, math.nan, math.nan, math.nan, math.nan)
    flat = np.abs(d_vlm) <= DPHI_ZERO_TOL
    flat_true = np.abs(d_true) <= DPHI_ZERO_TOL
    sign_vlm = np.where(flat, 0.0, np.sign(d_vlm))
    sign_true = np.where(flat_true, 0.0, np.sign(d_true))
    return DeltaPhiStats(
        n_states=n,
        n_pairs=int(d_vlm.size),
        phi_unavailable=unavailable,
        dead_zone=float(np.mean(flat)),
        dead_zone_while_truth_moves=float(np.mean(flat & ~flat_true)),
        sign_disagreement=float(np.mean(sign_vlm != sign_true)),
        mean_abs_dphi_error=float(np.mean(np.abs(d_vlm - d_true))),
    )
