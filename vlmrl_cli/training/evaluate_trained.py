"""`vlmrl evaluate`: re-evaluate a trained run from MLflow (detached, no VLM in the loop) and write
one episode as a captioned GIF, with the run's VLM's label of each frame for arms that use one."""

from __future__ import annotations

import json
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.core.paths import SCRATCH, check_out_folder
from vlmrl_cli.frames.gif import captioned, write_gif
from vlmrl_cli.shaping.arms import PotentialSource
from vlmrl_cli.shaping.camera import FrameView
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.shaping.scene import SceneCamera
from vlmrl_cli.tasks.base import Task, TaskLookup
from vlmrl_cli.tracking import store
from vlmrl_cli.training.config import EVAL_SEED
from vlmrl_cli.training.evaluation import EvalResult, Policy, evaluate_detached
from vlmrl_cli.training.trained import TrainedRun, load_trained_run
from vlmrl_cli.vlm.config import DEFAULT_CACHE

#: Under the git-ignored scratch folder: run from the repository, a default never overwrites the
#: committed results (results/tasks/*/evaluate/ were written with --out).
DEFAULT_ROOT = SCRATCH / "evaluate"
ARTIFACT_PATH = "evaluate"
SIMULATED_ALERT = "SIMULATED VLM (not a real model)"
MAX_EPISODES = 10_000


@dataclass(frozen=True)
class EvaluateConfig:
    """Everything `vlmrl evaluate` does, as one value."""

    run_id: str
    tracking_uri: str | None = None
    out: Path | None = field(default=None, metadata={"help": "None = results/_scratch/evaluate/<run_id>"})
    episodes: int = field(default=10, metadata={"help": "detached episodes; episode i resets with EVAL_SEED + i"})
    episode_index: int = field(default=0, metadata={"help": "which of them the GIF shows"})
    frame_every: int = field(default=2, metadata={"help": "keep every k-th frame in the GIF"})
    width: int = field(default=300, metadata={"help": "GIF width, pixels"})
    use_cache: bool = True
    cache_path: Path | None = DEFAULT_CACHE
    trust_pickle: bool = field(default=False, metadata={"help": "load an old run's pickled normaliser"})

    @property
    def out_dir(self) -> Path:
        return self.out if self.out is not None else DEFAULT_ROOT / self.run_id

    def validate(self) -> None:
        """Raise ``BadInput`` for anything that would fail later; nothing is read before."""
        if not self.run_id.strip():
            raise BadInput("the run id is empty; copy one from `vlmrl run`'s output or the MLflow UI.")
        if not 1 <= self.episodes <= MAX_EPISODES:
            raise BadInput(f"--episodes must be in 1..{MAX_EPISODES:,} (each is a whole episode; 100 give a success "
                           f"rate to within about 0.1), got {self.episodes}.")
        if not 0 <= self.episode_index < self.episodes:
            raise BadInput(f"--episode-index must be in 0..{self.episodes - 1} (one of the evaluated episodes), "
                           f"got {self.episode_index}.")
        if self.frame_every < 1 or self.width < 16:
            raise BadInput("the GIF needs frame_every >= 1 and a width of at least 16 pixels.")
        check_out_folder(self.out_dir)


@dataclass(frozen=True)
class PlayedStep:
    """The state after ``t`` steps of an episode, and ``action`` and ``r_kin`` of step ``t`` (None
    and 0.0 at the reset); ``pixels`` (and the training camera's ``view``) only for the GIF's frames."""

    t: int
    obs: tuple[float, ...]
    action: Any
    r_kin: float
    native_return: float
    terminated: bool = False
    pixels: np.ndarray | None = field(default=None, repr=False)
    view: FrameView | None = field(default=None, repr=False)


