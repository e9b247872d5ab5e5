"""The configuration of `vlmrl run`: one frozen object, loadable from one TOML file.

A TOML file may set every knob; a flag given on the command line overrides the file.
Example file (every key optional)::

    arms = ["baseline", "hybrid"]
    seeds = [0, 1, 2]
    preset = "paper"
    timesteps = 300000
    workers = 2
    experiment = "vlmrl"

    [vlm]
    backend = "sim"

    [vlm.sim]
    flicker = 0.1

    [shaping]
    alpha = 5.0
    query_every = 10

    [shaping.label_potentials]
    LEFT_PEAK = 0.3
"""

from __future__ import annotations

import dataclasses
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.core.provenance import config_hash, to_jsonable
from vlmrl_cli.frames.geometry import Zone
from vlmrl_cli.shaping.arms import ARMS, ArmSpec, parse_arms
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.training.presets import PPOPreset, get_preset
from vlmrl_cli.vlm.config import BACKENDS, SimKnobs, VLMConfig

DEFAULT_EXPERIMENT = "vlmrl"
EVAL_SEED = 1_000_000  # detached evaluation episode i resets with seed EVAL_SEED + i


@dataclass(frozen=True)
class RunConfig:
    """Everything `vlmrl run` does, as one value: logged whole, hashed per job for resume."""

    arms: tuple[str, ...] = ("baseline", "hybrid")
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    preset: str = "paper"
    timesteps: int | None = field(default=None, metadata={"help": "None = the preset's budget"})
    eval_episodes: int | None = field(default=None, metadata={"help": "None = the preset's (100)"})
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    experiment: str = DEFAULT_EXPERIMENT
    tracking_uri: str | None = None
    vlm: VLMConfig = field(default_factory=VLMConfig)
    shaping: ShapingConfig = field(default_factory=ShapingConfig)

    def validate(self) -> None:
        """Raise ``BadInput`` for anything that would fail later; nothing is trained before."""
        parse_arms(",".join(self.arms))
        get_preset(self.preset)
        if not self.seeds:
            raise BadInput("no seed given; pass --seeds N (N >= 1) or --seed-list 0,1,2.")
        if len(set(self.seeds)) != len(self.seeds):
            raise BadInput("a seed is listed twice; list each seed once.")
        if any(s < 0 for s in self.seeds):
            raise BadInput("seeds must be non-negative integers.")
        if self.timesteps is not None and self.timesteps < 1:
            raise BadInput(f"--timesteps must be at least 1, got {self.timesteps}.")
        if self.eval_episodes is not None and self.eval_episodes < 1:
            raise BadInput(f"eval_episodes must be at least 1, got {self.eval_episodes}.")
        if self.workers < 1:
            raise BadInput(f"--workers must be at least 1, got {self.workers}.")
        if self.vlm.backend not in BACKENDS:
            raise BadInput(f"unknown VLM backend '{self.vlm.backend}'; choose one of {', '.join(BACKENDS)}.")
        s = self.shaping
        if s.query_every < 1 or s.confirm < 1:
            raise BadInput("shaping.query_every and shaping.confirm must be at least 1.")
        if s.bandwidth <= 0 or s.reuse_radius < 0 or s.render_quantum <= 0:
            raise BadInput("shaping.bandwidth and render_quantum must be > 0 and reuse_radius >= 0.")
        if s.gamma is not None and not 0 < s.gamma <= 1:
            raise BadInput(f"shaping.gamma must be in (0, 1], got {s.gamma}.")
        missing = set(Zone) - {z for z, _ in s.label_potentials}
        if missing:
            raise BadInput(f"shaping.label_potentials lacks {sorted(missing)[0]}; give a potential for every label.")

    @property
    def preset_spec(self) -> PPOPreset:
        return get_preset(self.preset)

    @property
    def budget(self) -> int:
        return self.timesteps if self.timesteps is not None else self.preset_spec.timesteps

    def jobs(self) -> list[TrainJob]:
        """One job per (arm, seed), arms in the given order, seeds inner."""
        preset = self.preset_spec
        return [
            TrainJob(
                arm=ARMS[arm], seed=seed, preset=preset, timesteps=self.budget,
                eval_episodes=self.eval_episodes or preset.eval_episodes,
                vlm=self.vlm, shaping=self.shaping,
            )
            for arm in self.arms
            for seed in self.seeds
        ]


