"""`vlmrl evaluate`: re-evaluate a trained run from MLflow and watch one of its episodes.

The policy plays native MountainCar-v0 (no shaping, no VLM in the loop), as in the detached
evaluation of training. One episode is played again with ``render_mode="rgb_array"`` and
written as an animated GIF whose captions give, per frame, the step, x, v, the action, R_kin
of the step, the native return so far and, for arms that use a VLM, the label the run's VLM
gives the frame (as the camera of training renders it) and that label's raw potential.
"""

from __future__ import annotations

import json
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.frames.gif import captioned, write_gif
from vlmrl_cli.frames.render import FrameRenderer
from vlmrl_cli.shaping.arms import PotentialSource
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.shaping.kinematic import kinematic_reward
from vlmrl_cli.tracking import store
from vlmrl_cli.training.config import EVAL_SEED
from vlmrl_cli.training.evaluation import EvalResult, Policy, evaluate_detached
from vlmrl_cli.training.trained import TrainedRun, load_trained_run
from vlmrl_cli.vlm.config import DEFAULT_CACHE

DEFAULT_ROOT = Path("results") / "evaluate"
ARTIFACT_PATH = "evaluate"
ACTIONS = {0: "push left", 1: "no push", 2: "push right"}
SIMULATED_ALERT = "SIMULATED VLM (not a real model)"


@dataclass(frozen=True)
class EvaluateConfig:
    """Everything `vlmrl evaluate` does, as one value."""

    run_id: str
    tracking_uri: str | None = None
    out: Path | None = field(default=None, metadata={"help": "None = results/evaluate/<run_id>"})
    episodes: int = field(default=10, metadata={"help": "detached episodes; episode i resets with EVAL_SEED + i"})
    episode_index: int = field(default=0, metadata={"help": "which of them the GIF shows"})
    frame_every: int = field(default=2, metadata={"help": "keep every k-th frame in the GIF"})
    width: int = field(default=300, metadata={"help": "GIF width, pixels"})
    use_cache: bool = True
    cache_path: Path | None = DEFAULT_CACHE

    @property
    def out_dir(self) -> Path:
        return self.out if self.out is not None else DEFAULT_ROOT / self.run_id

    def validate(self) -> None:
        """Raise ``BadInput`` for anything that would fail later; nothing is read before."""
        if not self.run_id.strip():
            raise BadInput("the run id is empty; copy one from `vlmrl run`'s output or the MLflow UI.")
        if self.episodes < 1:
            raise BadInput(f"--episodes must be at least 1, got {self.episodes}.")
        if not 0 <= self.episode_index < self.episodes:
            raise BadInput(f"--episode-index must be in 0..{self.episodes - 1} (one of the evaluated episodes), "
                           f"got {self.episode_index}.")
        if self.frame_every < 1 or self.width < 16:
            raise BadInput("the GIF needs frame_every >= 1 and a width of at least 16 pixels.")
        if self.out_dir.exists() and not self.out_dir.is_dir():
            raise BadInput(f"--out {self.out_dir} is a file; pass a folder.")


@dataclass(frozen=True)
class PlayedStep:
    """The state after ``t`` steps of an episode and the step that led there.

    ``action`` and ``r_kin`` belong to step ``t`` (None and 0.0 at the reset state, t = 0);
    ``native_return`` is the sum of native rewards so far. ``pixels`` is the rendered frame,
    (400, 600, 3) uint8, kept only for the frames the GIF shows.
    """

    t: int
    x: float
    v: float
    action: int | None
    r_kin: float
    native_return: float
    terminated: bool = False
    pixels: np.ndarray | None = field(default=None, repr=False)


def play_episode(policy: Policy, seed: int, shaping: ShapingConfig, frame_every: int = 2) -> list[PlayedStep]:
    """Play one native MountainCar-v0 episode reset with ``seed``, rendering every
    ``frame_every``-th state (and the last one) with gymnasium's ``rgb_array`` renderer.

    Example:
        >>> steps = play_episode(lambda obs: 2 if obs[1] >= 0 else 0, seed=0, shaping=ShapingConfig(), frame_every=50)
        >>> steps[-1].terminated, [s.t for s in steps if s.pixels is not None][:2]
        (True, [0, 50])
    """
    import gymnasium as gym

    from vlmrl_cli.training.envs import ENV_ID

    env: Any = gym.make(ENV_ID)
    renderer = FrameRenderer()  # gymnasium's rgb_array renderer, headless

    def pixels(obs: np.ndarray) -> np.ndarray:
        return renderer.render(float(obs[0]), float(obs[1])).pixels

    try:
        obs, _ = env.reset(seed=seed)
        steps = [PlayedStep(0, float(obs[0]), float(obs[1]), None, 0.0, 0.0, pixels=pixels(obs))]
        done, total, t = False, 0.0, 0
        while not done:
            action = policy(obs)
            obs, reward, terminated, truncated, _ = env.step(action)
            t += 1
            total += float(reward)
            done = bool(terminated or truncated)
            x = float(obs[0])
            keep = done or t % frame_every == 0
            steps.append(PlayedStep(t, x, float(obs[1]), int(action),
                                    kinematic_reward(x, shaping.kin_scale, shaping.kin_offset), total,
                                    bool(terminated), pixels(obs) if keep else None))
    finally:
        renderer.close()
        env.close()
    return steps


