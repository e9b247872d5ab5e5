"""The study's numbers from tracked runs: the regime map, the VLM-quality points, the verdicts and
the plain-language summary. Pure functions of the loaded runs (no training, no MLflow writes).

Every interval reuses the report's statistics: reliability with a Wilson interval and steps to a
threshold as a restricted mean (a DNF at the budget, ``analysis/censored.py``) with a bootstrap CI
(``report/table2.py``), speedups as ratios of restricted means with a bootstrap CI, a censored
Mann-Whitney test and a verdict (faster / slower / equivalent within the margin by TOST /
inconclusive), and the learning-curve area (``report/attribution.py compare_arms``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from vlmrl_cli.analysis import censored, multiplicity, stats
from vlmrl_cli.analysis.load import ExperimentData
from vlmrl_cli.analysis.multiplicity import DEFAULT_ADJUST
from vlmrl_cli.calibration.regimes import Regime
from vlmrl_cli.core import tables
from vlmrl_cli.probe.metrics import spearman
from vlmrl_cli.report import attribution, figures
from vlmrl_cli.report.markdown import format_cell
from vlmrl_cli.report.table2 import (
    build_table2,
    compare_steps,
    order_arms,
    per_seed_table,
    threshold_key,
)
from vlmrl_cli.shaping.arms import ARMS, BASELINE, DENSE, METHOD, NO_LOCK, ArmSpec, comparisons
from vlmrl_cli.study.config import PLACEBO_ARM, Cell
from vlmrl_cli.sweep.multi import runs_of
from vlmrl_cli.training.config import RunConfig

FASTER, SLOWER, INCONCLUSIVE = censored.FASTER, censored.SLOWER, censored.INCONCLUSIVE
NOT_MEASURED = "not measurable"
NEITHER = "neither arm reaches the threshold"
#: The study's family of comparisons, as its Method text names it.
FAMILY_WHAT = ("The study's comparisons of steps to the top threshold (each regime's map pairs and each "
               "control)")


def map_pairs(registry: Mapping[str, ArmSpec] = ARMS) -> tuple[tuple[str, str, str], ...]:
    """The comparisons of the regime map: (arm a, arm b, what the difference isolates), those of
    ``registry`` that the study makes (``Comparison.in_study``), in the report's order.

    Example:
        >>> [f"{a}_vs_{b}" for a, b, _ in map_pairs()][-3:]
        ['kinematic_vs_baseline', 'hybrid-dense-pbrs_vs_baseline', 'hybrid-dense-pbrs_vs_hybrid']
    """
    return tuple(comparisons(registry, study=True))


MAP_PAIRS = map_pairs()


def _restrict(data: ExperimentData, runs: pd.DataFrame) -> ExperimentData:
    ids = set(runs["run_id"])
    evals = data.eval_episodes
    return dataclasses.replace(data, runs=runs.reset_index(drop=True),
                               episodes=data.episodes[data.episodes["run_id"].isin(ids)],
                               eval_episodes=evals[evals["run_id"].isin(ids)] if len(evals) else evals)


def subset(data: ExperimentData, run: RunConfig) -> ExperimentData:
    """The runs of ``data`` that are jobs of ``run`` (arm, seed and config hash), with their episodes."""
    return _restrict(data, runs_of(data.runs, run))


def paired(data: ExperimentData, reference: RunConfig, variant: RunConfig) -> ExperimentData:
    """The baseline runs of ``reference`` and the runs of ``variant`` (a VLM variant's hybrid)."""
    ref = runs_of(data.runs, reference)
    runs = pd.concat([ref[ref["arm"] == BASELINE], runs_of(data.runs, variant)]).drop_duplicates("run_id")
    return _restrict(data, runs)


def _pair_columns(key: str, comparisons: pd.DataFrame, a: str, b: str, top: float, none_reach: bool
                  ) -> dict[str, Any]:
    """The map's columns of one comparison: speedup, CI, p, verdict, TOST interval; reliability and
    learning-curve area differences with their verdicts."""
    def get(metric: str) -> dict[str, Any] | None:
        hit = comparisons[(comparisons["pair"] == f"{a} vs {b}") & (comparisons["metric"] == metric)]
        return None if hit.empty else dict(hit.iloc[0])

    steps, rel, auc = get(f"speedup_{top:g}"), get("reliability_diff"), get("auc_diff")
    if steps is None:
        return {f"{key}.speedup": math.nan, f"{key}.low": math.nan, f"{key}.high": math.nan, f"{key}.p": math.nan,
                f"{key}.verdict": NOT_MEASURED}
    out = {f"{key}.speedup": steps["value"], f"{key}.low": steps["ci_low"], f"{key}.high": steps["ci_high"],
           f"{key}.p": steps["p_value"], f"{key}.p_adj": math.nan, f"{key}.logrank_p": steps["logrank_p"],
           f"{key}.logrank_p_adj": math.nan, f"{key}.tests_disagree": "", f"{key}.test": steps["test"],
           f"{key}.tost_low": steps["tost_low"], f"{key}.tost_high": steps["tost_high"],
           f"{key}.direction": steps["direction"], f"{key}.equivalence_ok": bool(steps["equivalence_ok"]),
           f"{key}.verdict": NEITHER if none_reach else steps["verdict"]}
    if rel is not None:
        out |= {f"{key}.reliability_diff": rel["value"], f"{key}.reliability_diff_low": rel["ci_low"],
                f"{key}.reliability_diff_high": rel["ci_high"], f"{key}.reliability_p": rel["p_value"],
                f"{key}.reliability_verdict": rel["verdict"]}
    if auc is not None:
        out |= {f"{key}.auc_diff": auc["value"], f"{key}.auc_low": auc["ci_low"], f"{key}.auc_high": auc["ci_high"],
                f"{key}.auc_p": auc["p_value"], f"{key}.auc_verdict": auc["verdict"]}
    return out


def regime_row(name: str, data: ExperimentData, thresholds: Sequence[float], streams: stats.Streams,
               n_boot: int = stats.DEFAULT_N_BOOT, ci: float = 0.95, alpha: float = 0.05,
               margin: float = censored.DEFAULT_MARGIN, window: int = 100,
               auc_delta: float = attribution.DEFAULT_AUC_DELTA, registry: Mapping[str, ArmSpec] = ARMS
               ) -> tuple[dict[str, Any], pd.DataFrame]:
    """One regime's row of the map (per arm: reliability and restricted mean steps to the top
    threshold with CIs; per ``map_pairs(registry)`` pair: speedup, CI, rank-test p and verdict,
    reliability and learning-curve area differences) and its per-seed table."""
    top = max(thresholds)
    per_seed = per_seed_table(data, thresholds, window)
    table = build_table2(per_seed, data.eval_episodes, {}, thresholds, streams, window=window, n_boot=n_boot, ci=ci,
                         registry=registry)
    pairs = [attribution.Pair(a, b, meaning) for a, b, meaning in map_pairs(registry)
             if a in set(per_seed["arm"]) and b in set(per_seed["arm"])]
    comparisons = attribution.compare_arms(per_seed, thresholds, streams, n_boot, ci, alpha=alpha, margin=margin,
                                           pairs=pairs, adjust="none",  # the family spans regimes: adjust_family
                                           auc_delta=auc_delta)
    row: dict[str, Any] = {"regime": name, "seeds": int(per_seed.groupby("arm").size().max())}
    for arm in table.arms:
        rel, steps = table.cell("reliability", arm), table.cell(threshold_key(top), arm)
        assert rel is not None and steps is not None
        row |= {f"{arm}.reliability": rel["value"], f"{arm}.reliability_low": rel["ci_low"],
                f"{arm}.reliability_high": rel["ci_high"], f"{arm}.reached": int(rel["n_reached"]),
                f"{arm}.n": int(rel["n"]),
                f"{arm}.steps": steps["value"], f"{arm}.steps_low": steps["ci_low"],
                f"{arm}.steps_high": steps["ci_high"], f"{arm}.reliability_text": format_cell(rel),
                f"{arm}.steps_text": format_cell(steps)}
    for a, b, _ in map_pairs(registry):
        none_reach = row.get(f"{a}.reached", 0) == 0 and row.get(f"{b}.reached", 0) == 0
        row |= _pair_columns(f"{a}_vs_{b}", comparisons, a, b, top, none_reach)
    return row, per_seed


@dataclass(frozen=True)
class Control:
    """A comparison of two control cells: ``a`` (the cell with the VLM's labels, or the lock) against
    ``b`` (its reference), and what the difference isolates."""

    name: str
    question: str
    a: Cell
    b: Cell


def _jobs(run: RunConfig, arm: str) -> frozenset[tuple[str, int, str]]:
    return frozenset((j.arm.name, j.seed, j.config_hash) for j in run.jobs() if j.arm.name == arm)


def map_twin(control: Control, regimes: Sequence[Regime], registry: Mapping[str, ArmSpec] = ARMS) -> str | None:
    """The regime-map comparison that ``control`` repeats (the same two arms on the same jobs: a
    dose point that is the hybrid's own regime against the kinematic arm), as ``"R1: hybrid vs
    kinematic"``; None when it repeats none. Such a control is listed, and counted, once."""
    for regime in regimes:
        for a, b, _ in map_pairs(registry):
            if (control.a.arm, control.b.arm) == (a, b) and _jobs(control.a.regime.run, a) == _jobs(regime.run, a) \
                    and _jobs(control.b.regime.run, b) == _jobs(regime.run, b):
                return f"{regime.id}: {a} vs {b}"
    return None


def controls(cells: Sequence[Cell], regimes: Sequence[Regime] = ()) -> list[Control]:
    """The comparisons the control cells exist for: each dose cell with a potential against the dense
    term alone at the same kinematic scale (does the VLM's potential help, by dose?); each VLM dose
    cell against its placebo (is it the labels' content?); the hybrid against hybrid-no-lock under
    the same per-query flicker (what the lock is for). A control that repeats a comparison of one of
    ``regimes``' maps (``map_twin``) is left out: the map lists it."""
    return [c for c in _controls(cells) if map_twin(c, regimes) is None]


def twin_lines(cells: Sequence[Cell], regimes: Sequence[Regime]) -> list[str]:
    """The summary's line for each control left out as a repeat of a map comparison."""
    return [f"- Control `{c.name}` is the map's `{twin}` (the same runs): listed and counted there, once."
            for c in _controls(cells) if (twin := map_twin(c, regimes)) is not None]


def _controls(cells: Sequence[Cell]) -> list[Control]:
    dose = [c for c in cells if c.kind == "dose"]
    out = []
    for c in dose:
        if c.placebo or c.alpha == 0:
            continue
        dense = next((d for d in dose if d.kin_scale == c.kin_scale and d.alpha == 0 and not d.placebo), None)
        if dense is not None:
            out.append(Control(f"alpha={c.alpha:g} kin={c.kin_scale:g} vs alpha=0",
                               "does the VLM's potential help at this dose?", c, dense))
        placebo = next((d for d in dose if d.placebo and (d.alpha, d.kin_scale) == (c.alpha, c.kin_scale)), None)
        if placebo is not None:
            out.append(Control(f"alpha={c.alpha:g} kin={c.kin_scale:g} vs its placebo",
                               "is it the labels' content?", c, placebo))
    flicker = [c for c in cells if c.kind == "query-flicker"]
    for c in flicker:
        if c.arm != METHOD:
            continue
        other = next((d for d in flicker if d.arm == NO_LOCK and d.query_flicker == c.query_flicker), None)
        if other is not None:
            out.append(Control(f"query flicker {c.query_flicker:g}: {METHOD} vs {NO_LOCK}",
                               "what the hysteresis lock is for", c, other))
    return out


def control_row(control: Control, data: ExperimentData, thresholds: Sequence[float], streams: stats.Streams,
                n_boot: int = stats.DEFAULT_N_BOOT, ci: float = 0.95, alpha: float = 0.05,
                margin: float = censored.DEFAULT_MARGIN, window: int = 100,
                auc_delta: float = attribution.DEFAULT_AUC_DELTA) -> dict[str, Any]:
    """One control comparison's row: each side's arm, knobs, seeds reaching the top threshold and
    restricted mean steps, then the comparison's columns (as the regime map's)."""
    top = max(thresholds)
    a_runs, b_runs = runs_of(data.runs, control.a.regime.run), runs_of(data.runs, control.b.regime.run)
    both = _restrict(data, pd.concat([a_runs, b_runs]).drop_duplicates("run_id"))
    per_seed = per_seed_table(both, thresholds, window)
    a, b = control.a.arm, control.b.arm
    pair = attribution.Pair(a, b, control.question)
    comparisons = attribution.compare_arms(per_seed, thresholds, streams, n_boot, ci, alpha=alpha, margin=margin,
                                           pairs=[pair], adjust="none",  # the family spans controls: adjust_family
                                           auc_delta=auc_delta)
    row: dict[str, Any] = {"control": control.name, "question": control.question, "a": control.a.regime.id,
                           "b": control.b.regime.id, "a.arm": a, "b.arm": b}
    key = threshold_key(top)
    for side, arm in (("a", a), ("b", b)):
        d = per_seed[per_seed["arm"] == arm]
        steps, budget = d[key].to_numpy(dtype=float), d["budget"].to_numpy(dtype=float)
        row |= {f"{side}.n": len(d), f"{side}.reached": int(censored.reached(steps, budget).sum()),
                f"{side}.steps": censored.restricted_mean(steps, budget).value,
                f"{side}.auc": float(d["auc"].mean()) if len(d) else math.nan}
    none_reach = row["a.reached"] == 0 and row["b.reached"] == 0
    return row | _pair_columns("cmp", comparisons, a, b, top, none_reach)


def family_keys(map_rows: Sequence[dict[str, Any]], control_rows: Sequence[dict[str, Any]],
                registry: Mapping[str, ArmSpec] = ARMS) -> list[tuple[str, int, str]]:
    """Where the study's comparisons of steps to the top threshold sit: ``("map" | "control", row
    index, column key)`` for each regime's ``map_pairs(registry)`` pair and each control, in table order."""
    found = [("map", i, f"{a}_vs_{b}") for i, r in enumerate(map_rows) for a, b, _ in map_pairs(registry)
             if f"{a}_vs_{b}.speedup" in r]
    return found + [("control", i, "cmp") for i, r in enumerate(control_rows) if "cmp.speedup" in r]


def _made(row: dict[str, Any], key: str) -> bool:
    """A comparison was made: both sides ran and at least one reached the threshold (a finite speedup)."""
    value = row.get(f"{key}.speedup", math.nan)
    return row.get(f"{key}.verdict") not in (NOT_MEASURED, NEITHER) and isinstance(value, float) and math.isfinite(
        value)


def adjust_family(map_rows: Sequence[dict[str, Any]], control_rows: Sequence[dict[str, Any]],
                  method: str = DEFAULT_ADJUST, alpha: float = 0.05, margin: float = censored.DEFAULT_MARGIN,
                  registry: Mapping[str, ArmSpec] = ARMS) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The study's comparisons of steps to the top threshold (every regime's map pairs and every
    control) as one family: copies of the rows with ``.p_adj``, ``.logrank_p_adj``,
    ``.tests_disagree`` and the ``.verdict`` judged on the adjusted p (``censored.judge_family``).
    A comparison not made (a side absent, or neither arm reaching the threshold) stays out."""
    rows = {"map": [dict(r) for r in map_rows], "control": [dict(r) for r in control_rows]}
    keys = [(table, i, key) for table, i, key in family_keys(map_rows, control_rows, registry)
            if _made(rows[table][i], key)]
    if not keys:
        return rows["map"], rows["control"]

    def col(name: str) -> list[float]:
        return [float(rows[t][i][f"{k}.{name}"]) for t, i, k in keys]

    judged = censored.judge_family(col("p"), col("logrank_p"), col("direction"),
                                   list(zip(col("low"), col("high"), strict=True)),
                                   list(zip(col("tost_low"), col("tost_high"), strict=True)),
                                   [bool(rows[t][i][f"{k}.equivalence_ok"]) for t, i, k in keys], method, alpha,
                                   margin)
    for n, (t, i, k) in enumerate(keys):
        rows[t][i] |= {f"{k}.p_adj": float(judged.p_adjusted[n]),
                       f"{k}.logrank_p_adj": float(judged.logrank_adjusted[n]),
                       f"{k}.tests_disagree": judged.disagreement[n], f"{k}.verdict": judged.verdicts[n]}
    return rows["map"], rows["control"]


def _count(map_rows: Sequence[dict[str, Any]], control_rows: Sequence[dict[str, Any]],
           registry: Mapping[str, ArmSpec], keep: Callable[[dict[str, Any], str], bool]) -> int:
    """How many of the family's comparisons (``family_keys``) ``keep`` accepts."""
    tables_ = {"map": map_rows, "control": control_rows}
    return sum(keep(tables_[t][i], k) for t, i, k in family_keys(map_rows, control_rows, registry))


