"""MiniGrid DoorKey-5x5 as a task: pick up the key, open the locked door, reach the green goal.
The policy sees the egocentric view as 147 float32 numbers; the camera draws the whole grid from
above, and the reader finds the milestones in those pixels only. See docs/tasks.md."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import minigrid  # noqa: F401  (registers the MiniGrid envs with gymnasium)
import numpy as np
from minigrid.envs import DoorKeyEnv

from vlmrl_cli.frames.render import Frame
from vlmrl_cli.shaping.camera import CellCamera, FrameView
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.shaping.features import feature_dim
from vlmrl_cli.shaping.scales import task_scales
from vlmrl_cli.shaping.scene import Scene
from vlmrl_cli.tasks.base import SB3_DEFAULT_100K, SMOKE, RandomScore, Task
from vlmrl_cli.tasks.capabilities import TaskCamera
from vlmrl_cli.vlm.prompts import Milestones, mcq_prompt

ENV_ID = "MiniGrid-DoorKey-5x5-v0"
TILE = 32  # px per grid cell: 5 cells give 160 px, a multiple of the features' 20 px blocks
MAX_STEPS = 250
LABELS = ("NO_KEY", "HAS_KEY", "DOOR_OPEN", "AT_GOAL")
MILESTONES = Milestones(LABELS, mcq_prompt(
    "This image shows a small grid world from above: a red triangle (the agent), a yellow key, a "
    "yellow door in a grey wall and a green goal square. Which stage has the agent reached? NO_KEY: "
    "the key still lies on the floor; HAS_KEY: the key is gone from the floor and the door is still "
    "shut; DOOR_OPEN: the door is open; AT_GOAL: the agent stands on the green square.", LABELS))
POTENTIALS: tuple[tuple[str, float], ...] = (("NO_KEY", 0.0), ("HAS_KEY", 0.3), ("DOOR_OPEN", 0.6),
                                             ("AT_GOAL", 1.0))

YELLOW = (255, 255, 0)
LOCKED_FILL = (114, 114, 0)  # MiniGrid fills a locked door with 0.45 x its colour
RED = (255, 0, 0)
GREEN = (0, 255, 0)
OPEN_STRIP_FROM = 28  # an open door is drawn as its tile's columns 0.88..1.0 (28..31 px)


def _count(tile: np.ndarray, colour: tuple[int, int, int]) -> np.ndarray:
    return np.all(tile == np.asarray(colour, dtype=np.uint8), axis=-1)


def read_stage(pixels: np.ndarray, tile: int = TILE) -> str | None:
    """The stage a top-down DoorKey frame shows, from its pixels only (None: no agent drawn); the
    picture never shows what the agent carries, so HAS_KEY is "no key on the floor, the door shut".
    """
    rows, cols = pixels.shape[0] // tile, pixels.shape[1] // tile
    agent_on_goal = agent_seen = key_seen = door_open = False
    for j in range(rows):
        for i in range(cols):
            t = pixels[j * tile:(j + 1) * tile, i * tile:(i + 1) * tile]
            red, green = int(_count(t, RED).sum()), int(_count(t, GREEN).sum())
            if red > tile:
                agent_seen = True
                agent_on_goal = agent_on_goal or green > 0
            yellow = _count(t, YELLOW)
            if not yellow.any():
                continue
            used = np.nonzero(yellow.any(axis=0))[0]
            if _count(t, LOCKED_FILL).any():
                continue  # the locked door
            if used.min() >= OPEN_STRIP_FROM * tile // TILE:
                door_open = True
            elif used.min() > 2 and used.max() < OPEN_STRIP_FROM * tile // TILE:
                key_seen = True  # a glyph inside its tile, off the edges: the key on the floor
            # else: a closed, unlocked door (its outline touches both edges)
    if not agent_seen:
        return None
    if agent_on_goal:
        return "AT_GOAL"
    if door_open:
        return "DOOR_OPEN"
    return "NO_KEY" if key_seen else "HAS_KEY"


def label_of_sim(sim: Any) -> str:
    """The true stage of a DoorKey simulator (probes and diagnostics only, never the VLM)."""
    here = sim.grid.get(*sim.agent_pos)
    if here is not None and here.type == "goal":
        return "AT_GOAL"
    doors = [c for c in sim.grid.grid if c is not None and c.type == "door"]
    if doors and doors[0].is_open:
        return "DOOR_OPEN"
    carrying = getattr(sim, "carrying", None)
    return "HAS_KEY" if carrying is not None and carrying.type == "key" else "NO_KEY"


class StageReader:
    """The simulated VLM's reader (a ``MilestoneReader``): ``read_stage`` on the frame's pixels."""

    name = "minigrid-doorkey"
    milestones = MILESTONES

    def read(self, pixels: np.ndarray) -> str | None:
        return read_stage(pixels)


Cell = tuple[bytes, tuple[int, int, int], int, int]  # grid encoding, its shape, agent x, agent y * 4 + direction


def cell_of(sim: Any) -> Cell:
    """What the top-down picture depends on: the grid's encoding and the agent's pose."""
    encoded = sim.grid.encode()
    x, y = (int(v) for v in sim.agent_pos)
    return encoded.tobytes(), tuple(int(s) for s in encoded.shape), x, y * 4 + int(sim.agent_dir)  # type: ignore[return-value]


def render_cell(cell: Cell, sha256: str | None = None) -> Frame:
    """Draw a cell again from its encoding (no simulator needed)."""
    from minigrid.core.grid import Grid

    raw, shape, x, pose = cell
    grid, _ = Grid.decode(np.frombuffer(raw, dtype=np.uint8).reshape(shape))
    pixels = grid.render(TILE, (x, pose // 4), pose % 4, highlight_mask=None)
    return Frame.drawn(pixels, sha256=sha256)


class DoorKeyCamera(CellCamera[Cell]):
    """The top-down camera: one frame per (grid, agent pose)."""

    def _draw(self, cell: Cell, sha256: str | None) -> Frame:
        return render_cell(cell, sha256)

    def look(self, sim: Any) -> FrameView:
        return self._view_of(cell_of(sim))


def stage_of_obs(obs: np.ndarray) -> float:
    """``p`` in [0, 1] from the flattened egocentric view: half for carrying the key, half for an open
    door in view.

    Example:
        >>> view = np.zeros((7, 7, 3)); view[3, 6] = (5, 4, 0)
        >>> stage_of_obs(view.reshape(-1))
        0.5
    """
    carries, door_open = key_and_door(obs)
    return (float(carries) + float(door_open)) / 2.0


def key_and_door(obs: Any) -> tuple[bool, bool]:
    """Whether the agent carries the key (MiniGrid draws a carried object in the agent's own cell,
    (3, 6), object 5) and whether an open door (object 4, state 0) is in the flattened egocentric
    view."""
    view = np.asarray(obs).reshape(7, 7, 3)
    return bool(view[3, 6, 0] == 5), bool(np.any((view[..., 0] == 4) & (view[..., 2] == 0)))


def doorkey_dense(obs: np.ndarray, scale: float, offset: float) -> float:
    """Eq. 1 on the stage coordinate ``u = 2 p - 1``, per step of the 250-step limit."""
    return max(0.0, scale * (2.0 * stage_of_obs(obs) - 1.0 + offset)) / MAX_STEPS


#: MiniGrid's seven actions (``minigrid.core.actions.Actions``), by index.
ACTIONS = ("turn left", "turn right", "forward", "pick up", "drop", "toggle", "done")


def describe_step(obs: tuple[float, ...], action: Any) -> tuple[dict[str, Any], str]:
    """A played step of DoorKey as named fields (key carried, open door in view) and a caption.

    Example:
        >>> view = np.zeros((7, 7, 3)); view[3, 6] = (5, 4, 0)
        >>> describe_step(tuple(view.reshape(-1)), 5)
        ({'has_key': True, 'door_open_in_view': False}, 'key carried  door not open in view  action toggle')
    """
    has_key, door_open = key_and_door(obs)
    shown = "-" if action is None else (ACTIONS[int(action)] if 0 <= int(action) < len(ACTIONS) else str(action))
    caption = (f"key {'carried' if has_key else 'not carried'}  door {'open' if door_open else 'not open'} "
               f"in view  action {shown}")
    return {"has_key": has_key, "door_open_in_view": door_open}, caption


class FlatImage(gym.ObservationWrapper[np.ndarray, Any, Any], gym.utils.RecordConstructorArgs):
    """``Task.wrap``: MiniGrid's Dict observation as its egocentric image, 147 float32 numbers (a
    ``uint8`` one would be truncated under ``VecNormalize``); recorded, so ``env.spec.make()`` works.

    Example:
        >>> env = FlatImage(gym.make(ENV_ID))
        >>> space = env.observation_space
        >>> space.shape, space.dtype, env.spec.make().observation_space == space
        ((147,), dtype('float32'), True)
    """

    def __init__(self, env: gym.Env[Any, Any]) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ObservationWrapper.__init__(self, env)
        image = env.observation_space["image"]  # type: ignore[index]
        self.observation_space = gym.spaces.Box(
            np.asarray(image.low, dtype=np.float32).reshape(-1), np.asarray(image.high, dtype=np.float32).reshape(-1),
            dtype=np.float32)

    def observation(self, observation: Any) -> np.ndarray:
        return np.asarray(observation["image"], dtype=np.float32).reshape(-1)


def make_doorkey_env(render_mode: str | None = None) -> gym.Env[Any, Any]:
    """DoorKey-5x5 with the flattened egocentric image as its observation."""
    return FlatImage(gym.make(ENV_ID, render_mode=render_mode))


def reset_state(seed: int) -> Any:
    """A freshly reset DoorKey simulator (the unwrapped env) for ``seed``."""
    env = make_doorkey_env()
    env.reset(seed=seed)
    return env.unwrapped


def render_state(sim: Any) -> Frame:
    """The camera's frame of a simulator."""
    return render_cell(cell_of(sim))


