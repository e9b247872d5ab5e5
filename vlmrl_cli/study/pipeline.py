"""`vlmrl study` end to end: train every regime and VLM variant through the resumable sweep, probe
each variant's VLM with the taxonomy, read the runs back from MLflow, write the outputs.

Outputs in ``cfg.out``: ``regime_map.md``/``.csv`` (per regime: each arm's reliability and steps
to the top threshold, the hybrid's speedups over the baseline and the kinematic arm, verdicts),
``vlm_quality.csv``/``.png`` (the hybrid's speedup against the VLM's measured MCQ accuracy),
``hacking.csv``, ``report.md`` (a summary generated from the numbers first) and ``manifest.json``
(commit, versions, command, wall time per stage), also logged as artifacts of one MLflow run
tagged ``vlmrl.kind=study``; ``taxonomy/<variant>/`` holds each variant's Table 1.
"""

from __future__ import annotations

import json
import math
import re
import statistics
import time
from collections.abc import Callable, Mapping, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from vlmrl_cli.analysis import stats
from vlmrl_cli.analysis.load import load_experiment
from vlmrl_cli.calibration.pipeline import log_summary_run, train_regimes, wall_s
from vlmrl_cli.calibration.regimes import Regime
from vlmrl_cli.core import tables
from vlmrl_cli.core.provenance import config_hash, git_commit, package_versions
from vlmrl_cli.probe.taxonomy import TaxonomyConfig, run_taxonomy
from vlmrl_cli.report import hacking
from vlmrl_cli.report.writer import ensure_writable
from vlmrl_cli.study import analysis
from vlmrl_cli.study.config import StudyConfig
from vlmrl_cli.tracking import schema, store
from vlmrl_cli.training.config import TrainJob
from vlmrl_cli.training.sweep import JobResult, SweepReporter, dry_plan, vlm_identity

KIND = schema.KIND_STUDY
#: Seconds per environment step of one run on one worker, when the store has no finished run to
#: measure: `nox -s repro` on 2 cores trained 20 runs of 300,000 steps in 665 s of wall time.
FALLBACK_S_PER_STEP = 665.0 * 2 / (20 * 300_000)


@dataclass(frozen=True)
class CostEstimate:
    """What a study will train: ``pending`` runs (``done`` already FINISHED), about ``per_run_s``
    seconds each on one worker, ``total_s`` of wall time over ``workers``; ``how``: the basis."""

    pending: int
    done: int
    per_run_s: float
    total_s: float
    workers: int
    how: str


def estimate_cost(cfg: StudyConfig) -> CostEstimate:
    """The study's cost, read without writing: pending jobs from the store (``dry_plan``) times a
    per-step time measured on the store's finished runs of the same arm (``perf/wall_s``), else
    ``FALLBACK_S_PER_STEP``."""
    rates = _measured_rates(cfg)
    fallback = statistics.median(rates.values()) if rates else FALLBACK_S_PER_STEP
    pending_jobs: dict[tuple[str, int, str], TrainJob] = {}
    done_jobs: set[tuple[str, int, str]] = set()
    for regime in cfg.all_regimes():  # a job shared by two sweeps (same knobs) is trained once
        plan = dry_plan(regime.run)
        done_jobs |= {(j.arm.name, j.seed, j.config_hash) for j in plan.done}
        pending_jobs |= {(j.arm.name, j.seed, j.config_hash): j for j in plan.pending}
    pending, done = len(pending_jobs), len(done_jobs)
    seconds = sum(j.timesteps * rates.get(j.arm.name, fallback) for j in pending_jobs.values())
    workers = max(1, cfg.base.workers)
    how = (f"per-step wall time of {len(rates)} arm(s) measured on finished runs in experiment "
           f"'{cfg.base.experiment}' (perf/wall_s)" if rates else
           f"no finished run to measure yet: {FALLBACK_S_PER_STEP * 1e3:.2f} ms per step and worker, from "
           "`nox -s repro` on 2 cores (20 runs x 300,000 steps in 665 s)")
    return CostEstimate(pending, done, seconds / pending if pending else 0.0, seconds / workers, workers, how)


