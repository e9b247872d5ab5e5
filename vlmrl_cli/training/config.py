"""The configuration of `vlmrl run`: one frozen ``RunConfig``, resolved from layers (preset < TOML
file < ``--set`` < flags, ``training/overrides.py``) and checked whole (``training/validation.py``)."""

from __future__ import annotations

import dataclasses
import functools
import json
import os
import tomllib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomli_w
from annotated_types import Ge, Gt
from pydantic import AfterValidator

from vlmrl_cli.core.errors import BadInput, first_repeated
from vlmrl_cli.core.fields import CARRIED, one_of
from vlmrl_cli.core.names import experiment_problem, tracking_uri_problem
from vlmrl_cli.core.provenance import config_hash, flatten, to_jsonable
from vlmrl_cli.shaping.arms import ARMS, ArmSpec, PotentialSource, parse_arms
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.tasks.base import Task, TaskLookup
from vlmrl_cli.training.events import EXECUTORS
from vlmrl_cli.training.overrides import nest, parse_assignment, parse_value, resolve_raw, task_ref
from vlmrl_cli.training.presets import PPOConfig, ppo_identity, preset_of
from vlmrl_cli.vlm.config import VLMConfig, profile_problem, vlm_identity

DEFAULT_EXPERIMENT = "vlmrl"
#: The task of a config that names none (``vlmrl run`` without ``--task``), and its preset (the
#: task's ``default_preset``; a test checks that the two agree). Nothing below this layer knows it.
DEFAULT_TASK = "mountain-car"
DEFAULT_PRESET = "paper"
EVAL_SEED = 1_000_000  # detached evaluation episode i resets with seed EVAL_SEED + i


def _known_arms(arms: tuple[str, ...]) -> tuple[str, ...]:
    try:
        parse_arms(",".join(arms))
    except BadInput as exc:
        raise ValueError(str(exc).removesuffix(".")) from None
    return arms


#: The most seeds of one configuration: past any power a study here needs (the committed use 20).
MAX_SEEDS = 1_000
#: The largest seed: numpy takes 32-bit seeds, and env i of a run is seeded with seed + i.
MAX_SEED = 2**31 - 1


def seed_count_problem(n: int) -> str | None:
    """Why ``n`` seeds are too many for one configuration (None when they are not).

    Example:
        >>> seed_count_problem(20) is None, seed_count_problem(10**8)
        (True, 'at most 1,000 seeds, got 100,000,000: each trains a run per arm; the committed studies use 20')
    """
    if n > MAX_SEEDS:
        return f"at most {MAX_SEEDS:,} seeds, got {n:,}: each trains a run per arm; the committed studies use 20"
    return None


def _distinct_seeds(seeds: tuple[int, ...]) -> tuple[int, ...]:
    if not seeds:
        raise ValueError("no seed given; pass --seeds N (N >= 1) or --seed-list 0,1,2")
    problem = seed_count_problem(len(seeds))
    if problem:
        raise ValueError(problem)
    if len(set(seeds)) != len(seeds):
        raise ValueError("a seed is listed twice; list each seed once")
    if any(s < 0 for s in seeds):
        raise ValueError("seeds must be non-negative integers")
    if any(s > MAX_SEED for s in seeds):
        raise ValueError(f"seeds are at most {MAX_SEED:,} (numpy takes 32-bit seeds, and env i of a run is seeded "
                         "with seed + i)")
    return seeds


def _no_problem(problem: Callable[[Any], str | None]) -> Callable[[Any], Any]:
    """A field rule: the value, or a ValueError saying ``problem``'s sentence."""
    def check(value: Any) -> Any:
        if why := problem(value):
            raise ValueError(why)
        return value
    return check


def _builtin_presets() -> list[str]:
    """The presets of the built-in tasks this machine can run (the run's task checks its own)."""
    from vlmrl_cli.tasks.registry import BUILTIN

    known: list[str] = []
    for load in BUILTIN.values():
        try:
            task = load()
        except BadInput:  # an optional extra missing (Pusher without MuJoCo): naming the task says why
            continue
        known += [name for name in task.presets if name not in known]
    return known


