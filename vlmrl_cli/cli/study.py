"""`vlmrl study`: regimes x arms x seeds and the hybrid's VLM-quality variants, one regime map and report."""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console

from vlmrl_cli.cli import options as opt
from vlmrl_cli.cli.exit_codes import exit_codes
from vlmrl_cli.cli.progress import RichSweepReporter
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.vlm.config import VLMConfig

RegimeFlag = Annotated[
    list[str] | None,
    typer.Option(
        "--regime",
        help="A regime, repeatable: NAME (the preset of that name), NAME=PRESET, or NAME='KEY=VALUE KEY=VALUE' "
        "(--set assignments, e.g. hard='preset=paper ppo.normalize_obs=false ppo.normalize_reward=false'). "
        "Replaces the study.regimes table of --config and the default list (paper, paper-calibrated when that "
        "preset exists, hard).",
    ),
]
StudyArms = Annotated[str | None, typer.Option("--arms", help="Arms of every regime (default: "
                                                             "baseline,kinematic,semantic,hybrid).")]
Profiles = Annotated[
    str | None,
    typer.Option("--profiles", help="Simulated-VLM profiles of the hybrid's VLM-quality runs, comma-separated, or "
                                    "'none' (default: ideal,default,llava-table1)."),
]
Flickers = Annotated[
    str | None,
    typer.Option("--flickers", help="Flicker rates of the hybrid's VLM-quality runs (default profile), "
                                    "or 'none' (default: 0,0.1,0.3,0.5)."),
]
Alphas = Annotated[
    str | None,
    typer.Option("--alphas", help="PBRS scales of the dose-response cells, comma-separated, or 'none' "
                                  "(default: 5,25,100; alpha 0, the dense term alone, is always included)."),
]
KinScales = Annotated[
    str | None,
    typer.Option("--kin-scales", help="Kinematic scales of the dose-response cells, or 'none' (default: 0,0.5,2; "
                                      "0 is the VLM's potential alone)."),
]
QueryFlickers = Annotated[
    str | None,
    typer.Option("--query-flickers", help="Per-query (temporal) flicker rates at which hybrid and hybrid-no-lock "
                                          "are compared, or 'none' (default: 0.3)."),
]
VlmRegime = Annotated[
    str | None,
    typer.Option("--vlm-regime", help="Regime of the VLM-quality runs (default: paper-calibrated, else the first)."),
]
States = Annotated[int | None, typer.Option("--states", min=2,
                                           help="Taxonomy sweep positions per VLM variant (default 101).")]
DryRun = Annotated[bool, typer.Option("--dry-run", help="Print the grid and the cost estimate; train nothing.")]
NoTrain = Annotated[bool, typer.Option("--no-train", help="Analyse the runs already FINISHED and write the report; "
                                                          "train nothing (a long study's progress; the report says "
                                                          "PARTIAL and what is missing).")]
Out = Annotated[Path, typer.Option("--out", help="Output folder of the regime map, figure, report and manifest.")]


def _names(text: str | None, flag: str) -> list[str] | None:
    """``"a,b"`` -> ["a", "b"]; ``"none"`` -> []; None (not given) -> None; ``""`` or ``","`` is
    ``BadInput`` (an empty shell variable, not a choice: 'none' says it on purpose)."""
    if text is None:
        return None
    if text.strip().lower() == "none":
        return []
    names = [t.strip() for t in text.split(",") if t.strip()]
    if not names:
        raise BadInput(f"{flag} lists no value, got '{text}'; pass comma-separated values, or 'none' for no run.")
    return opt.list_entries(text, flag)


def _numbers(text: str | None, flag: str = "--flickers") -> list[float] | None:
    try:
        names = _names(text, flag)
        return None if names is None else [float(v) for v in names]
    except ValueError:
        raise BadInput(f"{flag} takes numbers like 0,0.1,0.3 or 'none', got '{text}'.") from None


def _pick(flag: list[float] | None, section: Mapping[str, Any], key: str, default: Sequence[float]
          ) -> Sequence[float]:
    """A list option: the flag when given, else the [study] table's, else the default."""
    return flag if flag is not None else section.get(key, default)