def _measured_rates(cfg: StudyConfig) -> dict[str, float]:
    """Median seconds per step and arm over the experiment's finished training runs (empty when
    the store or experiment does not exist: nothing is created)."""
    uri = store.resolve_tracking_uri(cfg.base.tracking_uri)
    if uri.startswith("sqlite:///") and not Path(uri.removeprefix("sqlite:///")).exists():
        return {}
    client = store.connect(uri)
    exp = client.get_experiment_by_name(cfg.base.experiment)
    if exp is None or exp.lifecycle_stage == "deleted":
        return {}
    found = schema.search_all(client, exp.experiment_id, schema.runs_filter({schema.TAG_KIND: schema.KIND_TRAIN},
                                                                          finished=True))
    per_arm: dict[str, list[float]] = {}
    for run in found:
        wall, steps = run.data.metrics.get(schema.METRIC_WALL_S), run.data.params.get(schema.PARAM_TIMESTEPS)
        if wall and steps and float(steps) > 0:
            per_arm.setdefault(run.data.tags.get(schema.TAG_ARM, ""), []).append(wall / float(steps))
    return {arm: statistics.median(v) for arm, v in per_arm.items()}


@dataclass
class StudyResult:
    regime_map: pd.DataFrame = field(default_factory=pd.DataFrame)
    vlm_points: pd.DataFrame = field(default_factory=pd.DataFrame)
    summary: list[str] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)
    run_id: str | None = None
    stages: list[dict[str, Any]] = field(default_factory=list)
    trained: int = 0
    failed: list[JobResult] = field(default_factory=list)

    @property
    def wall_s(self) -> float:
        return float(sum(s["wall_s"] for s in self.stages))


def slug(name: str) -> str:
    """A folder name for a variant.

    Example:
        >>> slug("profile llava-table1"), slug("flicker 0.3")
        ('profile-llava-table1', 'flicker-0.3')
    """
    return re.sub(r"[^A-Za-z0-9.]+", "-", name).strip("-")


def run_study(
    cfg: StudyConfig,
    reporter_for: Callable[[Regime], AbstractContextManager[SweepReporter]],
    command: str = "",
    cost: CostEstimate | None = None,
) -> StudyResult:
    """Train what is missing, probe each variant's VLM, then analyse and write. Failed runs stop
    before the analysis; a rerun resumes."""
    result = StudyResult()

    def stage(name: str, start: float, **extra: Any) -> None:
        result.stages.append({"stage": name, "wall_s": round(time.perf_counter() - start, 1), **extra})

    ensure_writable(cfg.out)
    start = time.perf_counter()
    result.trained, result.failed = train_regimes(cfg.all_regimes(), reporter_for)
    stage("train", start, runs_trained_now=result.trained)
    if result.failed:
        return result
    start = time.perf_counter()
    accuracy = _probe_variants(cfg)
    stage("taxonomy", start, variants=len(cfg.variants))

    start = time.perf_counter()
    client = store.connect(cfg.base.tracking_uri)
    data = load_experiment(client, cfg.base.experiment)
    streams = stats.Streams(cfg.seed)
    rows, hack = [], []
    for regime in cfg.regimes:
        sub = analysis.subset(data, regime.run)
        row, per_seed = analysis.regime_row(regime.id, sub, cfg.thresholds, streams, cfg.n_boot, cfg.ci, cfg.alpha)
        row["overrides"] = regime.label
        row["train_wall_s"] = sum(wall_s(client, r) for r in per_seed["run_id"])
        rows.append(row)
        hack.append(hacking.hacking_frame(per_seed, sub.eval_episodes, cfg.ci).assign(regime=regime.id))
    reference = next(r for r in cfg.regimes if r.id == cfg.vlm_regime)
    points = [analysis.vlm_point(v.id, analysis.paired(data, reference.run, v.run), cfg.top, accuracy[v.id], streams,
                                 cfg.n_boot, cfg.ci) for v in cfg.variants]
    result.regime_map = pd.DataFrame(rows)
    result.vlm_points = pd.DataFrame(points, columns=["variant", "mcq_accuracy", "speedup", "low", "high", "p",
                                                      "hybrid_seeds", "baseline_seeds"])
    result.summary = analysis.summary(rows, result.vlm_points, cfg.top, cfg.alpha, cfg.vlm_regime)
    hack_frame = pd.concat(hack, ignore_index=True) if hack else pd.DataFrame()
    simulated = any(r.run.vlm.backend == "sim" for r in cfg.all_regimes())
    stage("analysis", start)
    result.files = _write(cfg, result, hack_frame, simulated, command, cost)
    label, sim = vlm_identity(cfg.base)
    result.run_id = log_summary_run(client, data.experiment_id, KIND, config_hash(identity(cfg)),
                                    {"regimes": " | ".join(f"{r.id}: {r.label}" for r in cfg.regimes),
                                     "variants": " | ".join(v.id for v in cfg.variants),
                                     "vlm_regime": cfg.vlm_regime, "thresholds": str(list(cfg.thresholds))},
                                    result.files, (label, sim))
    return result