def family_size(map_rows: Sequence[dict[str, Any]], control_rows: Sequence[dict[str, Any]],
                registry: Mapping[str, ArmSpec] = ARMS) -> int:
    """How many comparisons the study's family holds (those made)."""
    return _count(map_rows, control_rows, registry, _made)


def untestable(map_rows: Sequence[dict[str, Any]], control_rows: Sequence[dict[str, Any]],
               registry: Mapping[str, ArmSpec] = ARMS) -> int:
    """How many of the family's comparisons were measured but have no test: every seed of both arms
    is a DNF at the budget, so they cannot reject and are left out of the adjustment."""
    return _count(map_rows, control_rows, registry, lambda row, key: row.get(f"{key}.verdict") == NEITHER)


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
    map row; a note where the rank test and the log-rank disagree after adjustment. Where neither arm
    reached the threshold no test says anything (every seed ties as a DNF): no p is printed.

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
    """The control comparisons: each side's seeds reaching ``top`` and restricted mean steps, the
    speedup of a over b with its verdict, the learning-curve area difference with its verdict."""
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


def vlm_point(name: str, data: ExperimentData, top: float, accuracy: float, streams: stats.Streams,
              n_boot: int = stats.DEFAULT_N_BOOT, ci: float = 0.95) -> dict[str, Any]:
    """One VLM-quality point: the variant's measured MCQ accuracy and the hybrid's speedup over the
    baseline to ``top`` (``data``: the reference regime's baseline runs and the variant's hybrid runs)."""
    per_seed = per_seed_table(data, [top])
    est, test = compare_steps(per_seed, METHOD, BASELINE, top, streams, n_boot, ci)
    return {"variant": name, "mcq_accuracy": accuracy, "speedup": est.value, "low": est.low, "high": est.high,
            "p": test.p_value, "hybrid_seeds": int((per_seed["arm"] == METHOD).sum()),
            "baseline_seeds": int((per_seed["arm"] == BASELINE).sum())}


