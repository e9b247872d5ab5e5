"""Table 2 of the paper (steps to reward thresholds, final reliability), ours beside the paper's.

``per_seed_table`` turns loaded runs into one row per (arm, seed); ``build_table2`` summarises
it per arm (mean over seeds that reached each threshold with a bootstrap CI, DNF counts,
speedup over ``baseline``, reliability with a Wilson CI, detached evaluation, final-return IQM
and spread); ``to_markdown`` / ``to_latex`` / ``to_csv`` render it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from vlmrl_cli.analysis import stats
from vlmrl_cli.analysis.load import ExperimentData
from vlmrl_cli.analysis.thresholds import steps_to_threshold
from vlmrl_cli.shaping.arms import ARMS

BASELINE = "baseline"
NEEDS_BASELINE = "needs baseline arm"


def order_arms(arms: Sequence[str]) -> list[str]:
    """The paper's order (hybrid, baseline), then the registry's, then any others alphabetically.

    Example:
        >>> order_arms(["kinematic", "zeta", "baseline", "hybrid"])
        ['hybrid', 'baseline', 'kinematic', 'zeta']
    """
    known = ["hybrid", "baseline", *[a for a in ARMS if a not in ("hybrid", "baseline")]]
    present = set(arms)
    return [a for a in known if a in present] + sorted(present - set(known))


def threshold_key(threshold: float) -> str:
    """Column/metric name of a threshold, e.g. ``steps_-130``."""
    return f"steps_{threshold:g}"


def per_seed_table(data: ExperimentData, thresholds: Sequence[float], window: int = 100,
                   min_episodes: int = 1) -> pd.DataFrame:
    """One row per run: arm, seed, run_id, config_hash, budget, steps to each threshold (NaN = DNF),
    final return (mean of the last ``window`` episodes), number of episodes and the eval metrics."""
    rows = []
    by_run = dict(tuple(data.episodes.groupby("run_id", sort=False)))
    for run in data.runs.itertuples(index=False):
        ep = by_run.get(run.run_id, data.episodes.iloc[0:0]).sort_values("timestep", kind="stable")
        ts, ret = ep["timestep"].to_numpy(dtype=np.int64), ep["native_return"].to_numpy(dtype=float)
        row: dict[str, Any] = {"arm": run.arm, "seed": run.seed, "run_id": run.run_id,
                               "config_hash": run.config_hash, "preset": run.preset, "budget": run.budget}
        for t in thresholds:
            s = steps_to_threshold(ts, ret, t, window, min_episodes)
            row[threshold_key(t)] = float("nan") if s is None else float(s)
        row["final_return"] = stats.final_return(ret, window)
        row["episodes"] = len(ep)
        row["eval_success_rate"] = run.eval_success_rate
        row["eval_mean_length"] = run.eval_mean_length
        row["eval_mean_return"] = run.eval_mean_return
        rows.append(row)
    return pd.DataFrame(rows)


@dataclass(frozen=True)
class Table2:
    """Per-arm results. ``cells``: one row per (metric, arm) with value, CI, counts, paper value.
    ``speedups``: one row per (threshold, arm != baseline). ``labels``: metric -> row label."""

    arms: tuple[str, ...]
    thresholds: tuple[float, ...]
    cells: pd.DataFrame
    speedups: pd.DataFrame
    labels: dict[str, str]
    ci: float
    paper: dict[str, dict[str, Any]]

    @property
    def has_baseline(self) -> bool:
        return BASELINE in self.arms

    def cell(self, metric: str, arm: str) -> dict[str, Any] | None:
        hit = self.cells[(self.cells["metric"] == metric) & (self.cells["arm"] == arm)]
        return None if hit.empty else dict(hit.iloc[0])

    def speedup(self, threshold: float, arm: str) -> dict[str, Any] | None:
        hit = self.speedups[(self.speedups["metric"] == threshold_key(threshold)) & (self.speedups["arm"] == arm)]
        return None if hit.empty else dict(hit.iloc[0])


def _paper_steps(reported: dict[str, Any], threshold: float) -> dict[str, Any]:
    for row in reported.get("table2", {}).get("steps_to_threshold", []):
        if float(row["threshold"]) == float(threshold):
            return dict(row)
    return {}


def _paper_values(reported: dict[str, Any], metric: str, thresholds: Sequence[float]) -> dict[str, Any]:
    """{arm: value, "speedup": value} the paper reports for ``metric``."""
    for t in thresholds:
        if metric == threshold_key(t):
            return _paper_steps(reported, t)
    if metric == "reliability":
        return dict(reported.get("table2", {}).get("final_reliability", {}))
    if metric == "eval_success":
        return dict(reported.get("detached_evaluation", {}).get("success_rate", {}))
    if metric == "eval_length":
        return dict(reported.get("detached_evaluation", {}).get("mean_episode_length", {}))
    return {}


def _cell(metric: str, arm: str, est: stats.Estimate, paper: Any, n: int, n_reached: int | None = None) -> dict:
    return {"metric": metric, "arm": arm, "value": est.value, "ci_low": est.low, "ci_high": est.high, "n": n,
            "n_reached": n_reached, "paper": float(paper) if paper is not None else float("nan"), "note": est.note}


def build_table2(
    per_seed: pd.DataFrame,
    eval_episodes: pd.DataFrame,
    reported: dict[str, Any],
    thresholds: Sequence[float],
    rng: np.random.Generator,
    window: int = 100,
    ci: float = 0.95,
    n_boot: int = stats.DEFAULT_N_BOOT,
) -> Table2:
    """Table 2 from ``per_seed`` (see ``per_seed_table``) and per-episode eval lengths (may be empty).

    Reliability is the fraction of seeds that reached the highest threshold (the paper: -130).
    Detached eval mean length uses the per-episode lengths when logged (pooled over seeds),
    else one value per seed.
    """
    arms = tuple(order_arms(per_seed["arm"].unique().tolist()))
    top = max(thresholds)
    labels = {threshold_key(t): f"Steps to reach {t:g}" for t in thresholds}
    labels |= {
        "reliability": f"Final reliability (seeds reaching {top:g})",
        "eval_success": "Detached eval success rate",
        "eval_length": "Detached eval mean episode length",
        "final_iqm": f"Final return IQM (last {window} episodes)",
        "final_std": "Final return std across seeds",
    }
    cells: list[dict[str, Any]] = []
    steps_by_arm: dict[str, dict[float, np.ndarray]] = {}
    for arm in arms:
        d = per_seed[per_seed["arm"] == arm]
        n = len(d)
        budget = d["budget"].to_numpy(dtype=float)
        steps_by_arm[arm] = {}
        for t in thresholds:
            key = threshold_key(t)
            s = d[key].to_numpy(dtype=float)
            steps_by_arm[arm][t] = s
            summ = stats.summarize_steps(s, budget, rng, n_boot, ci)
            c = _cell(key, arm, summ.mean, _paper_values(reported, key, thresholds).get(arm), n, summ.n_reached)
            c |= {"median": summ.median, "censored_mean": summ.censored_mean, "std": summ.std, "iqr": summ.iqr}
            cells.append(c)
        reached = np.isfinite(d[threshold_key(top)].to_numpy(dtype=float))
        rel = stats.reliability(reached, ci)
        cells.append(_cell("reliability", arm, rel, _paper_values(reported, "reliability", thresholds).get(arm), n,
                           int(reached.sum())))
        succ = stats.mean_ci(d["eval_success_rate"].to_numpy(dtype=float), rng, n_boot, ci)
        cells.append(_cell("eval_success", arm, succ, _paper_values(reported, "eval_success", thresholds).get(arm),
                           succ.n))
        ev = eval_episodes[eval_episodes["arm"] == arm] if len(eval_episodes) else eval_episodes
        if len(ev):
            length = stats.mean_ci(ev["length"].to_numpy(dtype=float), rng, n_boot, ci)
            length = stats.Estimate(length.value, length.low, length.high, length.n,
                                    f"{len(ev)} episodes pooled over {ev['seed'].nunique()} seeds")
        else:
            length = stats.mean_ci(d["eval_mean_length"].to_numpy(dtype=float), rng, n_boot, ci)
        cells.append(_cell("eval_length", arm, length, _paper_values(reported, "eval_length", thresholds).get(arm),
                           length.n))
        final = d["final_return"].to_numpy(dtype=float)
        cells.append(_cell("final_iqm", arm, stats.iqm_ci(final, rng, n_boot, ci), None, n))
        fin = final[np.isfinite(final)]
        std = float(fin.std(ddof=1)) if fin.size >= 2 else float("nan")
        cells.append(_cell("final_std", arm, stats.Estimate(std, n=int(fin.size)), None, n))

    speed_rows: list[dict[str, Any]] = []
    for t in thresholds:
        paper = _paper_steps(reported, t).get("speedup")
        for arm in arms:
            if arm == BASELINE:
                continue
            if BASELINE in steps_by_arm:
                est = stats.speedup(steps_by_arm[BASELINE][t], steps_by_arm[arm][t], rng, n_boot, ci)
            else:
                est = stats.Estimate(float("nan"), note=NEEDS_BASELINE)
            speed_rows.append({"metric": threshold_key(t), "arm": arm, "value": est.value, "ci_low": est.low,
                               "ci_high": est.high, "n": est.n,
                               "paper": float(paper) if paper is not None and arm == "hybrid" else float("nan"),
                               "note": est.note})
    speed_cols = ["metric", "arm", "value", "ci_low", "ci_high", "n", "paper", "note"]
    paper_values = {m: _paper_values(reported, m, thresholds) for m in labels}
    return Table2(arms, tuple(thresholds), pd.DataFrame(cells), pd.DataFrame(speed_rows, columns=speed_cols),
                  labels, ci, paper_values)


# ---- formatting -----------------------------------------------------------------------------


def _isnan(x: Any) -> bool:
    return x is None or (isinstance(x, float) and math.isnan(x))


def _fmt(metric: str, x: Any) -> str:
    if _isnan(x):
        return "—"
    x = float(x)
    if metric.startswith("steps_"):
        return f"{x:,.0f}"
    if metric in ("reliability", "eval_success"):
        return f"{100 * x:.0f}%"
    return f"{x:,.1f}"


def format_cell(c: dict[str, Any] | None) -> str:
    """``value [low, high]`` with ``DNF k/n`` for steps and ``k/n`` for reliability."""
    if c is None:
        return "—"
    metric = c["metric"]
    c = {**c, "n": int(c["n"] or 0), "n_reached": None if _isnan(c["n_reached"]) else int(c["n_reached"])}
    if metric.startswith("steps_") and c["n_reached"] == 0:
        return f"DNF {c['n']}/{c['n']}"
    text = _fmt(metric, c["value"])
    if not (_isnan(c["ci_low"]) or _isnan(c["ci_high"])):
        text += f" [{_fmt(metric, c['ci_low'])}, {_fmt(metric, c['ci_high'])}]"
    if metric.startswith("steps_") and c["n_reached"] < c["n"]:
        text += f" (DNF {c['n'] - c['n_reached']}/{c['n']})"
    if metric == "reliability":
        text += f" ({c['n_reached']}/{c['n']})"
    if metric == "final_std" or (c["n"] == 1 and metric != "reliability"):
        text += f" (n={c['n']})"
    return text


def format_speedup(s: dict[str, Any] | None) -> str:
    if s is None:
        return ""
    if s["note"] == NEEDS_BASELINE:
        return NEEDS_BASELINE
    if _isnan(s["value"]):
        return "— (" + s["note"] + ")" if s["note"] else "—"
    text = f"{s['value']:.2f}x"
    if not (_isnan(s["ci_low"]) or _isnan(s["ci_high"])):
        text += f" [{s['ci_low']:.2f}, {s['ci_high']:.2f}]"
    return text


def _paper_cell(metric: str, value: Any) -> str:
    if _isnan(value):
        return "—"
    text = _fmt(metric, value)
    return f"~{text}" if metric == "eval_length" else text


def display_frame(table: Table2) -> pd.DataFrame:
    """The wide table as strings: metric rows; our arms, the paper's hybrid/baseline, speedups."""
    ci_pct = f"{100 * table.ci:g}% CI"
    speed_arms = [a for a in table.arms if a != BASELINE] if table.has_baseline else ["hybrid"]
    records = []
    for metric, label in table.labels.items():
        rec: dict[str, str] = {"Metric": label}
        for arm in table.arms:
            rec[f"{arm} (ours, mean [{ci_pct}])"] = format_cell(table.cell(metric, arm))
        for arm in ("hybrid", BASELINE):
            rec[f"{arm} (paper)"] = _paper_cell(metric, table.paper.get(metric, {}).get(arm))
        is_steps = metric.startswith("steps_")
        for arm in speed_arms:
            col = f"speedup {arm} (ours)"
            if not table.has_baseline:
                rec[col] = NEEDS_BASELINE if is_steps else ""
            else:
                rec[col] = format_speedup(table.speedup(float(metric.removeprefix("steps_")), arm)) if is_steps else ""
        paper_speed = table.paper.get(metric, {}).get("speedup")
        rec["speedup (paper)"] = f"{float(paper_speed):.1f}x" if paper_speed is not None else ""
        records.append(rec)
    return pd.DataFrame(records)


