"""A ``Task``: everything the harness knows about one environment, in one object; no layer below
this one names an environment. A user's own task is loaded by ``--task package.module:NAME``
(``tasks/registry.py``). See docs/tasks.md."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym

from vlmrl_cli.shaping.config import ShapingConfig, label_problem
from vlmrl_cli.shaping.scales import TaskScales
from vlmrl_cli.shaping.scene import Scene, SuccessRule
from vlmrl_cli.tasks.capabilities import Hover, PaperTask, StepCaption, TaskCamera
from vlmrl_cli.vlm.config import SimProfile
from vlmrl_cli.vlm.prompts import Milestones, NumberProbe
from vlmrl_cli.vlm.sim import MilestoneReader, NumberReader

LabelMap = tuple[tuple[str, float], ...]
#: How a command turns a task's name into its ``Task``, passed down to where a config is built.
TaskLookup = Callable[[str], "Task"]

#: A preset that only checks the plumbing (seconds per run), for a task's ``presets["smoke"]``.
SMOKE: Mapping[str, Any] = {"n_envs": 2, "n_steps": 64, "batch_size": 64, "gae_lambda": 0.95, "gamma": 0.99,
                            "n_epochs": 1, "normalize_obs": True, "normalize_reward": True, "timesteps": 1_024,
                            "eval_episodes": 3}

#: SB3's PPO defaults on one env, without normalisation, at 100,000 steps: a calibration candidate.
SB3_DEFAULT_100K: Mapping[str, Any] = {
    "n_envs": 1, "n_steps": 2048, "batch_size": 64, "gae_lambda": 0.95, "gamma": 0.99, "n_epochs": 10,
    "ent_coef": 0.0, "learning_rate": 3e-4, "normalize_obs": False, "normalize_reward": False, "timesteps": 100_000,
}


#: The command that measured every built-in task's ``random_score`` (``training.random_policy``).
RANDOM_SCORE_COMMAND = "python scripts/random_scores.py"


@dataclass(frozen=True)
class RandomScore:
    """A uniformly random policy's mean evaluation return (``vlmrl compare``'s 0): ``episodes`` episodes,
    episode ``i`` reset with ``seed + i``, printed by ``command``."""

    mean: float
    episodes: int = 200
    seed: int = 0
    command: str = RANDOM_SCORE_COMMAND


@dataclass(frozen=True)
class Task:
    """One environment as the experiment sees it (docs/tasks.md, "Add a task").

    Attributes:
        name, summary: the ``--task`` name (runs are tagged ``vlmrl.task``) and one line for ``--help``.
        env_id, env_kwargs: what ``make_env`` passes to ``gym.make``.
        scene: the observation shape, the dense "proprioceptive" term and the simulator type.
        milestones, label_potentials: the MCQ vocabulary (low to high), its prompt, each label's potential.
        truth: the true label of a simulator (the unwrapped env), for probes and diagnostics.
        camera: the run's camera (``TaskCamera``); reader: the simulated VLM's pixel reader.
        thresholds: report thresholds on the rolling mean of ``window`` episodes' native return,
            lowest first.
        max_steps: the time limit; ``success_rule(terminated, length)`` (default: terminated within
            it) is the one success rule of training and every evaluation.
        presets: PPO presets as ``PPOConfig`` keyword arguments, at least ``zoo`` and ``smoke``;
            ``default_preset``, ``study_preset`` (``vlmrl study``'s regime) and ``calibration``
            (``vlmrl calibrate``'s grid: ``--set`` overrides, one mapping per regime) name them.
        zoo_reference, random_score: rl-baselines3-zoo's cited result and a random policy's measured
            score, the fixed pair ``vlmrl compare`` normalises by.
        area_margin: the equivalence margin of a learning-curve area (None: ``auc_margin``'s rule).
        scales: the task's alpha and kin_scale (None: the paper's MountainCar-v0 scales).
        wrap: observation wrappers ``make_env`` puts around the env (None: none).
        sim_profiles: simulated-VLM profiles beside the generic ``ideal`` and ``default``.
        hover, numbers, probe_states, paper, hacking_note, caption: optional capabilities
            (``tasks/capabilities.py``); None turns the feature off.
    """

    name: str
    env_id: str
    summary: str
    scene: Scene
    milestones: Milestones
    label_potentials: LabelMap
    truth: Callable[[Any], str]
    camera: TaskCamera
    reader: MilestoneReader
    thresholds: tuple[float, ...]
    max_steps: int
    presets: Mapping[str, Mapping[str, Any]]
    default_preset: str = "zoo"
    zoo_reference: str = ""
    random_score: RandomScore | None = None
    hover: Hover | None = None
    numbers: NumberProbe | None = None
    probe_states: Callable[[int], list[Any]] | None = None
    env_kwargs: Mapping[str, Any] = field(default_factory=dict)
    window: int = 100
    calibration: tuple[Mapping[str, Any], ...] = ()
    study_preset: str | None = None
    area_margin: float | None = None
    paper: PaperTask | None = None
    hacking_note: tuple[str, str] | None = None
    caption: StepCaption | None = None
    wrap: Callable[[gym.Env[Any, Any]], gym.Env[Any, Any]] | None = None
    # seconds per env step and worker of the committed runs, for cost estimates (None: MountainCar-v0's)
    step_seconds: float | None = None
    # the same for an arm that asks the VLM, where rendering and the RBF field cost more (None: step_seconds)
    vlm_step_seconds: float | None = None
    scales: TaskScales | None = None
    success_rule: SuccessRule | None = None
    sim_profiles: tuple[SimProfile, ...] = ()

    @property
    def auc_margin(self) -> float:
        """The equivalence margin of a learning-curve area difference (return points): the task's
        own, else a twelfth of its thresholds' span (MountainCar-v0: 5), else max_steps / 40.

        Example:
            >>> from vlmrl_cli.tasks.registry import get_task
            >>> get_task("mountain-car").auc_margin, get_task("acrobot").auc_margin
            (5.0, 25.0)
        """
        if self.area_margin is not None:
            return self.area_margin
        span = max(self.thresholds) - min(self.thresholds)
        return span / 12 if span > 0 else self.max_steps / 40

    def __post_init__(self) -> None:
        problem = label_problem(self.label_potentials, self.milestones.labels)
        if problem:
            raise ValueError(f"task '{self.name}': {problem}")
        if list(self.thresholds) != sorted(self.thresholds) or not self.thresholds:
            raise ValueError(f"task '{self.name}': give its reward thresholds lowest first")
        if not {"zoo", "smoke"} <= set(self.presets):
            raise ValueError(f"task '{self.name}': its presets must include 'zoo' and 'smoke'")
        if self.numbers is not None and not isinstance(self.reader, NumberReader):
            raise ValueError(f"task '{self.name}': it asks for numbers, so its reader must be a NumberReader "
                             "(estimate, label_at, box_at)")
        if self.window < 1:
            raise ValueError(f"task '{self.name}': its window must be at least 1 episode")
        if self.default_preset not in self.presets:
            raise ValueError(f"task '{self.name}': its default preset '{self.default_preset}' is not one of "
                             "its presets")
        if self.study_preset is not None and self.study_preset not in self.presets:
            raise ValueError(f"task '{self.name}': its study preset '{self.study_preset}' is not one of its presets")

    def make_env(self, render_mode: str | None = None) -> gym.Env[Any, Any]:
        """A fresh env of this task, the time limit included (the process chooses its video driver)."""
        env = gym.make(self.env_id, render_mode=render_mode, **dict(self.env_kwargs))
        return env if self.wrap is None else self.wrap(env)

    @property
    def probes_floats(self) -> bool:
        """Whether the float and box probe (and the ``vision-float`` arm) exist for this task."""
        return self.numbers is not None

    @property
    def hover_diagnostic(self) -> bool:
        """Whether its runs carry the hovering diagnostic (the plug-in gives a ``Hover``)."""
        return self.hover is not None

    @property
    def hover_from(self) -> float | None:
        """Where hovering starts (``Hover.start``); None without the diagnostic."""
        return None if self.hover is None else self.hover.start

    @property
    def name_in_identity(self) -> bool:
        """Whether the name enters config hashes: not for the paper's task, whose runs predate tasks."""
        return self.paper is None

    def success(self, terminated: bool, length: int) -> bool:
        """Whether an episode succeeded: ``success_rule``, by default terminated within the time limit."""
        if self.success_rule is not None:
            return bool(self.success_rule(bool(terminated), int(length)))
        return bool(terminated) and length <= self.max_steps

    def shaping_for(self, shaping: ShapingConfig) -> ShapingConfig:
        """``shaping`` with this task's label map where it names none (its default, empty)."""
        if shaping.label_potentials:
            return shaping
        return dataclasses.replace(shaping, label_potentials=self.label_potentials)

    def default_shaping(self) -> ShapingConfig:
        """The shaping a run of this task takes when it sets none: its label map and its scales."""
        shaping = self.shaping_for(ShapingConfig())
        if self.scales is None:
            return shaping
        knobs: dict[str, Any] = self.scales.knobs()
        return dataclasses.replace(shaping, **knobs)

    def scales_note(self, shaping: ShapingConfig) -> str | None:
        """One line naming ``shaping``'s scales that are the task's own, not the paper's; None when none is.

        Example:
            >>> from vlmrl_cli.tasks.registry import get_task
            >>> acrobot = get_task("acrobot")
            >>> acrobot.scales_note(acrobot.default_shaping())
            "the task's own scales alpha 107, kin_scale 0.152 replace the paper's defaults alpha 5, kin_scale 2"
            >>> acrobot.scales_note(dataclasses.replace(acrobot.default_shaping(), alpha=5.0))
            "the task's own scale kin_scale 0.152 replaces the paper's default kin_scale 2"
            >>> get_task("mountain-car").scales_note(ShapingConfig()) is None
            True
        """
        if self.scales is None:
            return None
        paper = ShapingConfig()
        own = [(name, value, getattr(paper, name)) for name, value in self.scales.knobs().items()
               if getattr(shaping, name) == value != getattr(paper, name)]
        if not own:
            return None
        ours = ", ".join(f"{name} {value:g}" for name, value, _ in own)
        theirs = ", ".join(f"{name} {value:g}" for name, _, value in own)
        many = len(own) > 1
        return (f"the task's own scale{'s' if many else ''} {ours} replace{'' if many else 's'} the paper's "
                f"default{'s' if many else ''} {theirs}")

    def labels_problem(self, label_potentials: LabelMap) -> str | None:
        """Why a label map does not fit this task (None when it does)."""
        return label_problem(label_potentials, self.milestones.labels)