def vlm_figure(points: pd.DataFrame, top: float, regime: str, simulated: bool) -> Figure:
    """The hybrid's speedup over the baseline (with its CI) against the VLM's measured MCQ accuracy."""
    fig = Figure(figsize=(figures.WIDTH_IN, 3.6), layout="constrained")
    ax = fig.subplots()
    for r in points.itertuples(index=False):
        y = r.speedup if math.isfinite(r.speedup) else np.nan
        err = [[y - r.low if math.isfinite(r.low) else 0.0], [r.high - y if math.isfinite(r.high) else 0.0]]
        ax.errorbar([r.mcq_accuracy], [y], yerr=err, fmt="o", capsize=3)
        ax.annotate(str(r.variant), (r.mcq_accuracy, y if math.isfinite(y) else 1.0), fontsize=figures.SMALL,
                    xytext=(4, 4), textcoords="offset points")
    ax.axhline(1.0, color="gray", linestyle="--", linewidth=0.7)
    ax.set_xlabel("MCQ accuracy of the VLM (vlmrl taxonomy, same knobs)", fontsize=figures.SMALL + 1)
    ax.set_ylabel(f"speedup to {top:g}, hybrid / baseline", fontsize=figures.SMALL + 1)
    title = f"VLM quality vs the hybrid's speedup, regime {regime}"
    fig.suptitle(title + (" — SIMULATED VLM, not a real model" if simulated else ""), fontsize=figures.SMALL + 1)
    return fig


