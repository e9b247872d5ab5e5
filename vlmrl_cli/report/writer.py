"""`vlmrl report`: read finished runs from MLflow (never retrain) and write Table 2, Figures 2-4,
the claims table, the attribution table, the performance profile, the reward-hacking diagnostic
and ``report.md``, then log them as artifacts of a ``vlmrl.kind=report`` run."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from vlmrl_cli import paper
from vlmrl_cli.analysis import stats
from vlmrl_cli.analysis.load import ExperimentData, load_experiment
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.core.paths import check_out_folder
from vlmrl_cli.core.provenance import config_hash, flatten, to_jsonable
from vlmrl_cli.report import attribution, figures, hacking
from vlmrl_cli.report import claims as claims_mod
from vlmrl_cli.report.config import ReportConfig, check_report
from vlmrl_cli.report.markdown import report_md, write_table2
from vlmrl_cli.report.table2 import Table2, build_table2, per_seed_table
from vlmrl_cli.shaping.arms import ARMS, ArmSpec
from vlmrl_cli.shaping.hacking import HOVER_FLAG
from vlmrl_cli.tasks.base import Task, TaskLookup
from vlmrl_cli.tracking import schema, store
from vlmrl_cli.tracking.lifecycle import tracked_run


@dataclass(frozen=True)
class ReportResult:
    out: Path
    files: tuple[Path, ...]
    table: Table2
    claims: tuple[claims_mod.ClaimResult, ...]
    report_run_id: str | None
    warnings: tuple[str, ...] = field(default_factory=tuple)


def load_reported(path: Path | None) -> dict[str, Any]:
    """The paper's numbers (``vlmrl_cli/paper/reported.json``); ``BadInput`` when missing or malformed."""
    p = path or paper.REPORTED
    try:
        return dict(json.loads(p.read_text(encoding="utf-8")))
    except (OSError, json.JSONDecodeError) as exc:
        raise BadInput(f"cannot read the paper's reported numbers from {p}; check the file exists and is JSON."
                       ) from exc


def figure_vlm_note(runs: pd.DataFrame) -> str:
    """The short VLM line of a figure's title: the VLM(s) the shaped arms used, SIMULATED said.

    Example:
        >>> runs = pd.DataFrame({"arm": ["baseline", "hybrid"], "simulated": [False, True],
        ...                      "vlm": ["none (this arm queries no VLM)", "sim:pixel-reader-v1/abc (SIMULATED VLM)"]})
        >>> figure_vlm_note(runs)
        'VLM of the shaped arms: sim:pixel-reader-v1/abc (SIMULATED VLM)'
    """
    used = sorted({str(v) for v in runs["vlm"].dropna() if not str(v).startswith("none")})
    text = "VLM of the shaped arms: " + ("; ".join(used) if used else "none (no arm queries a VLM)")
    if bool(runs["simulated"].any()) and "SIMULATED" not in text:
        text += " (SIMULATED VLM, not a real model)"
    return text


def vlm_note(runs: pd.DataFrame) -> str:
    """One line naming the VLM backend(s); says SIMULATED VLM when any run used the simulated one."""
    per_arm = runs.dropna(subset=["vlm"]).groupby("arm", sort=True)["vlm"].agg(lambda v: " / ".join(sorted(set(v))))
    labels = [f"{arm}: {label}" for arm, label in per_arm.items()]
    text = "VLM backend per arm: " + ("; ".join(labels) if labels else "unknown")
    if bool(runs["simulated"].any()) and "SIMULATED VLM" not in text:
        text += " — SIMULATED VLM, not a real model"
    return text


def check_paths(runs: pd.DataFrame, allow_mixed: bool) -> list[str]:
    """``BadInput`` (a warning if ``allow_mixed``) when the runs come from several numeric paths
    (``analysis.load.numeric_path``), which train different agents from one config."""
    if "numeric_path" not in runs or runs.empty:
        return []
    counts = runs["numeric_path"].astype(str).value_counts().sort_index()
    if len(counts) <= 1:
        return []
    listed = "; ".join(f"{path}: {n} run(s)" for path, n in counts.items())
    if not allow_mixed:
        raise BadInput(f"the runs were computed on {len(counts)} numeric paths ({listed}), which train different "
                       "agents from one config; report the runs of one path (retrain the others with the pin), or "
                       "pass --allow-mixed-paths to compare them anyway.")
    return [f"the runs come from {len(counts)} numeric paths ({listed}); they are compared as asked "
            "(--allow-mixed-paths), though the same config trains different agents on each."]