@opt.with_vlm_options
def study(
    ctx: typer.Context,
    vlm_cfg: VLMConfig,
    regime: RegimeFlag = None,
    arms: StudyArms = None,
    task: opt.TaskOpt = None,
    seeds: opt.Seeds = 20,
    seed_list: opt.SeedList = None,
    timesteps: opt.Timesteps = None,
    workers: opt.Workers = None,
    executor: opt.ExecutorOpt = None,
    ray_address: opt.RayAddress = None,
    eval_episodes: opt.EvalEpisodes = None,
    profiles: Profiles = None,
    flickers: Flickers = None,
    alphas: Alphas = None,
    kin_scales: KinScales = None,
    query_flickers: QueryFlickers = None,
    vlm_regime: VlmRegime = None,
    states: States = None,
    config: opt.ConfigFile = None,
    sets: opt.Sets = None,
    dry_run: DryRun = False,
    no_train: NoTrain = False,
    margin: opt.Margin = 1.15,
    adjust: opt.Adjust = "holm",
    out: Out = Path("results/study"),
    experiment: opt.Experiment = "vlmrl-study",
    tracking_uri: opt.TrackingUri = None,
) -> None:
    """Run regimes x arms x seeds (and the hybrid under several simulated VLMs) through the resumable
    MLflow sweep; write the regime map, the VLM-quality figure and a report generated from the numbers."""
    from vlmrl_cli.calibration.regimes import Regime
    from vlmrl_cli.study.config import (
        DEFAULT_ALPHAS,
        DEFAULT_FLICKERS,
        DEFAULT_KIN_SCALES,
        DEFAULT_PROFILES,
        DEFAULT_QUERY_FLICKERS,
        build_study,
        choose_regimes,
        study_section,
        task_name_of,
    )
    from vlmrl_cli.tracking.store import check_store

    console = Console()
    with exit_codes():
        file_layer, *upper = opt.config_layers(ctx, config, sets, vlm_cfg)
        section = study_section(file_layer.pop("study", {}))
        chosen, notes = choose_regimes(regime or [], section.get("regimes"), task_name_of([file_layer, *upper]))
        profile_list, flicker_list = _names(profiles, "--profiles"), _numbers(flickers)
        cfg = build_study(
            [file_layer, *upper], chosen,
            profiles=profile_list if profile_list is not None else section.get("profiles", DEFAULT_PROFILES),
            flickers=flicker_list if flicker_list is not None else section.get("flickers", DEFAULT_FLICKERS),
            alphas=_pick(_numbers(alphas, "--alphas"), section, "alphas", DEFAULT_ALPHAS),
            kin_scales=_pick(_numbers(kin_scales, "--kin-scales"), section, "kin_scales",
                             DEFAULT_KIN_SCALES),
            query_flickers=_pick(_numbers(query_flickers, "--query-flickers"), section,
                                 "query_flickers", DEFAULT_QUERY_FLICKERS),
            vlm_regime=vlm_regime or section.get("vlm_regime"), notes=notes, out=out, margin=margin, adjust=adjust,
            **({} if states is None else {"states": states}),
        )
        base = cfg.base
        check_store(base.tracking_uri, write=not dry_run)  # before MLflow, the header or any file
        # the pipeline loads torch and MLflow (seconds): only once the store is known to be usable
        from vlmrl_cli.study.pipeline import estimate_cost, finished_per_seed, power_lines, run_study

        console.print(f"[bold]vlmrl study[/]: {len(cfg.regimes)} regime(s) x arms {', '.join(base.arms)} x seeds "
                      f"{list(base.seeds)}, + {len(cfg.variants)} VLM variant(s) of the hybrid and "
                      f"{len(cfg.cells)} control cell(s) (dose-response, query flicker) in "
                      f"'{cfg.vlm_regime}'; experiment '{base.experiment}'")
        for r in cfg.all_regimes():
            console.print(f"  {r.id}: {r.label}, {r.run.budget:,} steps per run", markup=False)
        if cfg.variants:
            console.print(f"  taxonomy: {cfg.states} sweep positions per VLM variant", markup=False)
        for note in cfg.notes:
            console.print(f"[yellow]note:[/] {note}")
        if base.vlm.backend == "sim":
            console.print("[yellow]VLM: the SIMULATED VLM (a pixel-reading stand-in), not a real model.[/]")
        cost = estimate_cost(cfg)
        console.print(f"cost estimate: {cost.line()}", markup=False)
        if dry_run:
            for line in power_lines(cfg, finished_per_seed(cfg)):
                console.print(line, markup=False)
            return

        def reporter_for(r: Regime) -> RichSweepReporter:
            console.print(f"[bold]{r.id}[/]: {r.label}", highlight=False)
            return RichSweepReporter(console)

        result = run_study(cfg, reporter_for, command=" ".join(["vlmrl", *sys.argv[1:]]), cost=cost,
                           train=not no_train)
        if result.failed:
            for f in result.failed:
                console.print(f"[red]{f.job}: {f.status} {f.error or ''}[/]")
            console.print("Some runs failed; nothing was analysed. Rerun the same command to retry them.")
            raise typer.Exit(1)
        for line in result.summary:
            console.print(line, markup=False)
        stages = ", ".join(f"{s['stage']} {s['wall_s']:.0f} s" for s in result.stages)
        console.print(f"wall time: {result.wall_s:,.0f} s ({stages}); {result.trained} run(s) trained now")
        console.print(f"wrote {', '.join(p.name for p in result.files)} to {out}; MLflow run {result.run_id}")