def _names(rows: Sequence[dict[str, Any]], key: str, wanted: str) -> list[str]:
    return [f"`{r['regime']}`" for r in rows if r.get(f"{key}.verdict") == wanted]


def _answer(row: dict[str, Any], key: str) -> str:
    """A comparison's verdict in words, with its figures."""
    return f"**{row.get(f'{key}.verdict', NOT_MEASURED)}** ({format_speedup(row, key).rsplit(' (', 1)[0]})"


def summary(rows: Sequence[dict[str, Any]], points: pd.DataFrame, top: float, alpha: float, vlm_regime: str,
            control_rows: Sequence[dict[str, Any]] = (), margin: float = censored.DEFAULT_MARGIN,
            adjust: str = DEFAULT_ADJUST, ci: float = 0.95, registry: Mapping[str, ArmSpec] = ARMS,
            hacking: Mapping[str, str] | None = None, planned: int = 0) -> list[str]:
    """The report's opening: the answers to the study's questions, in sentences made from the numbers.
    Every verdict follows ``censored.judge_speedup`` on the rank test's p adjusted within the study's
    family (``adjust_family``): faster / slower, equivalent within ``margin``, or inconclusive
    (saying which way it leans). ``hacking``: each regime's ``hacking_answer``; ``planned``: the
    family the finished study will hold (the power line's), said when fewer were measured."""
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


