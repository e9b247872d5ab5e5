"""A ``Task``: everything the harness knows about one environment, in one object.

Training builds its envs with ``Task.make_env``, the reward wrapper reads the task's ``Scene``
(observation, dense term, simulator type), the camera comes from ``Task.make_camera``, the
simulated VLM reads milestones with ``Task.reader``, and reports take their thresholds and
success rule from here. MountainCar-v0, the paper's task, is one of them (``tasks/mountain_car``):
no layer below this one knows it.

A user's own task is a ``Task`` value in the user's code, loaded by ``--task package.module:NAME``
(see ``tasks/registry.py`` and the docs' "Add a task" page).
"""

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
#: How a command turns a task's name into its ``Task`` (``tasks.registry.get_task``, or a test's
#: own table): passed down to where a config is built, so nothing below looks a task up itself.
TaskLookup = Callable[[str], "Task"]

#: A preset that only checks the plumbing (seconds per run), as MountainCar's ``smoke``: a task's
#: ``presets["smoke"]`` may take it whole.
SMOKE: Mapping[str, Any] = {"n_envs": 2, "n_steps": 64, "batch_size": 64, "gae_lambda": 0.95, "gamma": 0.99,
                            "n_epochs": 1, "normalize_obs": True, "normalize_reward": True, "timesteps": 1_024,
                            "eval_episodes": 3}

#: SB3's PPO defaults (n_steps 2048, batch 64, 10 epochs, gae 0.95, lr 3e-4) on one env, without
#: normalisation, at 100,000 steps: a calibration candidate any task may take whole.
SB3_DEFAULT_100K: Mapping[str, Any] = {
    "n_envs": 1, "n_steps": 2048, "batch_size": 64, "gae_lambda": 0.95, "gamma": 0.99, "n_epochs": 10,
    "ent_coef": 0.0, "learning_rate": 3e-4, "normalize_obs": False, "normalize_reward": False, "timesteps": 100_000,
}


#: The command that measured every built-in task's ``random_score`` (``training.random_policy``).
RANDOM_SCORE_COMMAND = "python scripts/random_scores.py"


@dataclass(frozen=True)
class RandomScore:
    """A uniformly random policy's mean detached evaluation return on a task, and how it was
    measured: ``episodes`` episodes from ``seed`` (episode ``i`` resets with ``seed + i``, the
    action space seeded with ``seed``), printed by ``command``. The fixed 0 of ``vlmrl compare``."""

    mean: float
    episodes: int = 200
    seed: int = 0
    command: str = RANDOM_SCORE_COMMAND