@dataclass(frozen=True)
class FrameLabel:
    """What the run's VLM says about one frame: its parsed answer (or why none) and the raw
    potential that answer maps to (None when unparsed)."""

    answer: str
    potential: float | None

    @property
    def caption(self) -> str:
        phi = f"{self.potential:.2f}" if self.potential is not None else "-"
        return f"VLM {self.answer}  Phi_raw {phi}"


def label_frames(run: TrainedRun, positions: list[float], cfg: EvaluateConfig) -> list[FrameLabel]:
    """Ask the run's VLM (its own config; cache as ``cfg`` says) about the frame of each
    position, rendered by the training camera (snapped to ``render_quantum``)."""
    from vlmrl_cli.shaping.camera import Camera
    from vlmrl_cli.shaping.placebo import oracle_shaping
    from vlmrl_cli.shaping.semantic import float_potential
    from vlmrl_cli.vlm.parsers import parse_float, parse_mcq
    from vlmrl_cli.vlm.prompts import PROMPTS, PromptKind
    from vlmrl_cli.vlm.registry import build_client

    mcq = run.arm.potential is PotentialSource.MCQ
    label_map = oracle_shaping(run.arm, run.shaping, run.seed)  # a placebo's shuffled map
    prompt = PROMPTS[PromptKind.MCQ if mcq else PromptKind.FLOAT]
    client = build_client(replace(run.vlm, use_cache=cfg.use_cache, cache_path=cfg.cache_path))
    camera = Camera(run.shaping.render_quantum)
    labels = []
    try:
        for x in positions:
            text = client.ask(prompt, camera.view(x).frame()).text
            if mcq:
                label = parse_mcq(text)
                labels.append(FrameLabel(label.label.value, label_map.potential_of(label.label))
                              if label.ok and label.label is not None else FrameLabel(f"({label.status})", None))
            else:
                number = parse_float(text)
                labels.append(FrameLabel(f"x={number.value:+.3f}", float_potential(number.value))
                              if number.ok and number.value is not None else FrameLabel(f"({number.status})", None))
    finally:
        camera.close()
        client.close()
    return labels


def _captions(run: TrainedRun, step: PlayedStep, last: int, index: int) -> list[str]:
    action = ACTIONS.get(step.action, str(step.action)) if step.action is not None else "-"
    return [
        f"{run.name}  episode {index}  step {step.t}/{last}",
        f"x {step.x:+.3f}  v {step.v:+.4f}  action {action}",
        f"R_kin {step.r_kin:.2f}  native return {step.native_return:.0f}",
    ]


@dataclass(frozen=True)
class EvaluateResult:
    run: TrainedRun
    result: EvalResult
    out: Path
    gif: Path
    summary: Path
    frames: int
    gif_bytes: int
    episode: list[PlayedStep] = field(repr=False)


def evaluate_run(cfg: EvaluateConfig) -> EvaluateResult:
    """Evaluate run ``cfg.run_id`` and write ``episode-<i>.gif`` and ``evaluation.json`` to
    ``cfg.out_dir``, logged as artifacts of that run under ``evaluate/``.

    Raises ``BadInput`` (before any folder is made) for a missing tracking database, an
    unknown run, a run without a model, or an unavailable VLM backend.
    """
    cfg.validate()
    client = store.connect_existing(cfg.tracking_uri)
    with tempfile.TemporaryDirectory(prefix="vlmrl-evaluate-") as tmp:
        run = load_trained_run(client, cfg.run_id, Path(tmp))
    result = evaluate_detached(run.policy, cfg.episodes, EVAL_SEED)
    seed = EVAL_SEED + cfg.episode_index
    steps = play_episode(run.policy, seed, run.shaping, cfg.frame_every)
    shown = [s for s in steps if s.pixels is not None]
    labels = label_frames(run, [s.x for s in shown], cfg) if run.arm.uses_vlm else None
    alert = SIMULATED_ALERT if run.arm.uses_vlm and run.simulated else None
    images = []
    for i, (step, pixels) in enumerate((s, s.pixels) for s in shown if s.pixels is not None):
        lines = _captions(run, step, steps[-1].t, cfg.episode_index)
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
    return EvaluateResult(run, result, out, gif, summary, len(images), gif.stat().st_size, steps)


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
    for i, s in enumerate(shown):
        frame: dict[str, Any] = {"step": s.t, "x": s.x, "v": s.v, "action": s.action, "r_kin": s.r_kin,
                                 "native_return": s.native_return}
        if labels is not None:
            frame.update(vlm_answer=labels[i].answer, phi_raw=labels[i].potential)
        frames.append(frame)
    figures: dict[str, Any] = {
        "run_id": run.run_id, "run_name": run.name, "arm": run.arm.name, "run_status": run.status,
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
                "native_return": last.native_return, "success": last.terminated},
        "frames": frames,
    })
    return figures