def to_markdown(table: Table2) -> str:
    """GitHub Markdown of ``display_frame`` (no ``tabulate`` dependency)."""
    df = display_frame(table)

    def row(cells: Sequence[str]) -> str:
        return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"

    lines = [row(df.columns), row(["---"] * len(df.columns))]
    lines += [row(r) for r in df.itertuples(index=False)]
    return "\n".join(lines) + "\n"


_LATEX_ESCAPES = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_",
                  "{": r"\{", "}": r"\}", "~": r"$\sim$", "^": r"\^{}", "—": "--"}


def _tex(text: str) -> str:
    return "".join(_LATEX_ESCAPES.get(ch, ch) for ch in str(text))


def to_latex(table: Table2, caption: str = "Steps to reward thresholds and reliability, ours vs the paper.") -> str:
    """A ``booktabs`` LaTeX table of ``display_frame``."""
    df = display_frame(table)
    lines = [r"\begin{table}[t]", r"\centering", r"\small", r"\caption{" + _tex(caption) + "}",
             r"\begin{tabular}{l" + "r" * (len(df.columns) - 1) + "}", r"\toprule",
             " & ".join(_tex(c) for c in df.columns) + r" \\", r"\midrule"]
    lines += [" & ".join(_tex(c) for c in r) + r" \\" for r in df.itertuples(index=False)]
    lines += [r"\bottomrule", r"\end{tabular}", r"\end{table}"]
    return "\n".join(lines) + "\n"