def play_episode(policy: Policy, seed: int, shaping: ShapingConfig, task: Task, frame_every: int = 2,
                 camera: SceneCamera | None = None) -> list[PlayedStep]:
    """One native episode of ``task`` from ``seed``, every ``frame_every``-th state and the last rendered."""
    env: Any = task.make_env(render_mode="rgb_array")  # gymnasium's rgb_array renderer, headless

    def step_of(t: int, obs: np.ndarray, action: Any, r_kin: float, total: float, terminated: bool,
                keep: bool) -> PlayedStep:
        values = tuple(float(v) for v in np.asarray(obs, dtype=float).reshape(-1))
        return PlayedStep(t, values, _plain(action), r_kin, total, terminated,
                          np.asarray(env.render()) if keep else None,
                          camera.look(env.unwrapped) if keep and camera is not None else None)

    try:
        obs, _ = env.reset(seed=seed)
        steps = [step_of(0, obs, None, 0.0, 0.0, False, True)]
        done, total, t = False, 0.0, 0
        while not done:
            action = policy(obs)
            obs, reward, terminated, truncated, _ = env.step(action)
            t += 1
            total += float(reward)
            done = bool(terminated or truncated)
            r_kin = task.scene.dense(obs, shaping.kin_scale, shaping.kin_offset)
            steps.append(step_of(t, obs, action, r_kin, total, bool(terminated), done or t % frame_every == 0))
    finally:
        env.close()
    return steps


def _plain(action: Any) -> Any:
    """An action as JSON writes it: an int (discrete), a float or a list of floats (continuous)."""
    if action is None or isinstance(action, int):
        return action
    flat = np.asarray(action).reshape(-1)
    if flat.dtype.kind in "iu" and flat.size == 1:
        return int(flat[0])
    return float(flat[0]) if flat.size == 1 else [float(a) for a in flat]


@dataclass(frozen=True)
class FrameLabel:
    """The run's VLM's parsed answer about one frame (or why none) and its raw potential."""

    answer: str
    potential: float | None

    @property
    def caption(self) -> str:
        phi = f"{self.potential:.2f}" if self.potential is not None else "-"
        return f"VLM {self.answer}  Phi_raw {phi}"


def label_frames(run: TrainedRun, views: list[FrameView], cfg: EvaluateConfig) -> list[FrameLabel]:
    """Ask the run's VLM (its own config; cache as ``cfg`` says) about each of the camera's views."""
    from vlmrl_cli.shaping.placebo import oracle_shaping
    from vlmrl_cli.vlm.parsers import parse_float, parse_mcq
    from vlmrl_cli.vlm.registry import build_client

    task = run.task
    mcq = run.arm.potential is PotentialSource.MCQ
    label_map = oracle_shaping(run.arm, task.shaping_for(run.shaping), run.seed)  # a placebo's shuffled map
    numbers = task.numbers
    if not mcq and numbers is None:
        raise BadInput(f"run {run.run_id} asks for a number, which task {task.name} does not ask for")
    prompt = task.milestones.prompt if mcq or numbers is None else numbers.float_prompt
    client = build_client(replace(run.vlm, use_cache=cfg.use_cache, cache_path=cfg.cache_path), reader=task.reader)
    labels = []
    try:
        for view in views:
            text = client.ask(prompt, view.frame()).text
            if mcq:
                label = parse_mcq(text, task.milestones.labels)
                labels.append(FrameLabel(str(label.label), label_map.potential_of(label.label))
                              if label.ok and label.label is not None else FrameLabel(f"({label.status})", None))
            else:
                assert numbers is not None
                number = parse_float(text, numbers.low, numbers.high)
                labels.append(FrameLabel(f"x={number.value:+.3f}", numbers.potential(number.value))
                              if number.ok and number.value is not None else FrameLabel(f"({number.status})", None))
    finally:
        client.close()
    return labels


def describe_step(task: Task, obs: tuple[float, ...], action: Any) -> tuple[dict[str, Any], str]:
    """A played step as JSON fields and a caption line: the task's (``Task.caption``), else raw."""
    if task.caption is not None:
        return task.caption(obs, action)
    shown = "-" if action is None else (f"{action:+.2f}" if isinstance(action, float) else str(action))
    return {"obs": list(obs)}, f"obs [{' '.join(f'{v:+.2f}' for v in obs[:6])}]  action {shown}"


@dataclass(frozen=True)
class EvaluateResult:
    run: TrainedRun
    result: EvalResult
    gif: Path
    summary: Path
    frames: int
    gif_bytes: int


