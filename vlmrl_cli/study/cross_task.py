"""The cross-task primary family (issue 51, declared in docs/results.md): each task's study's
hybrid vs baseline and hybrid vs kinematic speedups, Holm-adjusted across every task and judged by
``censored.judge_family``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from vlmrl_cli.analysis import censored
from vlmrl_cli.analysis.multiplicity import DEFAULT_ADJUST, family_line
from vlmrl_cli.core import tables
from vlmrl_cli.shaping.arms import BASELINE, DENSE, METHOD

#: The comparisons of the primary family on every task, as ``regime_map.csv`` keys them.
PRIMARY: tuple[str, ...] = (f"{METHOD}_vs_{BASELINE}", f"{METHOD}_vs_{DENSE}")
FAMILY_WHAT = ("The primary comparisons (each task's hybrid vs baseline and hybrid vs kinematic, steps to the "
               "study's top threshold)")
#: Each task's study whose main regime enters the committed family (relative to the repository root).
TASK_SCALED_STUDIES: dict[str, str] = {
    "mountain-car": "results/study", "acrobot": "results/tasks/acrobot/study-scaled",
    "minigrid-doorkey": "results/tasks/minigrid-doorkey/study-scaled",
    "mountain-car-continuous": "results/tasks/mountain-car-continuous/study-scaled"}
COLUMNS = ("task", "comparison", "speedup", "low", "high", "p", "test", "p_within_study", "p_family",
           "verdict_within_study", "verdict")


def primary_family(maps: Mapping[str, pd.DataFrame], method: str = DEFAULT_ADJUST, alpha: float = 0.05,
                   margin: float = censored.DEFAULT_MARGIN, pairs: Sequence[str] = PRIMARY) -> pd.DataFrame:
    """One row per (task, comparison) of the family (``COLUMNS``), p adjusted across tasks and re-judged;
    ``maps``: task -> its study's ``regime_map.csv`` (row 0: the main regime)."""
    rows = []
    for task, frame in maps.items():
        main = frame.iloc[0]
        for key in pairs:
            rows.append({"task": task, "comparison": key.replace("_vs_", " vs "),
                         **{c: main.get(f"{key}.{c}", np.nan) for c in
                            ("speedup", "low", "high", "p", "p_adj", "tost_low", "tost_high", "direction",
                             "equivalence_ok", "verdict", "test")}})
    df = pd.DataFrame(rows).rename(columns={"p_adj": "p_within_study", "verdict": "verdict_within_study"})
    judged = censored.judge_family(df["p"], np.full(len(df), np.nan), df["direction"], df[["low", "high"]],
                                   df[["tost_low", "tost_high"]],
                                   [str(v).lower() in ("true", "1", "1.0") for v in df["equivalence_ok"]],
                                   method, alpha, margin)
    df["p_family"], df["verdict"] = judged.p_adjusted, list(judged.verdicts)
    return df[list(COLUMNS)]


def _method(test: object) -> str:
    """The p's method named in a study's test column ("... (exact p)" -> "exact").

    Example:
        >>> _method("Mann-Whitney U on steps, DNF censored (exact p)"), _method(float("nan"))
        ('exact', '—')
    """
    text = str(test)
    return text[text.rfind("(") + 1:].removesuffix(" p)") if "(" in text else "—"


def to_markdown(df: pd.DataFrame, method: str = DEFAULT_ADJUST) -> str:
    """The family as a Markdown table, with the sentence that declares it."""
    body = [[r.task, r.comparison, f"{r.speedup:.2f}x [{r.low:.2f}, {r.high:.2f}]", f"{r.p:.2g}", _method(r.test),
             f"{r.p_within_study:.2g}", f"{r.p_family:.2g}", r.verdict_within_study, f"**{r.verdict}**"]
            for r in df.itertuples(index=False)]
    head = ["task", "comparison", "speedup [95%]", "raw p", "test", "adj. p within its study",
            f"adj. p in the family ({method})", "verdict within its study", "verdict in the family"]
    return (family_line(method, int(np.isfinite(df["p"].astype(float)).sum()), FAMILY_WHAT) + ".\n\n"
            + tables.markdown(pd.DataFrame(body, columns=head)))


def family_from_files(studies: Mapping[str, Path], method: str = DEFAULT_ADJUST) -> pd.DataFrame:
    """``primary_family`` of the studies' committed ``regime_map.csv`` (task -> study folder)."""
    return primary_family({t: pd.read_csv(d / "regime_map.csv") for t, d in studies.items()}, method)