def _warnings(data: ExperimentData, table: Table2, allow_mixed_paths: bool) -> list[str]:
    out = check_paths(data.runs, allow_mixed_paths)
    for arm, hashes in data.runs.groupby("arm")["config_hash"].unique().items():
        if len(hashes) > 1:
            out.append(f"arm `{arm}` mixes {len(hashes)} configurations ({', '.join(map(str, hashes))}); "
                       "its statistics pool them.")
    if not table.has_baseline:
        out.append("No `baseline` arm in this experiment: speedups need the baseline arm and are not computed.")
    for arm, n in data.runs.groupby("arm").size().items():
        if n < claims_mod.MIN_SEEDS:
            out.append(f"arm `{arm}` has only {n} seed(s); claims that use it are inconclusive.")
    return out


def for_task(cfg: ReportConfig, task: Task) -> ReportConfig:
    """``cfg`` with the thresholds and window it leaves unset (None) taken from ``task``; a window taken
    from the task also caps ``min_episodes`` at it.

    Example:
        >>> from vlmrl_cli.tasks.registry import get_task
        >>> acrobot = get_task("acrobot")
        >>> for_task(ReportConfig(), acrobot).window, for_task(ReportConfig(window=100), acrobot).window
        (20, 100)
    """
    window = cfg.window if cfg.window is not None else task.window
    return dataclasses.replace(
        cfg,
        thresholds=tuple(float(t) for t in (cfg.thresholds if cfg.thresholds is not None else task.thresholds)),
        window=window,
        min_episodes=cfg.min_episodes if cfg.window is not None else min(cfg.min_episodes, window),
    )


REPORTS_SUFFIX = "-reports"  # report runs live in their own experiment, beside the training runs


def _log_report_run(client: Any, data: ExperimentData, cfg: ReportConfig, files: Sequence[Path], note: str,
                    simulated: bool) -> str:
    """The report run of (settings, output folder) in ``<experiment>-reports``, updated on a rerun."""
    experiment_id = store.ensure_experiment(client, f"{data.experiment_name}{REPORTS_SUFFIX}")
    key = config_hash({"cfg": to_jsonable(cfg), "out": str(cfg.out.absolute())})
    tags = {schema.TAG_KIND: schema.KIND_REPORT, schema.TAG_REPORT_EXPERIMENT: data.experiment_name,
            schema.TAG_REPORT_KEY: key, **store.provenance_tags(note, simulated)}
    same = client.search_runs([experiment_id], filter_string=schema.runs_filter({schema.TAG_REPORT_KEY: key}),
                              max_results=1)
    if same:
        rid = str(same[0].info.run_id)
        client.update_run(rid, status="RUNNING")
        store.set_tags(client, rid, tags)
    else:
        run = client.create_run(experiment_id, run_name=f"report of {data.experiment_name} -> {cfg.out}", tags=tags)
        rid = str(run.info.run_id)
    with tracked_run(client, rid):
        if not same:  # params are write-once in MLflow; the same key means the same params
            store.log_params(client, rid, flatten(cfg))
        store.set_tags(client, rid, {schema.TAG_REPORT_RUNS: ",".join(data.runs["run_id"])[:5000]})
        store.log_artifacts(client, rid, files, "report")
    return rid


def _write_frame(frame: pd.DataFrame, stem: Path, vlm: str, markdown: str) -> list[Path]:
    """``stem.md`` (``markdown``) and ``stem.csv`` (``frame`` with a ``vlm`` column); returns both paths."""
    md, csv = stem.with_suffix(".md"), stem.with_suffix(".csv")
    md.write_text(markdown, encoding="utf-8")
    frame.assign(vlm=vlm).to_csv(csv, index=False)
    return [md, csv]


