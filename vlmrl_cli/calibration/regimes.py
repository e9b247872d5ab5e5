"""The configuration of `vlmrl calibrate`: a base run configuration and a grid of PPO regimes, each
a set of overrides (dotted keys, as ``--set`` takes them) whose baseline arm x seeds is an ordinary
`vlmrl run` configuration. See docs/commands/calibrate.md and docs/tasks.md."""

from __future__ import annotations

import itertools
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from vlmrl_cli.analysis.defaults import DEFAULT_N_BOOT
from vlmrl_cli.core.errors import BadInput, did_you_mean, first_repeated
from vlmrl_cli.tasks.base import TaskLookup
from vlmrl_cli.tasks.registry import paper_task
from vlmrl_cli.training.config import RunConfig, once, resolve
from vlmrl_cli.training.overrides import dotted, nest, parse_assignment, parse_values

if TYPE_CHECKING:  # the profiles load pandas and scipy: only once a calibration's regimes are checked
    from vlmrl_cli.analysis.learning_profile import TargetProfile

DEFAULT_EXPERIMENT = "vlmrl-calibrate"
DEFAULT_SEEDS = 10
CALIBRATED_ARM = "baseline"

@dataclass(frozen=True)
class Regime:
    """One point of the grid: its short id (R1, R2, ...), its overrides, and the run config they give."""

    id: str
    overrides: tuple[tuple[str, Any], ...]
    run: RunConfig

    @property
    def label(self) -> str:
        """The overrides as ``--set`` would spell them, or ``base`` for none."""
        return _label(dict(self.overrides))


@dataclass(frozen=True)
class CalibrateConfig:
    """Everything one `vlmrl calibrate` does, as one value."""

    regimes: tuple[Regime, ...]
    target: TargetProfile
    out: Path = Path("results/calibration")
    window: int = 100  # episodes in the rolling mean return
    n_boot: int = DEFAULT_N_BOOT
    seed: int = 0  # seed of the bootstrap generator

    @property
    def base(self) -> RunConfig:
        return self.regimes[0].run


def grid_flags(items: Sequence[str]) -> dict[str, list[Any]]:
    """``--grid KEY=V1,V2`` flags -> ``{dotted key: values}``; a key given twice is ``BadInput``.

    Example:
        >>> grid_flags(["ppo.n_envs=1,4", "ppo.normalize_obs=true,false"])
        {'ppo.n_envs': [1, 4], 'ppo.normalize_obs': [True, False]}
    """
    out: dict[str, list[Any]] = {}
    for key, values in (parse_assignment(item, "--grid") for item in items):
        if key in out:
            raise BadInput(f"--grid {key} is given twice; list all its values once: --grid {key}=V1,V2,...")
        out[key] = parse_values(values)
    return out


def grid_product(grid: Mapping[str, Sequence[Any]]) -> list[dict[str, Any]]:
    """Every combination of the grid's values, first key outermost.

    Example:
        >>> grid_product({"a": [1, 2], "b": [True, False]})
        [{'a': 1, 'b': True}, {'a': 1, 'b': False}, {'a': 2, 'b': True}, {'a': 2, 'b': False}]
    """
    keys = list(grid)
    return [dict(zip(keys, combo, strict=True)) for combo in itertools.product(*(grid[k] for k in keys))]


def calibrate_section(raw: Mapping[str, Any]) -> dict[str, list[Any]]:
    """The grid of a config file's ``[calibrate]`` table (dotted keys or nested tables) -> ``{dotted key: values}``.

    Example:
        >>> calibrate_section({"grid": {"ppo": {"n_envs": [1, 4]}, "ppo.ent_coef": [0.0, 0.01]}})
        {'ppo.n_envs': [1, 4], 'ppo.ent_coef': [0.0, 0.01]}
    """
    if not isinstance(raw, Mapping):
        raise BadInput("[calibrate] must be a table, e.g. [calibrate.grid] with a list per key.")
    unknown = [k for k in raw if k != "grid"]
    if unknown:
        raise BadInput(
            f"unknown key 'calibrate.{unknown[0]}'{did_you_mean(unknown[0], ['grid'])}; [calibrate] holds only grid."
        )
    grid = raw.get("grid", {})
    if not isinstance(grid, Mapping):
        raise BadInput("calibrate.grid must be a table with a list of values per key.")
    flat = dotted(grid)
    for key, values in flat.items():
        if not isinstance(values, list) or not values:
            raise BadInput(f"calibrate.grid.{key} must be a non-empty list of values, got {json.dumps(values)}.")
    return flat