#: The question the potential-form arm answers (issue 41): a verdict line of every study that has it.
HACKING_QUESTION = "Does the dense term in potential form remove the hacking?"


def _share_comparison(a: np.ndarray, b: np.ndarray, rng: np.random.Generator, n_boot: int, ci: float
                      ) -> tuple[stats.Estimate, float]:
    """Mean per-seed failure share of ``a`` minus ``b``, with its bootstrap interval (seeds resampled),
    and the two-sided Mann-Whitney p on the seeds' shares (NaN when every seed of both arms ties)."""
    from vlmrl_cli.analysis.ranks import censored_rank_test

    diff = stats.difference_of_means(a, b, rng, n_boot, ci)
    tied = np.unique(np.concatenate([a, b])).size <= 1
    return diff, float("nan") if tied else censored_rank_test(a, b, rng).p_value


def hacking_answer(per_seed: pd.DataFrame, rng: np.random.Generator, alpha: float = 0.05,
                   n_boot: int = stats.DEFAULT_N_BOOT, ci: float = 0.95) -> str | None:
    """One regime's answer to ``HACKING_QUESTION``, the seed the unit: each seed's share of detached
    evaluation episodes that failed (1 - ``eval_success_rate``; a policy farming the dense term runs
    out the clock). The hybrid hacks when its share is above the baseline's (rank test at ``alpha``
    and the interval of the difference above 0); the potential form removes it when its share is then
    below the hybrid's and not above the baseline's on the same rule. None when an arm is missing.

    Example:
        >>> seeds = pd.DataFrame({"arm": ["baseline"] * 4 + ["hybrid"] * 4 + ["hybrid-dense-pbrs"] * 4,
        ...                       "eval_success_rate": [1, 1, 1, 1, .2, .3, .1, .2, 1, 1, .9, 1]})
        >>> hacking_answer(seeds, np.random.default_rng(0), n_boot=200).split(":")[0]
        '**removed**'
    """
    from vlmrl_cli.shaping.arms import DENSE_POTENTIAL

    share = {arm: 1.0 - per_seed.loc[per_seed["arm"] == arm, "eval_success_rate"].to_numpy(dtype=float)
             for arm in (BASELINE, METHOD, DENSE_POTENTIAL)}
    if any(v.size < 2 for v in share.values()):
        return None
    vs = {pair: _share_comparison(share[pair[0]], share[pair[1]], rng, n_boot, ci)
          for pair in ((METHOD, BASELINE), (DENSE_POTENTIAL, METHOD), (DENSE_POTENTIAL, BASELINE))}

    def above(pair: tuple[str, str]) -> bool:
        diff, p = vs[pair]
        return math.isfinite(p) and p < alpha and diff.value > 0 and diff.low > 0

    def below(pair: tuple[str, str]) -> bool:
        diff, p = vs[pair]
        return math.isfinite(p) and p < alpha and diff.value < 0 and diff.high < 0

    hybrid_hacks = above((METHOD, BASELINE))
    if not hybrid_hacks:
        word = "no hacking to remove"
    elif below((DENSE_POTENTIAL, METHOD)) and not above((DENSE_POTENTIAL, BASELINE)):
        word = "removed"
    elif above((DENSE_POTENTIAL, BASELINE)):
        word = "not removed"
    else:
        word = "cannot tell"
    worse = " The potential form fails more often than the hybrid." if above((DENSE_POTENTIAL, METHOD)) else ""

    def text(pair: tuple[str, str]) -> str:
        diff, p = vs[pair]
        shown = "no seed failed in either arm: no test" if not math.isfinite(p) else f"Mann-Whitney p {p:.2g}"
        return (f"{100 * diff.value:+.1f} points [{100 * diff.low:+.1f}, {100 * diff.high:+.1f}], {shown}"
                if diff.has_ci else f"{100 * diff.value:+.1f} points ({diff.note})")

    means = ", ".join(f"{arm} {100 * share[arm].mean():.1f}%" for arm in (BASELINE, METHOD, DENSE_POTENTIAL))
    return (f"**{word}**: mean share of failed detached episodes per seed {means}; hybrid minus baseline "
            f"{text((METHOD, BASELINE))}; potential form minus hybrid {text((DENSE_POTENTIAL, METHOD))} "
            f"({100 * ci:g}% bootstrap intervals over seeds, unadjusted: not in the speed family).{worse}")