def _probe_variants(cfg: StudyConfig) -> dict[str, float]:
    """Each variant's MCQ accuracy, from `vlmrl taxonomy` run in-process on the variant's VLM knobs."""
    accuracy = {}
    for variant in cfg.variants:
        probe = run_taxonomy(TaxonomyConfig(
            vlm=variant.run.vlm, states=cfg.states, out=cfg.out / "taxonomy" / slug(variant.id),
            tracking_uri=cfg.base.tracking_uri, experiment=f"{cfg.base.experiment}-taxonomy",
        ))
        accuracy[variant.id] = float(probe.sweep.get("mcq.accuracy", math.nan))
    return accuracy


def identity(cfg: StudyConfig) -> dict[str, Any]:
    """What makes two studies the same: every sweep's job hashes and seeds, the statistics' settings."""
    return {
        "regimes": [[r.id, [j.config_hash for j in r.run.jobs()]] for r in cfg.all_regimes()],
        "vlm_regime": cfg.vlm_regime, "thresholds": list(cfg.thresholds), "states": cfg.states,
        "window": cfg.window, "ci": cfg.ci, "alpha": cfg.alpha, "n_boot": cfg.n_boot, "seed": cfg.seed,
    }


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
    vlm_line = ("**VLM: the SIMULATED VLM (a pixel-reading stand-in), not a real model: nothing here is evidence "
                "about a real VLM.**" if simulated else "VLM: a real backend (see the runs' vlmrl.vlm tags).")
    lines = ["# Study: where does the hybrid's advantage hold?", "", vlm_line, "", "## Summary", "",
             *result.summary, ""]
    lines += ["## Regime map", "", analysis.map_markdown(result.regime_map.to_dict("records"), cfg.top, cfg.ci)]
    lines += ["Regimes (overrides over the study's defaults): "
              + "; ".join(f"`{r.id}` = {r.label}" for r in cfg.regimes) + ".", ""]
    lines += [f"- {n}" for n in cfg.notes] + ([""] if cfg.notes else [])
    lines += ["## VLM quality", "",
              f"The hybrid alone, in regime `{cfg.vlm_regime}`, with other simulated-VLM knobs; each variant's MCQ "
              f"accuracy is measured by `vlmrl taxonomy` on the same knobs ({cfg.states} sweep positions; "
              "`taxonomy/<variant>/`). The baseline is the regime's own.", "",
              _vlm_table(result.vlm_points, cfg.top) if len(result.vlm_points) else "No VLM variant was run.\n",
              "![VLM quality](vlm_quality.png)", ""]
    lines += ["## Reward hacking", "", hacking.DEFINITION, ""]
    for regime in cfg.regimes:
        part = hack_frame[hack_frame["regime"] == regime.id] if len(hack_frame) else hack_frame
        lines += [f"### `{regime.id}`", "", hacking.hacking_markdown(part, cfg.ci) if len(part) else "no runs\n"]
    lines += ["## Method", "",
              f"Reliability: seeds whose rolling mean return ({cfg.window} episodes) reaches {cfg.top:g}, Wilson "
              f"interval. Steps to {cfg.top:g}: mean over the seeds that reach it, bootstrap CI (DNF counted). "
              "Speedup: ratio of those means, bootstrap CI; p: two-sided Mann-Whitney U with DNF seeds censored "
              f"(permutation). Verdict: faster/slower when p < {cfg.alpha:g} (direction from the speedup, or from the "
              "reliability difference when an arm never finishes), else no detectable difference. The unit is the "
              "seed.", ""]
    train = sum(r.get("train_wall_s", 0.0) for r in result.regime_map.to_dict("records"))
    cost_line = (f" Estimated up front: {cost.pending} run(s) to train, {cost.total_s / 60:.0f} min ({cost.how})."
                 if cost else "")
    lines += [f"Cost: {result.wall_s:,.0f} s of wall time in this invocation ({result.trained} run(s) trained now); "
              f"the regimes' runs' own wall times sum to {train:,.0f} s.{cost_line}", ""]
    if history:
        earlier = "; ".join(
            f"commit {str(h.get('git_commit', '?'))[:7]} on {str(h.get('written_at', '?'))[:10]}: "
            f"{h.get('runs_trained_now', '?')} run(s) trained, {float(h.get('wall_s', math.nan)):,.0f} s"
            for h in history)
        lines += [f"Earlier invocations of this study on the same store (`manifest.json`, `earlier_invocations`): "
                  f"{earlier}.", ""]
    return "\n".join(lines)