def _default_plugin() -> Task:
    """The Task of a config that names none (``DEFAULT_TASK``)."""
    from vlmrl_cli.tasks.registry import builtin_task

    return builtin_task(DEFAULT_TASK)


@dataclass(frozen=True)
class RunConfig:
    """Everything `vlmrl run` does, as one value: logged whole, hashed per job for resume."""

    arms: tuple[str, ...] = field(default=("baseline", "hybrid"), metadata={"rules": (AfterValidator(_known_arms),),
                                                                            "help": "arms to train (shaping/arms.py)"})
    seeds: tuple[int, ...] = field(default=(0, 1, 2, 3, 4), metadata={"rules": (AfterValidator(_distinct_seeds),),
                                                                      "help": "training seeds, each a run per arm"})
    preset: str = field(default=DEFAULT_PRESET, metadata={
        "rules": (AfterValidator(one_of(_builtin_presets, "preset")),),
        "help": "named PPO preset: the bottom layer of [ppo]"})
    task: str = field(default=DEFAULT_TASK, metadata={
        "help": "the environment: a built-in task (tasks/registry.py) or package.module:NAME"})
    workers: int = field(default_factory=lambda: os.cpu_count() or 1, metadata={"rules": (Ge(1),),
        "help": "worker processes (one torch thread each); default: the cores"})
    experiment: str = field(default=DEFAULT_EXPERIMENT, metadata={
        "rules": (AfterValidator(_no_problem(experiment_problem)),), "help": "MLflow experiment of the runs"})
    tracking_uri: str | None = field(default=None, metadata={
        "rules": (AfterValidator(_no_problem(tracking_uri_problem)),),
        "help": "MLflow store; None: $MLFLOW_TRACKING_URI or sqlite:///mlflow.db"})
    ppo: PPOConfig | None = field(default=None, metadata={"help": "None = the preset's values"})
    vlm: VLMConfig = field(default_factory=VLMConfig)
    shaping: ShapingConfig = field(default_factory=ShapingConfig)
    regime: str | None = field(default=None, metadata={"help": "calibration regime label (a tag, not hashed)"})
    # where and how the jobs run: none of these changes what a run computes, so none is hashed
    executor: str = field(default="local", metadata={"rules": (AfterValidator(one_of(EXECUTORS, "executor")),),
                                                     "help": "local (a process pool) or ray"})
    ray_address: str | None = field(default=None, metadata={
        "help": "Ray cluster to join (None: a running local cluster, else a new local instance)"})
    max_retries: int = field(default=2, metadata={"rules": (Ge(0),),
                                                  "help": "Ray retries of a job whose worker process died"})
    heartbeat_s: float = field(default=30.0, metadata={"rules": (Gt(0),),
                                                       "help": "how often a training run refreshes its heartbeat"})
    stale_after_s: float = field(default=300.0, metadata={"rules": (Gt(0),),
        "help": "a RUNNING run whose heartbeat is older is taken as dead and its job redone"})
    # the Task ``task`` names, resolved once where the config is built (``resolve``), never again
    plugin: Task = field(default_factory=_default_plugin, compare=False, repr=False, metadata=CARRIED)

    def __post_init__(self) -> None:
        _check_plugin(self.task, self.plugin)
        if self.stale_after_s < 2 * self.heartbeat_s:
            raise BadInput(f"stale_after_s ({self.stale_after_s:g}) must be at least twice heartbeat_s "
                           f"({self.heartbeat_s:g}), or live runs would be taken for dead ones.")

    @classmethod
    def from_sources(cls, file: Path | None, flags: Mapping[str, Any] | None = None, overrides: Iterable[str] = (),
                     tasks: TaskLookup | None = None) -> RunConfig:
        """The validated config of a TOML ``file``, ``--set`` ``overrides`` and dotted-key ``flags``
        (preset < file < overrides < flags), its task looked up by ``tasks`` (None: the built-ins)."""
        return resolve(source_layers(file, flags or {}, overrides), tasks)

    def validate(self) -> None:
        """Raise ``BadInput`` for anything that would fail later (for a config built by hand)."""
        from vlmrl_cli.training.validation import validate_as

        validate_as(RunConfig, to_jsonable(self), plugin=self.plugin)
        self._check_task()

    def _check_task(self) -> None:
        """What only the task can say: its presets, its labels, the arms it supports."""
        task = self.task_plugin
        if self.ppo is None:
            preset_of(task, self.preset)  # a BadInput naming the task's presets
        problem = task.labels_problem(self.task_shaping.label_potentials)
        if problem:
            raise BadInput(f"shaping.label_potentials: {problem} (task {self.task}).")
        profile = profile_problem(self.vlm.sim.profile, task)
        if profile:
            raise BadInput(f"vlm.sim.profile: {profile}.")
        floats = [a for a in self.arms if ARMS[a].potential is PotentialSource.FLOAT]
        if floats and not task.probes_floats:
            raise BadInput(f"arm '{floats[0]}' asks the VLM for a number, which task {self.task} does not "
                           "support; choose arms with MCQ milestones.")

    @property
    def task_plugin(self) -> Task:
        """The Task object this run trains on (``plugin``, resolved when the config was built)."""
        return self.plugin

    @property
    def task_shaping(self) -> ShapingConfig:
        """``shaping`` with the task's label map when it names none (the field's default)."""
        return self.plugin.shaping_for(self.shaping)

    @property
    def ppo_config(self) -> PPOConfig:
        """The PPO knobs of every job: ``ppo``, or the preset's when that is None."""
        return self.ppo if self.ppo is not None else preset_of(self.plugin, self.preset)

    @property
    def budget(self) -> int:
        return self.ppo_config.timesteps

    def jobs(self) -> list[TrainJob]:
        """One job per (arm, seed), arms in the given order, seeds inner."""
        ppo, shaping = self.ppo_config, self.task_shaping
        return [TrainJob(arm=ARMS[arm], seed=seed, preset=self.preset, ppo=ppo, vlm=self.vlm, shaping=shaping,
                         regime=self.regime, task=self.task, plugin=self.plugin)
                for arm in self.arms for seed in self.seeds]


