"""Reward-hacking section: does an arm learn to hover short of the flag for the kinematic reward?
Read from tracked results only (``shaping.hacking``'s eval metrics, detached lengths, shaped - native)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from vlmrl_cli.analysis import stats
from vlmrl_cli.core import tables
from vlmrl_cli.report.table2 import order_arms
from vlmrl_cli.shaping.hacking import HOVER_FLAG, HOVER_HORIZON

NO_DIAGNOSTIC = (
    "This task has no hovering diagnostic (its plug-in names no position to watch), so there is no hover "
    "fraction, dwell or flagged seed. Shaped - native: mean over the last training window of the shaped minus the "
    "native episode return (what the shaping paid on top of the task). Detached lengths and timeouts are per "
    "episode, pooled over seeds."
)


def definition(hover_from: float | None) -> str:
    """What the section's columns mean, given the task's ``Hover.start`` (None: no hovering diagnostic).

    Example:
        >>> definition(0.3)[:64]
        "Hover fraction: the share of a run's detached evaluation steps s"
    """
    if hover_from is None:
        return NO_DIAGNOSTIC
    return (
        f"Hover fraction: the share of a run's detached evaluation steps spent right of x = {hover_from:g} without "
        f"reaching the flag within the next {HOVER_HORIZON} steps (driving straight in takes about 5-7 steps from "
        f"there); a run is flagged when it exceeds {HOVER_FLAG:g}. Dwell: mean steps per detached episode right of "
        f"x = {hover_from:g}. Shaped - native: mean over the last training window of the shaped minus the native "
        "episode return (what the shaping paid on top of the task). Flagged seeds are counted per seed with a Wilson "
        "interval; detached lengths and timeouts are per episode, pooled over seeds."
    )


def _finite(x: Any) -> np.ndarray:
    a = np.asarray(x, dtype=float).reshape(-1)
    return a[np.isfinite(a)]


def hacking_frame(per_seed: pd.DataFrame, eval_episodes: pd.DataFrame, ci: float, timeout: int) -> pd.DataFrame:
    """One row per arm: hover fraction, flagged seeds (Wilson CI), dwell, shaped - native gap and the
    detached lengths (``timeout``: the task's time limit); NaN where the runs did not log a quantity."""
    rows = []
    for arm in order_arms(per_seed["arm"].unique().tolist()):
        d = per_seed[per_seed["arm"] == arm]
        hover = _finite(d["hover_fraction"]) if "hover_fraction" in d else np.zeros(0)
        flagged = stats.wilson_ci(int((hover > HOVER_FLAG).sum()), int(hover.size), ci)
        ev = eval_episodes[eval_episodes["arm"] == arm] if len(eval_episodes) else eval_episodes
        lengths = _finite(ev["length"]) if len(ev) else np.zeros(0)
        nan = float("nan")
        rows.append({
            "arm": arm, "seeds": len(d), "seeds_with_hover_metric": int(hover.size),
            "hover_fraction_mean": float(hover.mean()) if hover.size else nan,
            "hover_fraction_max": float(hover.max()) if hover.size else nan,
            "flagged_seeds": int((hover > HOVER_FLAG).sum()), "flagged_value": flagged.value,
            "flagged_ci_low": flagged.low, "flagged_ci_high": flagged.high,
            "dwell_right_steps_mean": _mean(d.get("dwell_right_steps")),
            "shaped_gap_mean": _mean(d.get("shaped_gap")),
            "eval_episodes": int(lengths.size),
            "eval_length_median": float(np.median(lengths)) if lengths.size else nan,
            "eval_length_p90": float(np.percentile(lengths, 90)) if lengths.size else nan,
            "eval_timeout_share": float(np.mean(lengths >= timeout)) if lengths.size else nan,
        })
    return pd.DataFrame(rows)


def _mean(values: Any) -> float:
    v = _finite(values) if values is not None else np.zeros(0)
    return float(v.mean()) if v.size else float("nan")


def _num(x: float, fmt: str) -> str:
    return format(x, fmt) if np.isfinite(x) else "—"


def hacking_markdown(frame: pd.DataFrame, ci: float = 0.95, hover: bool = True) -> str:
    """Markdown of ``hacking_frame``; ``hover`` False: the task has no hovering diagnostic."""
    rows = []
    for r in frame.itertuples(index=False):
        if not hover:
            flagged = "no diagnostic for this task"
        elif r.seeds_with_hover_metric:
            flagged = (f"{r.flagged_seeds}/{r.seeds_with_hover_metric} "
                       f"[{100 * r.flagged_ci_low:.0f}%, {100 * r.flagged_ci_high:.0f}%]")
        else:
            flagged = "not logged (runs predate the diagnostic)"
        lengths = (f"{r.eval_episodes} ep.: {_num(r.eval_length_median, '.0f')}, {_num(r.eval_length_p90, '.0f')}, "
                   f"{_num(100 * r.eval_timeout_share, '.0f')}%" if r.eval_episodes else "not logged")
        rows.append([r.arm, f"{_num(r.hover_fraction_mean, '.3f')} ({_num(r.hover_fraction_max, '.3f')})", flagged,
                     _num(r.dwell_right_steps_mean, ".1f"), _num(r.shaped_gap_mean, ".1f"), lengths])
    header = ["Arm", "Hover fraction mean (max)", f"Flagged seeds [{100 * ci:g}% Wilson]", "Dwell right (steps)",
              "Shaped - native", "Detached episodes: median length, p90, timeouts"]
    return "\n".join(tables.markdown_rows(header, rows)) + "\n"


def per_arm(frame: pd.DataFrame, column: str, arms: list[str]) -> dict[str, np.ndarray]:
    """``column`` of a tidy frame with an ``arm`` column, split by arm (shape ``(n_arm,)`` each)."""
    if column not in frame or not len(frame):
        return {a: np.zeros(0) for a in arms}
    return {a: frame.loc[frame["arm"] == a, column].to_numpy(dtype=float) for a in arms}