#: The fields of a manifest that say what one invocation did; earlier invocations keep only these.
INVOCATION_FIELDS = ("command", "git_commit", "versions", "stages", "wall_s", "runs_trained_now", "written_at")


def earlier_invocations(previous: Any, experiment: str, tracking_uri: str) -> list[dict[str, Any]]:
    """The invocations behind an earlier manifest in ``--out``, oldest first, when it describes the same
    store and experiment (a resumed study); [] otherwise, or when it is not a manifest.

    A resumed study trains only what was missing, so the runs in its tables may come from earlier
    invocations; their commands, commits and wall times stay on record.

    Example:
        >>> old = {"experiment": "e", "tracking_uri": "u", "command": "vlmrl study", "wall_s": 7417.0}
        >>> earlier_invocations(old, "e", "u"), earlier_invocations(old, "e", "other")
        ([{'command': 'vlmrl study', 'wall_s': 7417.0}], [])
    """
    if not isinstance(previous, dict) or (previous.get("experiment"), previous.get("tracking_uri")) != (
            experiment, tracking_uri):
        return []
    history = [h for h in previous.get("earlier_invocations", []) if isinstance(h, dict)]
    return [*history, {k: previous[k] for k in INVOCATION_FIELDS if k in previous}]


def _read_manifest(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def _write(cfg: StudyConfig, result: StudyResult, hack_frame: pd.DataFrame, simulated: bool, command: str,
           cost: CostEstimate | None) -> list[Path]:
    out = cfg.out
    out.mkdir(parents=True, exist_ok=True)
    tracking_uri = store.resolve_tracking_uri(cfg.base.tracking_uri)
    history = earlier_invocations(_read_manifest(out / "manifest.json"), cfg.base.experiment, tracking_uri)
    names = ["regime_map.md", "regime_map.csv", "vlm_quality.csv", "vlm_quality.png", "hacking.csv", "report.md",
             "manifest.json"]
    paths = [out / n for n in names]
    vlm_note = " SIMULATED VLM, not a real model." if simulated else ""
    paths[0].write_text(f"# Regime map{' (SIMULATED VLM)' if simulated else ''}\n\n"
                        + analysis.map_markdown(result.regime_map.to_dict("records"), cfg.top, cfg.ci)
                        + "\n" + "\n".join(f"- {n}" for n in cfg.notes) + "\n", encoding="utf-8")
    result.regime_map.drop(columns=[c for c in result.regime_map if c.endswith("_text")]).assign(
        vlm=vlm_note.strip()).to_csv(paths[1], index=False)
    result.vlm_points.assign(vlm=vlm_note.strip()).to_csv(paths[2], index=False)
    analysis.vlm_figure(result.vlm_points, cfg.top, cfg.vlm_regime, simulated).savefig(paths[3], dpi=150)
    hack_frame.to_csv(paths[4], index=False)
    paths[5].write_text(to_markdown(cfg, result, hack_frame, simulated, cost, history), encoding="utf-8")
    manifest = {
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
        "vlm_regime": cfg.vlm_regime,
        "notes": list(cfg.notes),
        "written_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "earlier_invocations": history,
    }
    paths[6].write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
    return paths
