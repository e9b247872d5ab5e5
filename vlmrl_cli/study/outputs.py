"""The files `vlmrl study` writes into ``--out``: the tables, ``report.md`` (its prose from this
package's ``report.md``), the figure and ``manifest.json``, from a ``StudyResult``.
"""

from __future__ import annotations

import json
import math
import re
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from string import Template
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from vlmrl_cli.analysis import multiplicity
from vlmrl_cli.analysis.censored import RATIO_INTERVAL, RULE, equivalent
from vlmrl_cli.core import tables
from vlmrl_cli.core.provenance import git_commit, package_versions
from vlmrl_cli.report import figures, hacking
from vlmrl_cli.study import markdown, verdicts
from vlmrl_cli.study.config import StudyConfig
from vlmrl_cli.sweep.cost import CostEstimate
from vlmrl_cli.sweep.runner import JobResult
from vlmrl_cli.tracking import store


@dataclass
class StudyResult:
    """What one `vlmrl study` found and wrote (``missing``: sweep -> jobs without a FINISHED run)."""

    regime_map: pd.DataFrame = field(default_factory=pd.DataFrame)
    vlm_points: pd.DataFrame = field(default_factory=pd.DataFrame)
    controls: pd.DataFrame = field(default_factory=pd.DataFrame)
    per_seed: pd.DataFrame = field(default_factory=pd.DataFrame)
    power: list[str] = field(default_factory=list)
    missing: dict[str, int] = field(default_factory=dict)
    summary: list[str] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)
    run_id: str | None = None
    stages: list[dict[str, Any]] = field(default_factory=list)
    trained: int = 0
    failed: list[JobResult] = field(default_factory=list)
    runs_wall_s: float = 0.0  # the own wall times of every run the study reads (each run once)
    runs: int = 0  # how many runs that is

    @property
    def wall_s(self) -> float:
        return float(sum(s["wall_s"] for s in self.stages))


def finished_keys(per_seed: pd.DataFrame) -> set[tuple[str, int, str]]:
    """The (arm, seed, config hash) of every run in ``per_seed``: the jobs that have a FINISHED run."""
    if not len(per_seed):
        return set()
    return set(zip(per_seed["arm"], per_seed["seed"].astype(int), per_seed["config_hash"], strict=True))


def _vlm_table(points: pd.DataFrame, top: float) -> str:
    rows = []
    for r in points.itertuples(index=False):
        speed = f"{r.speedup:.2f}x" if math.isfinite(r.speedup) else "—"
        if math.isfinite(r.low) and math.isfinite(r.high):
            speed += f" [{r.low:.2f}, {r.high:.2f}]"
        p = f"{r.p:.2g}" if math.isfinite(r.p) else "—"
        rows.append([r.variant, f"{r.mcq_accuracy:.2f}", speed, p, f"{r.hybrid_seeds}/{r.baseline_seeds}"])
    header = ["Variant", "MCQ accuracy", f"Speedup to {top:g}, hybrid / baseline [95% CI]", "rank p", "Seeds (h/b)"]
    return "\n".join(tables.markdown_rows(header, rows)) + "\n"


def to_markdown(cfg: StudyConfig, result: StudyResult, hack_frame: pd.DataFrame, simulated: bool,
                cost: CostEstimate | None, history: Sequence[Mapping[str, Any]] = ()) -> str:
    """``report.md``: the generated summary first, then the regime map, VLM quality, reward hacking, method."""
    return "\n".join([*_head_lines(cfg, result, simulated), *_map_lines(cfg, result), *_controls_lines(cfg, result),
                      *_vlm_lines(cfg, result), *_hacking_lines(cfg, hack_frame), *_method_lines(cfg, result),
                      *_cost_lines(result, cost), *_history_lines(history)])


def _head_lines(cfg: StudyConfig, result: StudyResult, simulated: bool) -> list[str]:
    """The title, which VLM answered, and what is missing from a study still training."""
    vlm_line = ("**VLM: the SIMULATED VLM (a pixel-reading stand-in), not a real model: nothing here is evidence "
                "about a real VLM.**" if simulated else "VLM: a real backend (see the runs' vlmrl.vlm tags).")
    lines = ["# Study: where does the hybrid's advantage hold?", "", vlm_line, ""]
    if result.missing:
        jobs = {(j.arm.name, j.seed, j.config_hash) for s in cfg.all_regimes() for j in s.run.jobs()}
        lines += [prose("partial", missing=len(jobs - finished_keys(result.per_seed)), jobs=len(jobs),
                        per_sweep="; ".join(f"`{k}` {v}" for k, v in result.missing.items())), ""]
    return lines


def _map_lines(cfg: StudyConfig, result: StudyResult) -> list[str]:
    """The summary, the regime map, the regimes' overrides and the notes on the grid."""
    lines = ["## Summary", "", *result.summary, ""]
    lines += ["## Regime map", "", markdown.map_markdown(result.regime_map.to_dict("records"), cfg.top, cfg.ci,
                                                       cfg.margin, cfg.adjust)]
    lines += ["Regimes (overrides over the study's defaults): "
              + "; ".join(f"`{r.id}` = {r.label}" for r in cfg.regimes) + ".", ""]
    return lines + [f"- {n}" for n in cfg.notes] + ([""] if cfg.notes else [])