def build_regimes(layers: Sequence[Mapping[str, Any]], grid: Mapping[str, Sequence[Any]],
                  tasks: TaskLookup | None = None) -> tuple[Regime, ...]:
    """One validated ``RunConfig`` per regime: ``layers`` (file, ``--set``, flags) with the
    calibration's defaults below them, the regime's overrides and the baseline arm above them
    (``tasks``: the command's registry; None: the built-in tasks). Any invalid regime is ``BadInput``."""
    empty = [key for key, values in grid.items() if not values]
    if empty:
        raise BadInput(f"the grid of {empty[0]} lists no value; give at least one (e.g. --grid {empty[0]}=1,4).")
    for key, values in grid.items():
        twice = first_repeated([json.dumps(v) for v in values])
        if twice is not None:  # two regimes of one configuration: the same runs, ranked twice
            raise BadInput(f"the grid of {key} lists {twice} twice; list each value once (a repeated value makes two "
                           "regimes of one configuration).")
    base = {"experiment": DEFAULT_EXPERIMENT, "seeds": list(range(DEFAULT_SEEDS))}
    tasks = once(tasks)
    if grid:
        points = grid_product(grid)
    else:  # the task's own grid (``Task.calibration``), its default preset alone when that is empty
        points = [dict(r) for r in resolve([base, *layers], tasks).task_plugin.calibration or ({},)]
    _refuse_shadowed(layers, points, given_grid=bool(grid))
    return tuple(
        resolve_regime(f"R{i}", point, [base, *layers], {"arms": [CALIBRATED_ARM], "regime": _label(point)}, tasks)
        for i, point in enumerate(points, start=1)
    )


def _refuse_shadowed(layers: Sequence[Mapping[str, Any]], points: Sequence[Mapping[str, Any]], *, given_grid: bool
                     ) -> None:
    """``BadInput`` when a key the user set is also set by a regime, whose value would replace it silently."""
    typed = {key for layer in layers for key in dotted(layer)}
    for point in points:
        shadowed = sorted(typed & set(point))
        if shadowed:
            key = shadowed[0]
            values = sorted({json.dumps(p[key]) for p in points if key in p})
            where = "--grid" if given_grid else "the task's default calibration grid (Task.calibration)"
            hint = (f"give its values once in --grid {key}=..." if given_grid else
                    f"leave {key} out to calibrate the default grid, or name the candidates with --grid {key}=A,B")
            raise BadInput(f"{key} is set by you and by {where} ({key}={', '.join(values)}), whose value would "
                           f"replace yours; {hint}.")


def resolve_regime(
    rid: str, point: Mapping[str, Any], layers: Sequence[Mapping[str, Any]], top: Mapping[str, Any],
    tasks: TaskLookup | None = None,
) -> Regime:
    """The validated ``Regime`` ``rid``: ``layers`` (lowest first), then the point's overrides, then
    ``top`` (top-level keys such as ``arms``); an invalid regime is ``BadInput`` naming it."""
    try:
        run = resolve([*layers, nest(point.items()) | dict(top)], tasks)
    except BadInput as exc:
        raise BadInput(f"regime {rid} ({_label(point)}): {exc}") from None
    return Regime(rid, tuple(point.items()), run)


def calibrate_config(regimes: tuple[Regime, ...], **settings: Any) -> CalibrateConfig:
    """The ``CalibrateConfig`` of ``regimes``, scored against their task's target on its window; a
    grid that spans two tasks is ``BadInput``."""
    tasks = sorted({r.run.task for r in regimes})
    if len(tasks) > 1:
        raise BadInput(f"the regimes span tasks {', '.join(tasks)}; calibrate one task at a time (--task).")
    base = regimes[0].run
    settings.setdefault("target", calibration_target(base))
    settings.setdefault("window", base.task_plugin.window)
    return CalibrateConfig(regimes, **settings)


def calibration_target(run: RunConfig) -> TargetProfile:
    """The paper's baseline for the task it reports, else its shape on the task's thresholds and the
    run's budget (``scaled_target``)."""
    from vlmrl_cli.analysis.learning_profile import paper_baseline, scaled_target

    task, papers = run.task_plugin, paper_task().paper
    assert papers is not None  # paper_task() is the task that has one
    if task.paper is not None:
        return paper_baseline(task.paper.reported)
    return scaled_target(task.thresholds, run.budget, paper_baseline(papers.reported), papers.budget)


def _label(point: Mapping[str, Any]) -> str:
    return " ".join(f"{k}={json.dumps(v)}" for k, v in point.items()) or "base"