@dataclass(frozen=True)
class TrainJob:
    """One (arm, seed) training run and its detached evaluation."""

    arm: ArmSpec
    seed: int
    preset: str
    ppo: PPOConfig
    vlm: VLMConfig
    shaping: ShapingConfig
    regime: str | None = None
    task: str = field(kw_only=True)  # the run's task (tasks/registry.py), as it is hashed and logged
    # the RunConfig's; None after pickling (a worker resolves it at its entry: ``sweep.worker.with_task``)
    plugin: Task | None = field(default=None, kw_only=True, compare=False, repr=False, metadata=CARRIED)

    def __post_init__(self) -> None:
        if self.plugin is not None:
            _check_plugin(self.task, self.plugin)

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "plugin": None}

    @property
    def name(self) -> str:
        return f"{self.arm.name}-s{self.seed}"

    @property
    def task_plugin(self) -> Task:
        """The Task object this job trains on (``plugin``)."""
        if self.plugin is None:
            raise RuntimeError(f"job {self.name}'s task was not resolved here: a config is built by resolve(), "
                               "and a sweep worker resolves a job's task at its entry (sweep.worker.with_task)")
        return self.plugin

    @property
    def timesteps(self) -> int:
        return self.ppo.timesteps

    @property
    def eval_episodes(self) -> int:
        return self.ppo.eval_episodes

    def identity(self) -> dict[str, Any]:
        """What makes two runs the same experiment cell, seed excluded: the resolved values, not the
        preset's name; the VLM and shaping knobs only for arms that use them; never cache settings."""
        ident: dict[str, Any] = {"arm": self.arm.identity(), "ppo": ppo_identity(self.ppo), "eval_seed": EVAL_SEED}
        if self.task_plugin.name_in_identity:  # False for MountainCar-v0: its runs predate tasks
            ident["task"] = self.task
        if self.arm.kinematic or self.arm.uses_vlm:
            ident["shaping"] = to_jsonable(self.shaping)
        if self.arm.uses_vlm:  # knobs added later count only off their neutral value: older runs keep their hash
            ident["vlm"] = vlm_identity(self.vlm)
        return ident

    @property
    def config_hash(self) -> str:
        return config_hash(self.identity())

    def params(self) -> dict[str, Any]:
        """The whole job config, for MLflow params."""
        return {"seed": self.seed, "preset": self.preset, **self.identity()}

    def overrides(self) -> dict[str, str]:
        """The identity's knobs that differ from the preset's and the defaults, as dotted keys."""
        reference = dataclasses.replace(self, ppo=preset_of(self.task_plugin, self.preset), vlm=VLMConfig(),
                                        shaping=self.task_plugin.default_shaping())
        ref = flatten(reference.identity())
        return {k: v for k, v in flatten(self.identity()).items() if ref.get(k) != v}