@dataclass(frozen=True)
class Task:
    """One environment as the experiment sees it.

    Attributes:
        name: the ``--task`` name (``mountain-car``); runs are tagged ``vlmrl.task`` with it.
        env_id: the gymnasium id ``make_env`` builds (``MountainCar-v0``).
        summary: one line for ``--help`` and reports.
        scene: the observation shape, the dense "proprioceptive" term and the simulator type.
        milestones: the MCQ vocabulary (labels in order) and its prompt.
        label_potentials: the default raw potential of every label.
        truth: the true label of a simulator (the unwrapped env), for probes and diagnostics.
        camera: the run's camera (``TaskCamera``: its maker for a shaping config, the size of its
            frames' features, and optionally every frame it can show, for replay checks).
        reader: the simulated VLM's pixel reader (a ``NumberReader`` also answers ``numbers``).
        thresholds: reward thresholds of reports (rolling mean native return), lowest first.
        max_steps: the time limit; by default an episode succeeds when it terminates within it
            (``success``).
        presets: PPO presets as ``PPOConfig`` keyword arguments; at least ``zoo`` and ``smoke``.
        default_preset: the preset a run takes when none is named (``zoo``).
        zoo_reference: rl-baselines3-zoo's published PPO result for the env, cited (empty: none).
        random_score: a uniformly random policy's measured score (``RandomScore``; None: not
            measured): with the zoo's score, the fixed pair ``vlmrl compare`` normalises by.
        hover: the hovering diagnostic (``Hover``: the coordinate read from an observation, and
            where hovering starts); None: no diagnostic.
        numbers: the float and box questions of Table 1's rows I and II and of the
            ``vision-float`` arm, with what Table 1 needs to ask them of any reading (``NumberProbe``:
            a renderer, the answer key, Figure 1's frames; None: the picture has no number to ask
            for; its reader must be a ``NumberReader`` to answer them).
        probe_states: about ``n`` simulator states for ``vlmrl taxonomy``'s milestone table of
            this task, each drawn by the task's camera: state vectors (the probe sets them as
            ``sim.state``) or simulators themselves, for a task whose state is no vector (None:
            no such table).
        env_kwargs: keyword arguments of ``gym.make``.
        window: episodes in the rolling mean return that thresholds are read on (100, as SB3's
            ``ep_rew_mean``; fewer for a task whose episodes are long next to its budgets).
        calibration: the default grid of ``vlmrl calibrate --task``: overrides (``--set`` keys)
            over the task's default preset, one mapping per regime (empty: that preset alone).
        study_preset: the preset of ``vlmrl study --task``'s default regime, one calibrated so that
            the baseline is slow or unreliable (None: the default preset).
        area_margin: the equivalence margin of a learning-curve area difference, in return units
            (None: ``auc_margin``'s default, scaled to the task's return range).
        paper: the paper's own task (``PaperTask``: its reported figures and budget; MountainCar-v0
            alone): calibration aims at the paper's baseline itself, reports set their numbers
            beside the paper's, and its runs' config hashes name no task (they predate tasks).
        hacking_note: the report's reward-hacking heading and the sentence saying how the task's
            dense term can pay more than finishing (None: a generic one).
        caption: a played step's observation and action as named fields (``vlmrl evaluate``'s
            JSON) and one caption line of its GIF (``StepCaption``; None: the raw observation and
            action).
        scales: the task's alpha and kin_scale (``shaping.scales``: set by the stated rule from its
            return range), the bottom layer of a run's ``[shaping]``; None: the paper's MountainCar-v0
            scales (``ShapingConfig``'s defaults, alpha 5 and kin_scale 2).
        wrap: observation wrappers ``make_env`` puts around ``gym.make(env_id)`` (a grid world's
            Dict observation flattened for an MLP policy); None: the env as gymnasium makes it.
        success_rule: ``rule(terminated, length)``, whether an episode that ended after ``length``
            steps (``terminated``: the env ended it, not the time limit) succeeded; the one rule of
            training's ``is_success`` and episode records and of every evaluation (``success``).
            None: it terminated within ``max_steps`` (every built-in task).
        sim_profiles: the simulated-VLM profiles the task offers beside the generic ``ideal`` and
            ``default`` (``SimProfile``: a name and ``SimKnobs`` values in its reader's units;
            MountainCar's ``llava-table1``); a run may name only these (``vlm.sim.profile``).
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
    # Seconds per environment step and worker (2 workers on 2 cores) of the task's committed runs: the
    # cost estimate's figure before a store has timed any run of it (None: MountainCar-v0's repro).
    step_seconds: float | None = None
    scales: TaskScales | None = None
    success_rule: SuccessRule | None = None
    sim_profiles: tuple[SimProfile, ...] = ()

    @property
    def auc_margin(self) -> float:
        """The equivalence margin of a learning-curve area difference (return points): the task's
        own, else a twelfth of the span of its thresholds, which is MountainCar-v0's +-5 return
        points (-190 to -130); a task with one threshold takes a fortieth of its time limit.

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
        """A fresh env of this task (``gym.make(env_id)``, the time limit included).

        ``render_mode="rgb_array"`` draws off screen and needs no display; the process chooses its
        video driver where it starts (``vlmrl``'s entry point and the sweep's workers set SDL's
        dummy one), never here."""
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
        """Whether the task's name enters its runs' config hashes: not for the paper's task, whose
        runs predate tasks and keep their hashes."""
        return self.paper is None

    def success(self, terminated: bool, length: int) -> bool:
        """The one success rule of this task: its ``success_rule``, by default the episode
        terminated (goal reached) within the time limit.

        Example:
            >>> from vlmrl_cli.tasks.registry import get_task
            >>> car = get_task("mountain-car")
            >>> car.success(True, 120), car.success(True, 201), car.success(False, 200)
            (True, False, False)
            >>> dataclasses.replace(car, success_rule=lambda terminated, length: length >= 150).success(False, 200)
            True
        """
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
        """One line saying which of ``shaping``'s scales are this task's own (``scales``) in place of
        the paper's defaults (``ShapingConfig``'s alpha 5, kin_scale 2); None when none is.

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
