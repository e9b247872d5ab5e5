"""The study's numbers from tracked runs: the regime map's and the controls' rows (the report's
statistics, ``report/table2.py`` and ``report/attribution.py``), the family's adjustment, the
VLM-quality points and the reward-hacking answer. Pure functions of the loaded runs.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from vlmrl_cli.analysis import censored, stats
from vlmrl_cli.analysis.load import ExperimentData
from vlmrl_cli.analysis.multiplicity import DEFAULT_ADJUST
from vlmrl_cli.analysis.ranks import censored_rank_test
from vlmrl_cli.calibration.regimes import Regime
from vlmrl_cli.report import attribution
from vlmrl_cli.report.markdown import format_cell
from vlmrl_cli.report.table2 import (
    build_table2,
    compare_steps,
    per_seed_table,
    threshold_key,
)
from vlmrl_cli.shaping.arms import ARMS, BASELINE, DENSE_POTENTIAL, METHOD, NO_LOCK, ArmSpec, comparisons
from vlmrl_cli.study.config import Cell
from vlmrl_cli.sweep.multi import runs_of
from vlmrl_cli.training.config import RunConfig

FASTER, SLOWER, INCONCLUSIVE = censored.FASTER, censored.SLOWER, censored.INCONCLUSIVE
NOT_MEASURED = "not measurable"
NEITHER = "neither arm reaches the threshold"
#: The study's family of comparisons, as its Method text names it.
FAMILY_WHAT = ("The study's comparisons of steps to the top threshold (each regime's map pairs and each "
               "control)")


def map_pairs(registry: Mapping[str, ArmSpec] = ARMS) -> tuple[tuple[str, str, str], ...]:
    """The regime map's (arm a, arm b, what it isolates) of ``registry`` (``in_study``), in report order.

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
    """The map's columns of one comparison: steps (speedup, CI, p, verdict), reliability and area."""
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
    threshold; per ``map_pairs(registry)`` pair: ``_pair_columns``) and its per-seed table."""
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
    """A comparison of control cell ``a`` against its reference ``b``, and what it isolates."""

    name: str
    question: str
    a: Cell
    b: Cell


def _jobs(run: RunConfig, arm: str) -> frozenset[tuple[str, int, str]]:
    return frozenset((j.arm.name, j.seed, j.config_hash) for j in run.jobs() if j.arm.name == arm)


def map_twin(control: Control, regimes: Sequence[Regime], registry: Mapping[str, ArmSpec] = ARMS) -> str | None:
    """The regime-map comparison that ``control`` repeats (the same arms on the same jobs), as
    ``"R1: hybrid vs kinematic"``; None when it repeats none."""
    for regime in regimes:
        for a, b, _ in map_pairs(registry):
            if (control.a.arm, control.b.arm) == (a, b) and _jobs(control.a.regime.run, a) == _jobs(regime.run, a) \
                    and _jobs(control.b.regime.run, b) == _jobs(regime.run, b):
                return f"{regime.id}: {a} vs {b}"
    return None


def controls(cells: Sequence[Cell], regimes: Sequence[Regime] = ()) -> list[Control]:
    """The comparisons the control cells exist for (each dose against alpha 0 and against its placebo,
    the hybrid against hybrid-no-lock), less those that repeat a map comparison (``map_twin``)."""
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
    """One control's row: each side's arm, reached seeds and restricted mean steps, then the comparison."""
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
    """Where the family's comparisons sit: ``("map" | "control", row index, column key)``, in table order."""
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
    """Copies of the rows with the family's comparisons made (``_made``) adjusted as one and re-judged
    (``censored.judge_family``): ``.p_adj``, ``.logrank_p_adj``, ``.tests_disagree``, ``.verdict``."""
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
    """How many of the family's comparisons have no test (every seed of both arms a DNF)."""
    return _count(map_rows, control_rows, registry, lambda row, key: row.get(f"{key}.verdict") == NEITHER)