# --- building from layers and back to TOML -----------------------------------------------


def resolve(layers: Iterable[Mapping[str, Any]], tasks: TaskLookup | None = None) -> RunConfig:
    """The validated ``RunConfig`` of ``layers`` (lowest first): the one place a config's task name
    becomes its Task, looked up with ``tasks`` (None: the built-in tasks alone)."""
    from vlmrl_cli.tasks.registry import builtin_task
    from vlmrl_cli.training.validation import validate_as

    layers = list(layers)
    ref, task = task_ref(layers, DEFAULT_TASK), None
    if isinstance(ref, str):  # else the schema says what is wrong
        try:
            task = (tasks or builtin_task)(ref)
        except BadInput as exc:
            msg = str(exc).removesuffix(".")
            raise BadInput(f"invalid task = {json.dumps(ref)}: {msg[:1].lower() + msg[1:]}.") from None
    raw = resolve_raw(layers, task)
    cfg: RunConfig = validate_as(RunConfig, raw) if task is None else validate_as(RunConfig, raw, plugin=task)
    cfg._check_task()
    return cfg


def once(tasks: TaskLookup | None) -> TaskLookup:
    """``tasks`` (None: the built-in tasks alone) looking each name up once.

    Example:
        >>> lookup = once(None)
        >>> lookup("acrobot") is lookup("acrobot")
        True
    """
    from vlmrl_cli.tasks.registry import builtin_task

    return functools.cache(tasks or builtin_task)


def _check_plugin(task: str, plugin: Task) -> None:
    """A config's ``plugin`` is the Task its ``task`` names (checked for a built-in name)."""
    from vlmrl_cli.tasks.registry import BUILTIN

    if task in BUILTIN and plugin.name != task:
        raise ValueError(f"the config names task '{task}' but carries task '{plugin.name}'; build it with "
                         "resolve() (or pass plugin=)")


def source_layers(file: Path | None, flags: Mapping[str, Any], sets: Iterable[str]) -> list[dict[str, Any]]:
    """The raw layers above the preset, lowest first: the config ``file`` (or none), the ``--set``
    assignments ``sets``, then ``flags`` (dotted keys)."""
    file_layer = load_config_file(file) if file is not None else {}
    assignments = [parse_assignment(text) for text in sets]
    twice = first_repeated([key for key, _ in assignments])
    if twice is not None:  # the last would win without a word
        values = " and ".join(f"--set {key}={value}" for key, value in assignments if key == twice)
        raise BadInput(f"{values} set one key twice; set each key once.")
    set_layer = nest((key, parse_value(value)) for key, value in assignments)
    return [file_layer, set_layer, nest(flags.items())]


def to_toml(cfg: RunConfig) -> str:
    """``cfg`` as a complete TOML config file that ``--config`` reads back to the same ``cfg``; keys
    whose value is None are left out (TOML has no null; every such key defaults to None)."""
    raw = to_jsonable(dataclasses.replace(cfg, ppo=cfg.ppo_config, shaping=cfg.task_shaping))
    raw["shaping"]["label_potentials"] = dict(raw["shaping"]["label_potentials"])
    return tomli_w.dumps(_drop_none(raw))


def _drop_none(tree: dict[str, Any]) -> dict[str, Any]:
    return {k: _drop_none(v) if isinstance(v, dict) else v for k, v in tree.items() if v is not None}


def load_config_file(path: Path) -> dict[str, Any]:
    """Parse a TOML config file into a raw nested dict (checked later, with every other layer)."""
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise BadInput(f"cannot read the config file {path}: {exc.strerror}.") from exc
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise BadInput(f"the config file {path} is not valid TOML ({exc}).") from exc