@dataclass(frozen=True)
class TrainJob:
    """One (arm, seed) training run and its detached evaluation."""

    arm: ArmSpec
    seed: int
    preset: PPOPreset
    timesteps: int
    eval_episodes: int
    vlm: VLMConfig
    shaping: ShapingConfig

    @property
    def name(self) -> str:
        return f"{self.arm.name}-s{self.seed}"

    def identity(self) -> dict[str, Any]:
        """What makes two runs the same experiment cell, seed excluded. The VLM and the shaping
        knobs count only for arms that use them, so tuning the VLM does not redo the baseline.
        Cache settings never count: they change speed, not answers."""
        ident: dict[str, Any] = {
            "arm": to_jsonable(self.arm),
            "preset": to_jsonable(self.preset),
            "timesteps": self.timesteps,
            "eval_episodes": self.eval_episodes,
            "eval_seed": EVAL_SEED,
        }
        if self.arm.kinematic or self.arm.uses_vlm:
            ident["shaping"] = to_jsonable(self.shaping)
        if self.arm.uses_vlm:
            vlm = to_jsonable(self.vlm)
            for key in ("cache_path", "use_cache", "timeout_s", "retries", "api_key_env"):
                vlm.pop(key, None)
            if self.vlm.backend != "sim":
                vlm.pop("sim", None)
            ident["vlm"] = vlm
        return ident

    @property
    def config_hash(self) -> str:
        return config_hash(self.identity())

    def params(self) -> dict[str, Any]:
        """The whole job config, for MLflow params."""
        return {"seed": self.seed, **self.identity()}


# --- loading from TOML -----------------------------------------------------------------

def _build(cls: type[Any], data: dict[str, Any], where: str) -> Any:
    known = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(known))
    if unknown:
        raise BadInput(f"unknown key '{unknown[0]}' in [{where}] of the config file; known: {', '.join(known)}.")
    return data


def _shaping_from(data: dict[str, Any]) -> ShapingConfig:
    data = dict(_build(ShapingConfig, data, "shaping"))
    if "label_potentials" in data:
        raw = data["label_potentials"]
        if not isinstance(raw, dict):
            raise BadInput("[shaping.label_potentials] must map labels to numbers.")
        base = dict(ShapingConfig().label_potentials)
        for label, value in raw.items():
            if label not in Zone.__members__:
                raise BadInput(f"unknown label '{label}' in [shaping.label_potentials]; known: {', '.join(Zone)}.")
            base[Zone(label)] = float(value)
        data["label_potentials"] = tuple(base.items())
    try:
        return ShapingConfig(**data)
    except TypeError as exc:
        raise BadInput(f"bad [shaping] section in the config file: {exc}.") from exc


def _vlm_from(data: dict[str, Any]) -> VLMConfig:
    data = dict(_build(VLMConfig, data, "vlm"))
    if "sim" in data:
        data["sim"] = SimKnobs(**_build(SimKnobs, dict(data["sim"]), "vlm.sim"))
    for key in ("transcript_in", "cache_path"):
        if data.get(key) is not None:
            data[key] = Path(data[key])
    return VLMConfig(**data)


def load_config_file(path: Path) -> dict[str, Any]:
    """Parse a TOML config file into ``RunConfig`` keyword arguments (validated later)."""
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise BadInput(f"cannot read the config file {path}: {exc.strerror}.") from exc
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise BadInput(f"the config file {path} is not valid TOML ({exc}).") from exc
    kwargs = dict(_build(RunConfig, raw, "top level"))
    try:
        for key in ("arms", "seeds"):
            if key in kwargs:
                kwargs[key] = tuple(kwargs[key])
        if "vlm" in kwargs:
            kwargs["vlm"] = _vlm_from(dict(kwargs["vlm"]))
        if "shaping" in kwargs:
            kwargs["shaping"] = _shaping_from(dict(kwargs["shaping"]))
    except (TypeError, ValueError) as exc:
        raise BadInput(f"the config file {path} has a value of the wrong type ({exc}).") from exc
    return kwargs
