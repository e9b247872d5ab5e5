"""`vlmrl study`: regimes x arms x seeds and the hybrid's VLM-quality variants, one regime map and report.

The study's own options are the fields of ``StudySettings`` (``study/settings.py``), one option
per field, built here from the field (``SETTING_OPTIONS``); its runs take `vlmrl run`'s options
(``RUN_OPTIONS``) and the VLM options; ``CLI_ONLY`` are the few that set no config key. Which
layer wins (file < ``--set`` < flags) is ``StudyConfig.from_sources``'s business, not this module's.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import sys
import typing
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from annotated_types import Ge
from rich.console import Console

from vlmrl_cli.cli import options as opt
from vlmrl_cli.cli.exit_codes import exit_codes
from vlmrl_cli.cli.progress import RichSweepReporter
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.core.fields import help_of, rules_of
from vlmrl_cli.study.settings import DEFAULT_ARMS, DEFAULT_EXPERIMENT, DEFAULT_SEEDS, Regimes, StudySettings
from vlmrl_cli.tasks.registry import command_tasks
from vlmrl_cli.vlm.config import VLMConfig

if TYPE_CHECKING:
    from vlmrl_cli.calibration.regimes import Regime
    from vlmrl_cli.study.config import StudyConfig
    from vlmrl_cli.study.pipeline import StudyResult

StudyArms = Annotated[str | None, typer.Option("--arms", help=f"Arms of every regime (default: "
                                                              f"{','.join(DEFAULT_ARMS)}).")]
DryRun = Annotated[bool, typer.Option("--dry-run", help="Print the grid and the cost estimate; train nothing.")]
NoTrain = Annotated[bool, typer.Option("--no-train", help="Analyse the runs already FINISHED and write the report; "
                                                          "train nothing (a long study's progress; the report says "
                                                          "PARTIAL and what is missing).")]

#: The options of the study's runs: `vlmrl run`'s, read as config keys by ``options.typed_flags``.
RUN_OPTIONS = ("arms", "task", "seeds", "seed_list", "timesteps", "workers", "executor", "ray_address",
               "eval_episodes", "experiment", "tracking_uri")
#: The options that set no config key: where the layers come from, and what to do with the study.
CLI_ONLY = ("config", "sets", "dry_run", "no_train")
#: The ``StudySettings`` fields whose option other commands share: the alias in ``cli/options.py``.
SHARED = {"margin": opt.Margin, "adjust": opt.Adjust}


def _names(text: str, flag: str) -> list[str]:
    """``"a,b"`` -> ["a", "b"]; ``"none"`` -> []; ``""`` or ``","`` is ``BadInput`` (an empty
    shell variable, not a choice: 'none' says it on purpose)."""
    if text.strip().lower() == "none":
        return []
    names = [t.strip() for t in text.split(",") if t.strip()]
    if not names:
        raise BadInput(f"{flag} lists no value, got '{text}'; pass comma-separated values, or 'none' for no run.")
    return opt.list_entries(text, flag)


def _numbers(text: str, flag: str) -> list[float]:
    try:
        return [float(v) for v in _names(text, flag)]
    except ValueError:
        raise BadInput(f"{flag} takes numbers like 0,0.1,0.3 or 'none', got '{text}'.") from None


def _regimes(texts: list[str], flag: str) -> dict[str, dict[str, Any]]:
    from vlmrl_cli.study.config import regimes_of  # the grid's module loads scipy: only when a study runs

    return regimes_of(texts)


def _as_typed(value: Any, flag: str) -> Any:
    return value


#: How the text of a flag becomes its field's value, by the field's type: (the option's type, the parser).
_SYNTAX: dict[Any, tuple[Any, Callable[[Any, str], Any]]] = {
    tuple[str, ...]: (str | None, _names),
    tuple[float, ...]: (str | None, _numbers),
    Regimes: (list[str] | None, _regimes),
}


@dataclass(frozen=True)
class SettingOption:
    """The option of one ``StudySettings`` field: a flag of the field's name (or its ``flag``), the
    field's help and checks (or the shared alias of ``SHARED``), and the parser of the flag's text."""

    name: str
    flag: str
    annotation: Any
    default: Any
    parse: Callable[[Any, str], Any]


def setting_option(f: dataclasses.Field[Any], hint: Any) -> SettingOption:
    """The option of field ``f`` (of type ``hint``). An option of its own defaults to None, "not
    given", and its help states the field's default; a shared one shows the field's default."""
    flag = str(f.metadata.get("flag", "--" + f.name.replace("_", "-")))
    if f.name in SHARED:
        return SettingOption(f.name, flag, SHARED[f.name], f.default, _as_typed)
    kind, parse = _SYNTAX.get(hint, (hint | None, _as_typed))
    least = typing.cast(float | None, next((rule.ge for rule in rules_of(f) if isinstance(rule, Ge)), None))
    return SettingOption(f.name, flag, Annotated[kind, typer.Option(flag, help=help_of(f), min=least)], None, parse)


