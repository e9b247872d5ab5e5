"""`vlmrl calibrate` end to end: train each regime's baseline through the resumable sweep, read the
runs back from MLflow, score each regime against the target profile, write the outputs (see
docs/commands/calibrate.md) and log them to one ``vlmrl.kind=calibration`` run."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from vlmrl_cli.analysis.learning_profile import RegimeProfile, regime_profile
from vlmrl_cli.analysis.load import load_experiment
from vlmrl_cli.analysis.stats import Estimate
from vlmrl_cli.calibration.regimes import CalibrateConfig, Regime
from vlmrl_cli.core import tables
from vlmrl_cli.core.paths import check_out_folder
from vlmrl_cli.core.provenance import config_hash, flatten, git_commit, package_versions, to_jsonable
from vlmrl_cli.report import figures
from vlmrl_cli.report.table2 import threshold_key
from vlmrl_cli.sweep.multi import log_summary_run, runs_of, train_sweeps, wall_s
from vlmrl_cli.sweep.runner import JobResult, SweepReporter
from vlmrl_cli.tracking import schema, store

KIND = schema.KIND_CALIBRATION


@dataclass
class CalibrationResult:
    table: pd.DataFrame  # one row per regime, closest first
    files: list[Path] = field(default_factory=list)
    run_id: str | None = None
    wall_s: float = 0.0
    train_wall_s: float = 0.0  # the regimes' runs' own wall times, summed (trained now or before)
    trained: int = 0  # runs trained by this invocation
    failed: list[JobResult] = field(default_factory=list)


def calibrate(
    cfg: CalibrateConfig, reporter_for: Callable[[Regime], AbstractContextManager[SweepReporter]], command: str = ""
) -> CalibrationResult:
    """Train what is missing (one sweep per regime, each with a fresh ``reporter_for(regime)``),
    then score and write. Failed runs stop before scoring; a rerun resumes."""
    check_out_folder(cfg.out)  # before training: a bad --out must not cost a sweep, nor leave a store
    start = time.perf_counter()
    result = CalibrationResult(pd.DataFrame())
    result.trained, result.failed = train_sweeps(cfg.regimes, reporter_for)
    if result.failed:
        result.wall_s = time.perf_counter() - start
        return result
    client = store.connect(cfg.base.tracking_uri)
    data = load_experiment(client, cfg.base.experiment)
    cfg.out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(cfg.seed)
    rows, curves = [], []
    for regime in cfg.regimes:
        runs = runs_of(data.runs, regime.run)
        episodes = data.episodes[data.episodes["run_id"].isin(runs["run_id"])]
        profile = regime_profile(
            episodes, cfg.target, regime.run.budget, rng, cfg.window, cfg.n_boot, seeds=regime.run.seeds
        )
        rows.append(_row(regime, profile, cfg))
        curves += figures.seed_curves(episodes.assign(arm=regime.id), cfg.window)
        result.train_wall_s += sum(wall_s(client, run_id) for run_id in runs["run_id"])
    result.table = pd.DataFrame(rows).sort_values("distance", kind="stable").reset_index(drop=True)
    result.wall_s = time.perf_counter() - start
    result.files = _write(cfg, result, curves, rng, command)
    result.run_id = _log_run(client, data.experiment_id, cfg, result.files)
    return result


def knob_columns(regimes: tuple[Regime, ...]) -> list[str]:
    """The PPO knobs that differ between regimes (every regime's value is listed in the table)."""
    ppo = [flatten(r.run.ppo_config) for r in regimes]
    return [k for k in ppo[0] if len({p[k] for p in ppo}) > 1]


def _with_ci(key: str, est: Estimate) -> dict[str, float]:
    return {key: est.value, f"{key}_low": est.low, f"{key}_high": est.high}


def _row(regime: Regime, profile: RegimeProfile, cfg: CalibrateConfig) -> dict[str, Any]:
    ppo = flatten(regime.run.ppo_config)
    row: dict[str, Any] = {"id": regime.id, "regime": regime.label}
    row |= {f"ppo.{k}": ppo[k] for k in knob_columns(cfg.regimes)}
    row |= {"seeds": profile.n_seeds, "budget": profile.budget} | _with_ci("reliability", profile.reliability)
    for t, est, n in zip(cfg.target.thresholds, profile.steps, profile.n_reached, strict=True):
        row |= _with_ci(threshold_key(t), est) | {f"reached_{t:g}": n}
    return row | _with_ci("distance", profile.distance) | {"config_hash": regime.run.jobs()[0].config_hash}


def _fmt_steps(x: float) -> str:
    return "—" if not np.isfinite(x) else f"{x:,.0f}"


def _shown(r: dict[str, Any], key: str, fmt: Callable[[float], str]) -> str:
    """``value [low, high]`` of the columns ``_with_ci`` gave ``key`` in the row ``r``."""
    return f"{fmt(r[key])} [{fmt(r[key + '_low'])}, {fmt(r[key + '_high'])}]"


def to_markdown(cfg: CalibrateConfig, result: CalibrationResult) -> str:
    """``calibration.md``: the target, the distance formula, one row per regime, the cost."""
    t = cfg.target
    table = result.table
    head = (
        ["id", "regime", "reliability [95% CI]"]
        + [f"steps to {x:g} [95% CI]" for x in t.thresholds]
        + ["distance [95% CI]"]
    )
    lines = [
        "# Calibration of the baseline's PPO regime",
        "",
        f"Target: {t.source or 'given profile'}: steps to "
        + ", ".join(f"{x:g} = {s:,.0f}" for x, s in zip(t.thresholds, t.steps, strict=True))
        + f"; reliability {t.reliability:.0%} (seeds reaching {t.thresholds[-1]:g} within the budget).",
        "",
        "Distance D = mean over thresholds of |ln(S_k / T_k)| + |reliability - target reliability|, where S_k is "
        "the mean over seeds of the steps to threshold k with a seed that never reaches it counted at the budget "
        "(censored, not dropped). 0 is a perfect match. Steps are means of those censored values; CIs are 95% "
        "percentile bootstraps over seeds (reliability: Wilson).",
        "",
    ]
    rows = []
    for r in table.to_dict("records"):
        cells = [r["id"], f"`{r['regime']}`", f"{_shown(r, 'reliability', '{:.0%}'.format)} (n={r['seeds']})"]
        for x in t.thresholds:
            cells.append(f"{_shown(r, threshold_key(x), _fmt_steps)} ({r[f'reached_{x:g}']}/{r['seeds']} reached)")
        rows.append([*cells, _shown(r, "distance", "{:.3f}".format)])
    lines += tables.markdown_rows(head, rows)
    best = table.iloc[0]
    lines += [
        "",
        f"Closest: {best['id']} (`{best['regime']}`), D = {best['distance']:.3f}. Budget {int(best['budget']):,} "
        f"steps per run; PPO knobs of every regime are in calibration.csv.",
        "",
        f"Cost: {result.wall_s:,.0f} s of wall time for this invocation ({result.trained} run(s) trained now); the "
        f"runs' own wall times sum to {result.train_wall_s:,.0f} s.",
        "",
    ]
    return "\n".join(lines)


def figure(cfg: CalibrateConfig, curves: list[figures.SeedCurve], rng: np.random.Generator) -> Figure:
    """Each regime's mean learning curve; dashed thresholds, the target's crossings marked x."""
    grid, bands = figures.mean_curves(curves, rng, n_boot=cfg.n_boot)
    fig = Figure(figsize=(figures.WIDTH_IN, 3.6), layout="constrained")
    ax = fig.subplots()
    for rid, (mean, low, high) in bands.items():
        figures.plot_mean_curve(grid, mean, low, high, ax, figures.arm_color(rid, list(bands)), rid)
    t = cfg.target
    for x in t.thresholds:
        ax.axhline(x, color="gray", linestyle="--", linewidth=0.7)
    ax.plot(t.steps, t.thresholds, "kx", markersize=8, label="target crossings")
    ax.set_xlabel("timestep", fontsize=figures.SMALL + 1)
    ax.set_ylabel(f"mean return (last {cfg.window} ep.)", fontsize=figures.SMALL + 1)
    ax.legend(fontsize=figures.SMALL, loc="lower right", ncols=2)
    fig.suptitle(
        f"Baseline learning curve per PPO regime (mean over seeds) vs {t.source or 'the target'}",
        fontsize=figures.SMALL + 1,
    )
    return fig


def _write(
    cfg: CalibrateConfig,
    result: CalibrationResult,
    curves: list[figures.SeedCurve],
    rng: np.random.Generator,
    command: str,
) -> list[Path]:
    out = cfg.out
    paths = [out / "calibration.csv", out / "calibration.md", out / "calibration.png", out / "manifest.json"]
    result.table.to_csv(paths[0], index=False)
    paths[1].write_text(to_markdown(cfg, result), encoding="utf-8")
    figure(cfg, curves, rng).savefig(paths[2], dpi=150)
    manifest = {
        "command": command,
        "git_commit": git_commit(),
        "versions": package_versions(),
        "wall_s": round(result.wall_s, 1),
        "train_wall_s_sum": round(result.train_wall_s, 1),
        "runs_trained_now": result.trained,
        "experiment": cfg.base.experiment,
        "tracking_uri": store.resolve_tracking_uri(cfg.base.tracking_uri),
        "target": to_jsonable(cfg.target),
        "regimes": [{"id": r.id, "regime": r.label, "config_hash": r.run.jobs()[0].config_hash} for r in cfg.regimes],
        "written_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    paths[3].write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
    return paths


def _log_run(client: Any, experiment_id: str, cfg: CalibrateConfig, files: list[Path]) -> str:
    """The calibration's MLflow run (the existing one of the same calibration, else a new one)."""
    params = flatten({"target": cfg.target, "window": cfg.window, "n_boot": cfg.n_boot,
                      "regimes": [r.label for r in cfg.regimes]})
    identity = {  # two calibrations are the same when their regimes' job hashes, target and scoring are
        "regimes": [[j.config_hash for j in r.run.jobs()] for r in cfg.regimes],
        "target": to_jsonable(cfg.target),
        "window": cfg.window,
        "n_boot": cfg.n_boot,
        "seed": cfg.seed,
    }
    return log_summary_run(client, experiment_id, KIND, config_hash(identity), params, files,
                           ("none (the baseline arm queries no VLM)", False))