def to_long(table: Table2) -> pd.DataFrame:
    """Tidy numeric form (CSV): one row per (metric, arm), speedups as ``speedup_<threshold>`` rows."""
    cells = table.cells.copy()
    cells.insert(1, "label", cells["metric"].map(table.labels))
    sp = table.speedups.copy()
    sp.insert(1, "label", "Speedup vs baseline to " + sp["metric"].str.removeprefix("steps_"))
    sp["metric"] = "speedup_" + sp["metric"].str.removeprefix("steps_")
    return pd.concat([cells, sp], ignore_index=True)


TABLE2_CAPTION = "Table 2 (recomputed): steps to reward thresholds and reliability, ours vs the paper."


def write_table2(table: Table2, out: Path, vlm_note: str) -> list[Path]:
    """Write ``table2.md``, ``table2.csv`` and ``table2.tex`` under ``out``; returns their paths.

    ``vlm_note`` names the VLM behind the shaped arms (SIMULATED said plainly); it is the
    caption's second sentence in Markdown and LaTeX and a ``vlm`` column in the CSV.
    """
    paths = [out / "table2.md", out / "table2.csv", out / "table2.tex"]
    paths[0].write_text(f"**{TABLE2_CAPTION}** {vlm_note}.\n\n" + to_markdown(table), encoding="utf-8")
    to_long(table).assign(vlm=vlm_note).to_csv(paths[1], index=False)
    paths[2].write_text(to_latex(table, caption=f"{TABLE2_CAPTION} {vlm_note}."), encoding="utf-8")
    return paths