_HINTS = typing.get_type_hints(StudySettings)
SETTING_OPTIONS = tuple(setting_option(f, _HINTS[f.name]) for f in dataclasses.fields(StudySettings))


def with_setting_options(command: Callable[..., None]) -> Callable[..., None]:
    """Give ``command`` the options of ``SETTING_OPTIONS``, first after its ``ctx``; it reads the
    ones typed with ``setting_flags(ctx)``."""
    hints = typing.get_type_hints(command, include_extras=True)
    own = [p.replace(annotation=hints.get(p.name, p.annotation), kind=inspect.Parameter.KEYWORD_ONLY)
           for p in inspect.signature(command).parameters.values()]
    added = [inspect.Parameter(o.name, inspect.Parameter.KEYWORD_ONLY, annotation=o.annotation, default=o.default)
             for o in SETTING_OPTIONS]
    params = [p for p in own if p.name == "ctx"] + added + [p for p in own if p.name != "ctx"]

    @functools.wraps(command)
    def wrapper(**kwargs: Any) -> None:
        for o in SETTING_OPTIONS:
            kwargs.pop(o.name)
        command(**kwargs)

    wrapper.__signature__ = inspect.Signature(params)  # type: ignore[attr-defined]
    wrapper.__annotations__ = {p.name: p.annotation for p in params}
    del wrapper.__wrapped__  # typer must see the merged signature, not the original
    return wrapper


def setting_flags(ctx: typer.Context) -> dict[str, Any]:
    """The study's settings typed on the command line, as dotted config keys (``{"study.alphas":
    [25.0]}``): the top layer of its ``[study]`` table."""
    return {f"study.{o.name}": o.parse(ctx.params[o.name], o.flag) for o in SETTING_OPTIONS if opt.given(ctx, o.name)}


@opt.with_vlm_options
@with_setting_options
def study(
    ctx: typer.Context,
    vlm_cfg: VLMConfig,
    arms: StudyArms = None,
    task: opt.TaskOpt = None,
    seeds: opt.Seeds = DEFAULT_SEEDS,
    seed_list: opt.SeedList = None,
    timesteps: opt.Timesteps = None,
    workers: opt.Workers = None,
    executor: opt.ExecutorOpt = None,
    ray_address: opt.RayAddress = None,
    eval_episodes: opt.EvalEpisodes = None,
    config: opt.ConfigFile = None,
    sets: opt.Sets = None,
    dry_run: DryRun = False,
    no_train: NoTrain = False,
    experiment: opt.Experiment = DEFAULT_EXPERIMENT,
    tracking_uri: opt.TrackingUri = None,
) -> None:
    """Run regimes x arms x seeds (and the hybrid under several simulated VLMs) through the resumable
    MLflow sweep; write the regime map, the VLM-quality figure and a report generated from the numbers."""
    from vlmrl_cli.core.paths import check_out_folder
    from vlmrl_cli.study.config import StudyConfig
    from vlmrl_cli.tracking.store import check_store

    console = Console()
    with exit_codes():
        cfg = StudyConfig.from_sources(config, opt.typed_flags(ctx, vlm_cfg) | setting_flags(ctx), sets or [],
                                       tasks=command_tasks([task]))
        check_out_folder(cfg.out)  # the pipeline checks it again; here, before its modules load (seconds)
        check_store(cfg.base.tracking_uri, write=not dry_run)  # before MLflow, the header or any file
        # the pipeline loads torch and MLflow (seconds): only once the store is known to be usable
        from vlmrl_cli.study.pipeline import estimate_cost, finished_per_seed, power_lines, run_study

        print_grid(console, cfg)
        cost = estimate_cost(cfg)
        console.print(f"cost estimate: {cost.line()}", markup=False)
        if dry_run:
            for line in power_lines(cfg, finished_per_seed(cfg)):
                console.print(line, markup=False)
            return
        result = run_study(cfg, functools.partial(_regime_reporter, console),
                           command=" ".join(["vlmrl", *sys.argv[1:]]), cost=cost, train=not no_train)
        print_result(console, result, cfg.out)


def print_grid(console: Console, cfg: StudyConfig) -> None:
    """The study's grid, before anything runs: its sweeps and their budgets, the notes, the VLM."""
    base = cfg.base
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


def _regime_reporter(console: Console, regime: Regime) -> RichSweepReporter:
    """The progress of one sweep of the study, under a line naming it."""
    console.print(f"[bold]{regime.id}[/]: {regime.label}", highlight=False)
    return RichSweepReporter(console)


def print_result(console: Console, result: StudyResult, out: Path) -> None:
    """What the study did: the failed runs (then exit 1: nothing was analysed), else its summary,
    wall time and files."""
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
