"""The study's numbers in words: the regime map's and the controls' Markdown tables and the
report's opening summary, from the rows of ``verdicts.py``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from vlmrl_cli.analysis import censored, multiplicity
from vlmrl_cli.analysis.multiplicity import DEFAULT_ADJUST
from vlmrl_cli.core import tables
from vlmrl_cli.probe.metrics import spearman
from vlmrl_cli.report.table2 import order_arms
from vlmrl_cli.shaping.arms import ARMS, BASELINE, DENSE, METHOD, ArmSpec
from vlmrl_cli.study.config import PLACEBO_ARM
from vlmrl_cli.study.verdicts import FAMILY_WHAT, NEITHER, NOT_MEASURED, family_size, map_pairs, untestable

#: The question the potential-form arm answers (issue 41): a verdict line of every study that has it.
HACKING_QUESTION = "Does the dense term in potential form remove the hacking?"


def _partial_family(planned: int, size: int, no_test: int) -> str:
    """What the summary says when the family adjusted (``size`` comparisons) is smaller than the
    ``planned`` one: ``no_test`` comparisons measured without a test, the rest not measured yet.

    Example:
        >>> _partial_family(15, 6, 9)[:67]
        " (the finished study's family holds 15: 9 of them have no test, as "
        >>> 'not measured yet' in _partial_family(15, 11, 1), _partial_family(15, 15, 0)
        (True, '')
    """
    if planned <= size:
        return ""
    parts = []
    if no_test:
        parts.append(f"{no_test} of them have no test, as every seed of both arms is a DNF at the budget: they "
                     "cannot reject and are not adjusted for")
    if planned - size > no_test:
        parts.append(f"{planned - size - no_test} not measured yet, so these adjustments are less strict than the "
                     "finished study's will be")
    return f" (the finished study's family holds {planned}: " + "; ".join(parts) + ")"


def format_speedup(row: dict[str, Any], key: str) -> str:
    """``1.40x [1.10, 1.80], p = 0.01 (adj. 0.05); log-rank p = 0.02 (adj. 0.08) (faster)`` from a
    map row, noting where the two tests disagree; no p where every seed of both arms is a DNF.

    Example:
        >>> format_speedup({"s.verdict": NEITHER, "s.p": 1.0}, "s")
        '— (no test: every seed of both arms is a DNF at the budget) (neither arm reaches the threshold)'
    """
    if row.get(f"{key}.verdict") == NEITHER:
        return f"— (no test: every seed of both arms is a DNF at the budget) ({NEITHER})"
    value = row.get(f"{key}.speedup", math.nan)
    text = f"{value:.2f}x" if math.isfinite(value) else "—"
    low, high = row.get(f"{key}.low", math.nan), row.get(f"{key}.high", math.nan)
    if math.isfinite(low) and math.isfinite(high):
        text += f" [{low:.2f}, {high:.2f}]"
    text += ", " + censored.format_p(row.get(f"{key}.p", math.nan))
    adj = row.get(f"{key}.p_adj", math.nan)
    if isinstance(adj, float) and math.isfinite(adj):
        text += f" (adj. {adj:.2g})"
    text += _logrank_text(row, key)
    return f"{text} ({row.get(f'{key}.verdict', NOT_MEASURED)})"


def _logrank_text(row: dict[str, Any], key: str) -> str:
    p, adj = row.get(f"{key}.logrank_p", math.nan), row.get(f"{key}.logrank_p_adj", math.nan)
    if not (isinstance(p, float) and math.isfinite(p)):
        return ""
    text = f"; log-rank p = {p:.2g}" + (f" (adj. {adj:.2g})" if isinstance(adj, float) and math.isfinite(adj) else "")
    disagree = row.get(f"{key}.tests_disagree", "")
    if disagree:
        text += "; **the tests disagree**: only the " + ("log-rank" if disagree == "log-rank only" else "rank test") \
            + " rejects"
    return text


def format_difference(row: dict[str, Any], key: str, kind: str) -> str:
    """A reliability (``kind="reliability"``, points) or area (``"auc"``, return units) difference with
    its CI, p and verdict, from a map or control row; ``—`` when absent."""
    value = row.get(f"{key}.{kind}_diff", math.nan)
    if not isinstance(value, float) or not math.isfinite(value):
        return "—"
    scale, unit = (100.0, " pts") if kind == "reliability" else (1.0, "")
    low, high = row.get(f"{key}.{kind}_{'diff_low' if kind == 'reliability' else 'low'}", math.nan), row.get(
        f"{key}.{kind}_{'diff_high' if kind == 'reliability' else 'high'}", math.nan)
    shown = [scale * x for x in (value, low, high) if math.isfinite(x)]
    d = 1 if max(abs(x) for x in shown) >= 1 else 3  # a task whose returns span 0..1 (DoorKey) needs more digits
    text = f"{scale * value:+.{d}f}{unit}"
    if math.isfinite(low) and math.isfinite(high):
        text += f" [{scale * low:+.{d}f}, {scale * high:+.{d}f}]"
    return f"{text}, {censored.format_p(row.get(f'{key}.{kind}_p', math.nan))} ({row.get(f'{key}.{kind}_verdict')})"


def controls_markdown(rows: Sequence[dict[str, Any]], top: float, margin: float, ci: float = 0.95,
                      adjust: str = DEFAULT_ADJUST) -> str:
    """The controls' table: each side's seeds reaching ``top`` and steps, the speedup and the area."""
    pct = f"{100 * ci:g}%"
    head = ["Comparison (a vs b)", "Question", f"a: reached {top:g}; steps", f"b: reached {top:g}; steps",
            f"Speedup a / b [{pct} CI], rank p ({adjust}-adj.); log-rank p ({adjust}-adj.) (verdict, margin "
            f"{margin:g}x)", f"Area a - b [{pct} CI], p, not adjusted (verdict)"]
    body = [[r["control"], r["question"], f"{r['a.reached']}/{r['a.n']}; {r['a.steps']:,.0f}",
             f"{r['b.reached']}/{r['b.n']}; {r['b.steps']:,.0f}", format_speedup(r, "cmp"),
             format_difference(r, "cmp", "auc")] for r in rows]
    return "\n".join(tables.markdown_rows(head, body)) + "\n"


def map_markdown(rows: Sequence[dict[str, Any]], top: float, ci: float = 0.95,
                 margin: float = censored.DEFAULT_MARGIN, adjust: str = DEFAULT_ADJUST,
                 registry: Mapping[str, ArmSpec] = ARMS) -> str:
    """The regime map: one line per regime, each arm's reliability and steps to ``top``, both speedups."""
    arms = order_arms(sorted({k.split(".")[0] for r in rows for k in r if k.endswith(".reliability")}), registry)
    pct = f"{100 * ci:g}%"
    head = ["Regime", "Seeds"] + [f"{a}: reliability [{pct} Wilson]; steps to {top:g} [{pct} CI]" for a in arms]
    pairs = [(a, b) for a, b, _ in map_pairs(registry) if any(f"{a}_vs_{b}.speedup" in r for r in rows)]
    head += [f"Speedup {a} / {b} to {top:g} [{pct} CI], rank p ({adjust}-adj.); log-rank p ({adjust}-adj.) "
             f"(verdict, margin {margin:g}x)" for a, b in pairs]
    body = []
    for r in rows:
        cells = [f"`{r['regime']}`", str(r["seeds"])]
        cells += [f"{r.get(f'{a}.reliability_text', '—')}; {r.get(f'{a}.steps_text', '—')}" for a in arms]
        cells += [format_speedup(r, f"{a}_vs_{b}") for a, b in pairs]
        body.append(cells)
    return "\n".join(tables.markdown_rows(head, body)) + "\n"