def _figures(cfg: ReportConfig, data: ExperimentData, table: Table2, per_seed: pd.DataFrame, task: Task,
             fig_note: str, streams: stats.Streams) -> dict[str, Any]:
    """The report's figures by file stem: Figures 2-4, the performance profile, reward hacking."""
    assert cfg.thresholds is not None and cfg.window is not None
    thresholds = cfg.thresholds
    curves = figures.seed_curves(data.episodes, cfg.window, cfg.min_episodes)
    arms = list(table.arms)
    return {"figure2": figures.figure2(table, fig_note),
            "figure3": figures.figure3(curves, fig_note, thresholds, cfg.window),
            "figure4": figures.figure4(curves, fig_note, streams("figure4"), thresholds, cfg.window, cfg.n_boot,
                                       cfg.ci),
            "performance_profile": figures.figure_performance_profile(
                hacking.per_arm(per_seed, "final_return", arms), fig_note, cfg.ci),
            "hacking": figures.figure_hacking(hacking.per_arm(data.eval_episodes, "length", arms),
                                              hacking.per_arm(per_seed, "hover_fraction", arms),
                                              hacking.per_arm(per_seed, "shaped_gap", arms), fig_note,
                                              HOVER_FLAG, task.max_steps)}


def write_report(cfg: ReportConfig, tasks: TaskLookup, registry: Mapping[str, ArmSpec] = ARMS) -> ReportResult:
    """Read the experiment's finished runs and write every report file under ``cfg.out``; ``tasks``
    resolves the task the runs recorded, ``registry`` gives the arms' order and comparisons."""
    check_report(cfg)
    check_out_folder(cfg.out)  # before touching MLflow, so a bad --out fails fast
    reported = load_reported(cfg.reported)
    client = store.connect_existing(cfg.tracking_uri)
    data = load_experiment(client, cfg.experiment)
    check_paths(data.runs, cfg.allow_mixed_paths)  # before anything is computed or written
    task = tasks(data.task)
    if task.paper is None:
        reported = {}  # the paper's numbers and claims are MountainCar-v0's: none beside another task
    cfg = for_task(cfg, task)
    thresholds = cfg.thresholds
    assert thresholds is not None and cfg.window is not None
    streams = stats.Streams(cfg.seed)

    per_seed = per_seed_table(data, thresholds, cfg.window, cfg.min_episodes, cfg.detached_cut)
    table = build_table2(per_seed, data.eval_episodes, reported, thresholds, streams, cfg.window, cfg.ci, cfg.n_boot,
                         cfg.detached_cut, cfg.n_perm, registry)
    comparisons = attribution.compare_arms(per_seed, thresholds, streams, cfg.n_boot, cfg.ci, cfg.n_perm,
                                           alpha=1 - cfg.ci, margin=cfg.margin, adjust=cfg.adjust,
                                           auc_delta=task.auc_margin, registry=registry)
    results = claims_mod.evaluate_claims(table, per_seed, reported, streams, cfg.n_boot, cfg.ci, comparisons)
    hack = hacking.hacking_frame(per_seed, data.eval_episodes, cfg.ci, task.max_steps)
    note = vlm_note(data.runs)
    warns = _warnings(data, table, cfg.allow_mixed_paths)

    out = cfg.out
    out.mkdir(parents=True, exist_ok=True)
    fig_note = figure_vlm_note(data.runs)
    files = write_table2(table, out, fig_note)
    for stem, fig in _figures(cfg, data, table, per_seed, task, fig_note, streams).items():
        files += figures.save_figure(fig, out, stem)
    files += claims_mod.write_claims(results, out, fig_note)
    files += _write_frame(comparisons, out / "attribution", fig_note,
                          "# Attribution: pairwise comparisons of arms\n\n" + fig_note + ".\n\n"
                          + attribution.attribution_markdown(comparisons, cfg.ci, cfg.adjust))
    files += _write_frame(hack, out / "hacking", fig_note,
                          "# Reward-hacking diagnostic\n\n" + fig_note + ".\n\n"
                          + hacking.definition(task.hover_from if task.hover_diagnostic else None) + "\n\n"
                          + hacking.hacking_markdown(hack, cfg.ci, task.hover_diagnostic))
    files += [out / "per_seed.csv", out / "report.md"]
    per_seed.merge(data.runs[["run_id", "vlm", "simulated"]], on="run_id", how="left").to_csv(files[-2], index=False)
    files[-1].write_text(report_md(cfg, data, table, results, per_seed, note, warns, comparisons, hack, task),
                         encoding="utf-8")

    run_id = (_log_report_run(client, data, cfg, files, note, bool(data.runs["simulated"].any()))
              if cfg.log_to_mlflow else None)
    return ReportResult(out, tuple(files), table, tuple(results), run_id, tuple(warns))


__all__ = ["ReportConfig", "ReportResult", "write_report"]