def probe_states(n: int) -> list[Any]:
    """About ``n`` DoorKey simulators, a quarter at each stage: seeds 0, 1, ...'s layouts staged, the
    agent on each free cell it could reach there, facing each way in turn.
    """
    import copy

    from minigrid.core.world_object import Key

    want = -(-n // len(LABELS))
    staged: dict[str, list[Any]] = {label: [] for label in LABELS}
    for seed in range(1_000):
        if min(len(v) for v in staged.values()) >= want:
            break
        base = reset_state(seed)
        cells = [(i % base.width, i // base.width, c) for i, c in enumerate(base.grid.grid)]
        key, door, goal = (next((x, y) for x, y, c in cells if c is not None and c.type == kind)
                           for kind in ("key", "door", "goal"))
        for label in LABELS:
            sim = copy.deepcopy(base)
            if label != "NO_KEY":
                sim.grid.set(*key, None)
                sim.carrying = Key("yellow")
            if label in ("DOOR_OPEN", "AT_GOAL"):
                shut = sim.grid.get(*door)
                shut.is_locked, shut.is_open = False, True
            if label == "AT_GOAL":
                spots = [goal] * 4
            else:
                spots = [(x, y) for x, y, _ in cells
                         if sim.grid.get(x, y) is None and (label == "DOOR_OPEN" or x < door[0])]
            for k, (x, y) in enumerate(spots):
                posed = copy.deepcopy(sim)
                posed.agent_pos, posed.agent_dir = (x, y), (k + seed) % 4
                staged[label].append(posed)
    picks = [staged[label][i] for i in range(want) for label in LABELS]
    return picks[:n]


def _camera(shaping: ShapingConfig) -> DoorKeyCamera:
    return DoorKeyCamera()


# rl-baselines3-zoo, hyperparams/ppo.yml, the MiniGrid defaults (with FlatObsWrapper; here the image only)
_ZOO: dict[str, Any] = {
    "n_envs": 8, "n_steps": 128, "batch_size": 64, "gae_lambda": 0.95, "gamma": 0.99, "n_epochs": 10,
    "ent_coef": 0.0, "learning_rate": 2.5e-4, "clip_range": 0.2, "normalize_obs": True, "normalize_reward": True,
    "timesteps": 100_000,
}


DOORKEY = Task(
    name="minigrid-doorkey",
    env_id=ENV_ID,
    summary="MiniGrid-DoorKey-5x5-v0: key, locked door, goal (7 actions, 1 - 0.9 t/250 at the goal, 250 steps)",
    scene=Scene("minigrid-doorkey", (147,), doorkey_dense, DoorKeyEnv),
    milestones=MILESTONES,
    label_potentials=POTENTIALS,
    truth=label_of_sim,
    camera=TaskCamera(_camera, feature_dim((5 * TILE, 5 * TILE, 3))),
    reader=StageReader(),
    thresholds=(0.5, 0.8, 0.9),
    max_steps=MAX_STEPS,
    presets={
        "zoo": _ZOO,
        # the candidates of `vlmrl calibrate --task minigrid-doorkey`, 100,000 steps each
        "zoo-100k-raw": {**_ZOO, "normalize_obs": False, "normalize_reward": False},
        "sb3-default-100k": SB3_DEFAULT_100K,
        "sb3-default-100k-norm": {**SB3_DEFAULT_100K, "normalize_obs": True, "normalize_reward": True},
        "smoke": SMOKE,
    },
    calibration=tuple({"preset": p} for p in ("zoo", "zoo-100k-raw", "sb3-default-100k", "sb3-default-100k-norm")),
    # the median of its 120 committed runs (calibration and study exports; quartiles 0.83-1.29 ms),
    # five times MountainCar-v0's repro figure
    step_seconds=1.1e-3,
    zoo_reference="rl-baselines3-zoo benchmark.md (at 22e3ff2), PPO MiniGrid-DoorKey-5x5-v0: "
                  "0.964 +/- 0.006 (100k steps); hyperparams/ppo.yml's MiniGrid defaults",
    random_score=RandomScore(0.029474),  # measured by RANDOM_SCORE_COMMAND on 2026-12-07
    study_preset="zoo",
    window=50,
    wrap=FlatImage,
    # goal: zoo's 0.964 over a failure's 0; Eq. 1 pays at most 1.4 / 250 per step at scale 1
    scales=task_scales(goal_return=0.964, potential_span=1.0, dense_peak=1.4 / MAX_STEPS, horizon=MAX_STEPS),
    probe_states=probe_states,
    caption=describe_step,
)