def _answer(row: dict[str, Any], key: str) -> str:
    """A comparison's verdict in words, with its figures."""
    return f"**{row.get(f'{key}.verdict', NOT_MEASURED)}** ({format_speedup(row, key).rsplit(' (', 1)[0]})"


def summary(rows: Sequence[dict[str, Any]], points: pd.DataFrame, top: float, alpha: float, vlm_regime: str,
            control_rows: Sequence[dict[str, Any]] = (), margin: float = censored.DEFAULT_MARGIN,
            adjust: str = DEFAULT_ADJUST, ci: float = 0.95, registry: Mapping[str, ArmSpec] = ARMS,
            hacking: Mapping[str, str] | None = None, planned: int = 0) -> list[str]:
    """The report's opening: the answers to the study's questions in sentences made from the numbers;
    ``hacking``: each regime's ``hacking_answer``; ``planned``: the finished study's family size."""
    size = family_size(rows, control_rows, registry)
    partial = (_partial_family(planned, size, untestable(rows, control_rows, registry)) if adjust != "none"
               else "")
    lines = [f"- Verdicts on steps to {top:g}: {multiplicity.family_line(adjust, size, FAMILY_WHAT)}{partial}. "
             "Faster/slower "
             f"when the adjusted censored rank test rejects at {alpha:g} and the {100 * ci:g}% interval of the "
             f"speedup excludes 1 on the same side; {censored.equivalent(margin)} when the "
             f"{100 * (1 - 2 * alpha):g}% interval of the speedup lies inside [1/{margin:g}, {margin:g}] (TOST); "
             "otherwise inconclusive, saying which way it leans when the interval or the adjusted test points one "
             f"way. {censored.RULE[0].upper()}{censored.RULE[1:]}."]
    for r in rows:
        rel = ", ".join(f"{a} {r[f'{a}.reached']}/{r[f'{a}.n']}" for a in order_arms(
            [k.split(".")[0] for k in r if k.endswith(".reliability")], registry))
        lines.append(f"- `{r['regime']}` ({r['seeds']} seeds per arm), seeds reaching {top:g}: {rel}.")
        questions = ((f"{METHOD}_vs_{BASELINE}", "Is the hybrid faster than plain PPO?"),
                     (f"{METHOD}_vs_{DENSE}", "Does the VLM add speed beyond the dense term (hybrid vs kinematic)?"),
                     (f"{METHOD}_vs_{PLACEBO_ARM}", "Does the VLM's content matter (hybrid vs the placebo)?"),
                     (f"{DENSE}_vs_{BASELINE}", "Does the dense term alone speed learning (kinematic vs baseline)?"))
        for key, question in questions:
            if f"{key}.verdict" in r and r[f"{key}.verdict"] != NOT_MEASURED:
                lines.append(f"  - {question} {_answer(r, key)}; learning-curve area "
                             f"{format_difference(r, key, 'auc')}.")
        if hacking and hacking.get(r["regime"]):
            lines.append(f"  - {HACKING_QUESTION} {hacking[r['regime']]}")
        if f"{METHOD}_vs_{BASELINE}.reliability_diff" in r:
            lines.append(f"  - Is the hybrid more reliable than plain PPO? hybrid minus baseline "
                         f"{format_difference(r, f'{METHOD}_vs_{BASELINE}', 'reliability')} (Newcombe interval, Fisher "
                         "exact p).")
    for c in control_rows:
        area = format_difference(c, "cmp", "auc")
        lines.append(f"- Control `{c['control']}` ({c['question']}): {_answer(c, 'cmp')}; seeds reaching {top:g}: "
                     f"{c['a.reached']}/{c['a.n']} vs {c['b.reached']}/{c['b.n']}; area {area}.")
    finite = points[np.isfinite(points["speedup"]) & np.isfinite(points["mcq_accuracy"])] if len(points) else points
    if len(finite) >= 3:
        rho = spearman(finite["mcq_accuracy"].to_numpy(), finite["speedup"].to_numpy())
        best, worst = finite.loc[finite["speedup"].idxmax()], finite.loc[finite["speedup"].idxmin()]
        lines.append(f"- **VLM quality** (regime `{vlm_regime}`, {len(finite)} VLM variants): MCQ accuracy "
                     f"{finite['mcq_accuracy'].min():.2f}-{finite['mcq_accuracy'].max():.2f}; the hybrid's speedup "
                     f"ranges from {worst['speedup']:.2f}x ({worst['variant']}) to {best['speedup']:.2f}x "
                     f"({best['variant']}); Spearman rank correlation of speedup with accuracy {rho:.2f} "
                     "(descriptive, over variants).")
    elif len(points):
        lines.append(f"- **VLM quality** (regime `{vlm_regime}`): {len(finite)} variant(s) with a measurable speedup; "
                     "too few for a trend.")
    return lines