def _controls_lines(cfg: StudyConfig, result: StudyResult) -> list[str]:
    """The placebo, dose-response and lock controls, when the study has any."""
    if not len(result.controls):
        return []
    return ["## Controls: placebo, dose-response, the lock", "", prose("controls", vlm_regime=cfg.vlm_regime), "",
            markdown.controls_markdown(result.controls.to_dict("records"), cfg.top, cfg.margin, cfg.ci, cfg.adjust)]


def _vlm_lines(cfg: StudyConfig, result: StudyResult) -> list[str]:
    """The hybrid's speedup against each VLM variant's measured accuracy, and its figure."""
    return ["## VLM quality", "", prose("vlm_quality", vlm_regime=cfg.vlm_regime, states=cfg.states), "",
            _vlm_table(result.vlm_points, cfg.top) if len(result.vlm_points) else "No VLM variant was run.\n",
            "![VLM quality](vlm_quality.png)", ""]


def _hacking_lines(cfg: StudyConfig, hack_frame: pd.DataFrame) -> list[str]:
    """Reward hacking per regime, with the hovering diagnostic where the task has one."""
    tasks = {regime.id: regime.run.task_plugin for regime in cfg.regimes}
    hover_from = next((task.hover_from for task in tasks.values() if task.hover_diagnostic), None)
    lines = ["## Reward hacking", "", hacking.definition(hover_from), ""]
    for regime in cfg.regimes:
        part = hack_frame[hack_frame["regime"] == regime.id] if len(hack_frame) else hack_frame
        lines += [f"### `{regime.id}`", "",
                  hacking.hacking_markdown(part, cfg.ci, tasks[regime.id].hover_diagnostic) if len(part)
                  else "no runs\n"]
    return lines


def _method_lines(cfg: StudyConfig, result: StudyResult) -> list[str]:
    """How every number was computed: the DNF rule, the tests, the family, the verdict rule; then the power."""
    family = verdicts.family_size(result.regime_map.to_dict("records"), result.controls.to_dict("records"))
    return ["## Method", "",
            prose("method", rule=RULE, top=f"{cfg.top:g}", ratio_interval=RATIO_INTERVAL,
                  family_line=multiplicity.family_line(cfg.adjust, family, verdicts.FAMILY_WHAT),
                  alpha=f"{cfg.alpha:g}", ci=f"{100 * cfg.ci:g}", equivalent=equivalent(cfg.margin),
                  tost=f"{100 * (1 - 2 * cfg.alpha):g}", margin=f"{cfg.margin:g}",
                  auc_margin=f"{cfg.base.task_plugin.auc_margin:.3g}"), "",
            *result.power, ""]


def _cost_lines(result: StudyResult, cost: CostEstimate | None) -> list[str]:
    """This invocation's wall time, the worker time of every run the report reads, and the estimate."""
    train = sum(r.get("train_wall_s", 0.0) for r in result.regime_map.to_dict("records"))
    estimate = (" " + prose("estimate", pending=cost.pending, minutes=f"{cost.total_s / 60:.0f}", how=cost.how)
                if cost else "")
    return [prose("cost", wall_s=f"{result.wall_s:,.0f}", trained=result.trained, runs=result.runs,
                  runs_wall_s=f"{result.runs_wall_s:,.0f}", runs_wall_h=f"{result.runs_wall_s / 3600:.1f}",
                  train=f"{train:,.0f}", estimate=estimate), ""]


def _history_lines(history: Sequence[Mapping[str, Any]]) -> list[str]:
    """The earlier invocations of a resumed study, oldest first (none: no line)."""
    if not history:
        return []
    earlier = "; ".join(
        f"commit {str(h.get('git_commit', '?'))[:7]} on {str(h.get('written_at', '?'))[:10]}: "
        f"{h.get('runs_trained_now', '?')} run(s) trained, {float(h.get('wall_s', math.nan)):,.0f} s"
        for h in history)
    return [prose("history", earlier=earlier), ""]


def _sections() -> dict[str, Template]:
    """The report's prose, from ``report.md`` in this package: section name -> its paragraph."""
    text = resources.files("vlmrl_cli.study").joinpath("report.md").read_text(encoding="utf-8")
    parts = re.split(r"^<!-- (\w+) -->\n", text, flags=re.MULTILINE)[1:]
    return {name: Template(" ".join(body.split("\n")).strip()) for name, body in zip(parts[::2], parts[1::2],
                                                                                     strict=True)}


def prose(section: str, **values: object) -> str:
    """The paragraph ``section`` of the report's prose with ``values`` filled in."""
    return _sections()[section].substitute(values)