def vlm_point(name: str, data: ExperimentData, top: float, accuracy: float, ci: float = 0.95) -> dict[str, Any]:
    """One VLM-quality point: the variant's MCQ accuracy and the hybrid's speedup (``data``: ``paired``)."""
    per_seed = per_seed_table(data, [top])
    est, test = compare_steps(per_seed, METHOD, BASELINE, top, ci)
    return {"variant": name, "mcq_accuracy": accuracy, "speedup": est.value, "low": est.low, "high": est.high,
            "p": test.p_value, "hybrid_seeds": int((per_seed["arm"] == METHOD).sum()),
            "baseline_seeds": int((per_seed["arm"] == BASELINE).sum())}


def _share_comparison(a: np.ndarray, b: np.ndarray, rng: np.random.Generator, n_boot: int, ci: float
                      ) -> tuple[stats.Estimate, float]:
    """Mean per-seed failure share of ``a`` minus ``b`` with its bootstrap interval, and the two-sided
    Mann-Whitney p on the shares (NaN when every seed ties)."""
    diff = stats.difference_of_means(a, b, rng, n_boot, ci)
    tied = np.unique(np.concatenate([a, b])).size <= 1
    return diff, float("nan") if tied else censored_rank_test(a, b).p_value


def hacking_answer(per_seed: pd.DataFrame, rng: np.random.Generator, alpha: float = 0.05,
                   n_boot: int = stats.DEFAULT_N_BOOT, ci: float = 0.95) -> str | None:
    """One regime's answer to ``markdown.HACKING_QUESTION`` on each seed's share of failed detached
    episodes, by the rule of docs/commands/study.md; None when an arm is missing.
    """
    share = {arm: 1.0 - per_seed.loc[per_seed["arm"] == arm, "eval_success_rate"].to_numpy(dtype=float)
             for arm in (BASELINE, METHOD, DENSE_POTENTIAL)}
    if any(v.size < 2 for v in share.values()):
        return None
    vs = {pair: _share_comparison(share[pair[0]], share[pair[1]], rng, n_boot, ci)
          for pair in ((METHOD, BASELINE), (DENSE_POTENTIAL, METHOD), (DENSE_POTENTIAL, BASELINE))}

    def beyond(pair: tuple[str, str], side: int) -> bool:
        """Whether ``pair[0]``'s share is above (``side`` 1) or below (-1) ``pair[1]``'s, test and interval."""
        diff, p = vs[pair]
        bound = diff.low if side > 0 else diff.high
        return math.isfinite(p) and p < alpha and side * diff.value > 0 and side * bound > 0

    if not beyond((METHOD, BASELINE), 1):
        word = "no hacking to remove"
    elif beyond((DENSE_POTENTIAL, METHOD), -1) and not beyond((DENSE_POTENTIAL, BASELINE), 1):
        word = "removed"
    elif beyond((DENSE_POTENTIAL, BASELINE), 1):
        word = "not removed"
    else:
        word = "cannot tell"
    worse = " The potential form fails more often than the hybrid." if beyond((DENSE_POTENTIAL, METHOD), 1) else ""

    def text(pair: tuple[str, str]) -> str:
        diff, p = vs[pair]
        shown = "no seed failed in either arm: no test" if not math.isfinite(p) else f"Mann-Whitney p {p:.2g}"
        return (f"{100 * diff.value:+.1f} points [{100 * diff.low:+.1f}, {100 * diff.high:+.1f}], {shown}"
                if diff.has_ci else f"{100 * diff.value:+.1f} points ({diff.note})")

    means = ", ".join(f"{arm} {100 * share[arm].mean():.1f}%" for arm in (BASELINE, METHOD, DENSE_POTENTIAL))
    return (f"**{word}**: mean share of failed detached episodes per seed {means}; hybrid minus baseline "
            f"{text((METHOD, BASELINE))}; potential form minus hybrid {text((DENSE_POTENTIAL, METHOD))} "
            f"({100 * ci:g}% bootstrap intervals over seeds, unadjusted: not in the speed family).{worse}")
