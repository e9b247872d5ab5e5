"""Statistics of the taxonomy probe; boxes are (x0, y0, x1, y1) in pixels, missing answers NaN or None."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np
from scipy import stats

from vlmrl_cli.vlm.parsers import Box, ParseStatus

# Statuses where the model's text itself failed (NO_ANSWER is the transcript's gap, not the model's).
FORMAT_FAILURES = frozenset({ParseStatus.FORMAT_COLLAPSE, ParseStatus.EMPTY, ParseStatus.AMBIGUOUS})
# Below this a potential difference counts as zero: the potentials are sums of a few decimals.
DPHI_ZERO_TOL = 1e-9


def finite_pairs(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pairs of two (n,) arrays where both values are finite, as two (m,) arrays, m <= n."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    keep = np.isfinite(x) & np.isfinite(y)
    return x[keep], y[keep]


def spearman(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> float:
    """Spearman rank correlation over the pairs where both are finite; NaN: < 2 pairs or a constant side."""
    x, y = finite_pairs(a, b)
    if x.size < 2 or np.all(x == x[0]) or np.all(y == y[0]):
        return math.nan
    return float(stats.spearmanr(x, y).statistic)


def spearman_ci(rho: float, n: int, level: float = 0.95) -> tuple[float, float]:
    """Fisher-z interval of a Spearman ``rho`` over ``n`` pairs, Bonett & Wright's (2000) variance; NaN: n < 4."""
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    if not math.isfinite(rho) or n < 4 or abs(rho) >= 1:
        return math.nan, math.nan
    half = float(stats.norm.ppf(0.5 + level / 2)) * math.sqrt((1 + rho * rho / 2) / (n - 3))
    z = math.atanh(rho)
    return math.tanh(z - half), math.tanh(z + half)


def iou(a: Box, b: Box) -> float:
    """Intersection over union of two boxes, in [0, 1]; 0 if either is empty."""
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
    return (box[0] + box[2]) / 2.0, (box[1] + box[3]) / 2.0


def centre_error_px(a: Box, b: Box) -> float:
    (ca, ra), (cb, rb) = box_centre(a), box_centre(b)
    return float(math.hypot(ca - cb, ra - rb))


def format_failure_rate(statuses: Iterable[ParseStatus]) -> float:
    """Fraction of answered queries (NO_ANSWER left out) whose text did not parse; NaN if none."""
    answered = [s for s in statuses if s is not ParseStatus.NO_ANSWER]
    return sum(s in FORMAT_FAILURES for s in answered) / len(answered) if answered else math.nan


def mcq_accuracy(predicted: Sequence[str | None], truth: Sequence[str]) -> float:
    """Fraction of predictions equal to the truth (None is wrong); NaN if there are none."""
    if len(predicted) != len(truth):
        raise ValueError(f"{len(predicted)} predictions for {len(truth)} true labels; pass one per frame.")
    if not truth:
        return math.nan
    return sum(p == t for p, t in zip(predicted, truth, strict=True)) / len(truth)


def delta_phi_stats(phi_vlm: Sequence[float] | np.ndarray, phi_true: Sequence[float] | np.ndarray) -> dict[str, float]:
    """dPhi = Phi(s_{i+1}) - Phi(s_i) of the VLM against the truth over (n,) states sorted along the
    range: ``phi_unavailable`` over the states (NaN), the fractions over the usable pairs (NaN: none)."""
    vlm = np.asarray(phi_vlm, dtype=float)
    true = np.asarray(phi_true, dtype=float)
    if vlm.shape != true.shape or vlm.ndim != 1:
        raise ValueError(f"phi_vlm {vlm.shape} and phi_true {true.shape} must be equal (n,) arrays.")
    n = int(vlm.size)
    unavailable = float(np.mean(~np.isfinite(vlm))) if n else math.nan
    d_vlm, d_true = np.diff(vlm), np.diff(true)
    keep = np.isfinite(d_vlm) & np.isfinite(d_true)
    d_vlm, d_true = d_vlm[keep], d_true[keep]
    out = {"n_states": float(n), "n_pairs": float(d_vlm.size), "phi_unavailable": unavailable}
    if d_vlm.size == 0:
        return out | dict.fromkeys(("dead_zone", "dead_zone_while_truth_moves", "sign_disagreement",
                                    "mean_abs_dphi_error"), math.nan)
    flat = np.abs(d_vlm) <= DPHI_ZERO_TOL
    flat_true = np.abs(d_true) <= DPHI_ZERO_TOL
    sign_vlm = np.where(flat, 0.0, np.sign(d_vlm))
    sign_true = np.where(flat_true, 0.0, np.sign(d_true))
    return out | {
        "dead_zone": float(np.mean(flat)),
        "dead_zone_while_truth_moves": float(np.mean(flat & ~flat_true)),
        "sign_disagreement": float(np.mean(sign_vlm != sign_true)),
        "mean_abs_dphi_error": float(np.mean(np.abs(d_vlm - d_true))),
    }