#: The fields of a manifest that say what one invocation did; earlier invocations keep only these.
INVOCATION_FIELDS = ("command", "git_commit", "versions", "stages", "wall_s", "runs_trained_now", "written_at")


def earlier_invocations(previous: Any, experiment: str, tracking_uri: str) -> list[dict[str, Any]]:
    """The invocations behind an earlier manifest of the same store and experiment in ``--out`` (a
    resumed study), oldest first; [] otherwise."""
    if not isinstance(previous, dict) or (previous.get("experiment"), previous.get("tracking_uri")) != (
            experiment, tracking_uri):
        return []
    history = [h for h in previous.get("earlier_invocations", []) if isinstance(h, dict)]
    return [*history, {k: previous[k] for k in INVOCATION_FIELDS if k in previous}]


#: The files a study writes into ``--out``, in the order they are listed and logged.
OUTPUTS = ("regime_map.md", "regime_map.csv", "vlm_quality.csv", "vlm_quality.png", "hacking.csv", "report.md",
           "manifest.json", "per_seed.csv", "controls.csv", "controls.md")


def write(cfg: StudyConfig, result: StudyResult, hack_frame: pd.DataFrame, simulated: bool, command: str,
           cost: CostEstimate | None) -> list[Path]:
    out = cfg.out
    out.mkdir(parents=True, exist_ok=True)
    path = {name: out / name for name in OUTPUTS}
    tracking_uri = store.resolve_tracking_uri(cfg.base.tracking_uri)
    try:
        previous = json.loads(path["manifest.json"].read_text(encoding="utf-8"))
    except (OSError, ValueError):  # none yet, or not a manifest
        previous = None
    history = earlier_invocations(previous, cfg.base.experiment, tracking_uri)
    vlm_note = "SIMULATED VLM, not a real model." if simulated else ""
    heading = " (SIMULATED VLM)" if simulated else ""
    path["regime_map.md"].write_text(f"# Regime map{heading}\n\n"
                                     + markdown.map_markdown(result.regime_map.to_dict("records"), cfg.top, cfg.ci,
                                                             cfg.margin, cfg.adjust)
                                     + "\n" + "\n".join(f"- {n}" for n in cfg.notes) + "\n", encoding="utf-8")
    result.regime_map.drop(columns=[c for c in result.regime_map if c.endswith("_text")]).assign(
        vlm=vlm_note).to_csv(path["regime_map.csv"], index=False)
    result.vlm_points.assign(vlm=vlm_note).to_csv(path["vlm_quality.csv"], index=False)
    vlm_figure(result.vlm_points, cfg.top, cfg.vlm_regime, simulated).savefig(path["vlm_quality.png"],
                                                                                       dpi=150)
    hack_frame.to_csv(path["hacking.csv"], index=False)
    path["report.md"].write_text(to_markdown(cfg, result, hack_frame, simulated, cost, history), encoding="utf-8")
    result.per_seed.assign(vlm=vlm_note).to_csv(path["per_seed.csv"], index=False)
    result.controls.assign(vlm=vlm_note).to_csv(path["controls.csv"], index=False)
    path["controls.md"].write_text(f"# Controls{heading}\n\n"
                                   + (markdown.controls_markdown(result.controls.to_dict("records"), cfg.top,
                                                                 cfg.margin, cfg.ci, cfg.adjust)
                                      if len(result.controls) else "No control cell was run.\n"), encoding="utf-8")
    manifest = _manifest(cfg, result, simulated, command, cost, tracking_uri, history)
    path["manifest.json"].write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
    return list(path.values())


def _manifest(cfg: StudyConfig, result: StudyResult, simulated: bool, command: str, cost: CostEstimate | None,
              tracking_uri: str, history: list[dict[str, Any]]) -> dict[str, Any]:
    """``manifest.json``: what was run, by which command and commit, at what cost, with which hashes."""
    return {
        "what": "vlmrl study" + (" with the SIMULATED VLM, not a real model" if simulated else ""),
        "command": command,
        "git_commit": git_commit(),
        "versions": package_versions(),
        "stages": result.stages,
        "wall_s": round(result.wall_s, 1),
        "runs_trained_now": result.trained,
        "cost_estimate": None if cost is None else cost.__dict__,
        "experiment": cfg.base.experiment,
        "tracking_uri": tracking_uri,
        "regimes": [{"id": r.id, "overrides": r.label, "config_hashes": sorted({j.config_hash for j in r.run.jobs()})}
                    for r in cfg.regimes],
        "variants": [{"id": v.id, "overrides": v.label, "config_hash": v.run.jobs()[0].config_hash}
                     for v in cfg.variants],
        "missing_runs": result.missing,
        "cells": [{"id": c.regime.id, "kind": c.kind, "arm": c.arm, "overrides": c.regime.label,
                   "config_hash": c.regime.run.jobs()[0].config_hash} for c in cfg.cells],
        "margin": cfg.margin,
        "adjust": cfg.adjust,
        "vlm_regime": cfg.vlm_regime,
        "notes": list(cfg.notes),
        "written_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "earlier_invocations": history,
    }


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