def evaluate_run(cfg: EvaluateConfig, tasks: TaskLookup) -> EvaluateResult:
    """Evaluate run ``cfg.run_id``; write ``episode-<i>.gif`` and ``evaluation.json`` to ``cfg.out_dir``
    and log them as the run's artifacts (``BadInput`` before any folder is made)."""
    cfg.validate()
    client = store.connect_existing(cfg.tracking_uri)
    with tempfile.TemporaryDirectory(prefix="vlmrl-evaluate-") as tmp:
        run = load_trained_run(client, cfg.run_id, Path(tmp), tasks, cfg.trust_pickle)
    task = run.task
    result = evaluate_detached(run.policy, cfg.episodes, EVAL_SEED, task)
    seed = EVAL_SEED + cfg.episode_index
    camera = task.camera.make(run.shaping) if run.arm.uses_vlm else None
    try:
        steps = play_episode(run.policy, seed, run.shaping, task, cfg.frame_every, camera)
        shown = [s for s in steps if s.pixels is not None]
        labels = (label_frames(run, [s.view for s in shown if s.view is not None], cfg)
                  if run.arm.uses_vlm else None)
    finally:
        if camera is not None:
            camera.close()
    alert = SIMULATED_ALERT if run.arm.uses_vlm and run.simulated else None
    images = []
    for i, (step, pixels) in enumerate((s, s.pixels) for s in shown if s.pixels is not None):
        lines = [f"{run.name}  episode {cfg.episode_index}  step {step.t}/{steps[-1].t}",
                 describe_step(task, step.obs, step.action)[1],
                 f"R_kin {step.r_kin:.2f}  native return {step.native_return:.0f}"]
        if labels is not None:
            lines.append(labels[i].caption)
        images.append(captioned(pixels, lines, cfg.width, alert))

    out = cfg.out_dir
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BadInput(f"cannot create the output folder {out} ({exc.strerror}).") from exc
    gif = out / f"episode-{cfg.episode_index}.gif"
    write_gif(images, gif)
    summary = out / "evaluation.json"
    figures = _summary(run, result, cfg, steps, shown, labels, gif)
    summary.write_text(json.dumps(figures, indent=2) + "\n", encoding="utf-8")
    store.log_artifacts(client, run.run_id, [gif, summary], artifact_path=ARTIFACT_PATH)
    return EvaluateResult(run, result, gif, summary, len(images), gif.stat().st_size)


def _summary(
    run: TrainedRun,
    result: EvalResult,
    cfg: EvaluateConfig,
    steps: list[PlayedStep],
    shown: list[PlayedStep],
    labels: list[FrameLabel] | None,
    gif: Path,
) -> dict[str, Any]:
    frames = []
    task = run.task
    for i, s in enumerate(shown):
        frame: dict[str, Any] = {"step": s.t, **describe_step(task, s.obs, s.action)[0]}
        frame.update({"action": s.action, "r_kin": s.r_kin, "native_return": s.native_return})
        if labels is not None:
            frame.update(vlm_answer=labels[i].answer, phi_raw=labels[i].potential)
        frames.append(frame)
    figures: dict[str, Any] = {
        "run_id": run.run_id, "run_name": run.name, "arm": run.arm.name, "run_status": run.status,
        **({"task": run.task_ref or task.name} if task.name_in_identity else {}),  # MountainCar's files predate tasks
        "vlm": run.vlm_label if run.arm.uses_vlm else "none (this arm queries no VLM)",
        "simulated": run.arm.uses_vlm and run.simulated,
    }
    if figures["simulated"]:
        figures["note"] = "The VLM labels come from the SIMULATED VLM (a pixel-reading stand-in), not a real model."
    last = steps[-1]
    figures.update({
        "episodes": cfg.episodes, "eval_seed": EVAL_SEED,
        "success_rate": result.success_rate, "mean_length": result.mean_length, "mean_return": result.mean_return,
        "returns": result.returns.tolist(), "lengths": result.lengths.tolist(),
        "successes": [bool(ok) for ok in result.successes],
        "gif": {"file": gif.name, "episode_index": cfg.episode_index, "seed": EVAL_SEED + cfg.episode_index,
                "frames": len(shown), "frame_every": cfg.frame_every, "width": cfg.width, "length": last.t,
                "native_return": last.native_return, "success": task.success(last.terminated, last.t)},
        "frames": frames,
    })
    return figures
