"""One frozen configuration object for choosing and tuning a VLM backend."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from annotated_types import Ge, Gt, Interval
from pydantic import AfterValidator

from vlmrl_cli import paper
from vlmrl_cli.core.errors import BadInput, did_you_mean
from vlmrl_cli.core.fields import one_of
from vlmrl_cli.core.provenance import to_jsonable

BACKENDS: tuple[str, ...] = ("sim", "hf", "openai", "replay")
MCQ_MODES: tuple[str, ...] = ("auto", "logprob", "generate")
PAPER_MODEL = "llava-hf/llava-1.5-7b-hf"
PAPER_TRANSCRIPT = paper.TABLE1_TRANSCRIPT
DEFAULT_CACHE = Path(".vlmrl-cache") / "responses.sqlite"
DEFAULT_SIM_PROFILE = "default"


def _profile_name(value: str) -> str:
    """A profile's name as written (which names exist is the task's: ``profile_problem``)."""
    if not value or value != value.strip():
        raise ValueError(f"a simulated-VLM profile is a name such as '{DEFAULT_SIM_PROFILE}', got {value!r}")
    return value


@dataclass(frozen=True)
class SimKnobs:
    """Knobs of the SIMULATED VLM (vlm/sim.py); the defaults are the ``default`` profile (``of_profile``)."""

    flicker: float = field(default=0.1, metadata={"rules": (Interval(ge=0, le=1),),
                                                  "help": "P(answer a neighbouring MCQ label)"})
    float_noise: float = field(default=0.25, metadata={"rules": (Ge(0),),
                                                       "help": "std of the float answer, in the task's units"})
    box_noise_px: float = field(default=20.0, metadata={"rules": (Ge(0),), "help": "std of box corner jitter, pixels"})
    box_failure: float = field(default=0.2, metadata={"rules": (Interval(ge=0, le=1),),
                                                      "help": "P(box format collapse)"})
    patch_px: int = field(default=28, metadata={"rules": (Ge(1),),
                                                "help": "spatial resolution: agent seen on this pixel grid"})
    latency_s: float = field(default=0.0, metadata={"rules": (Ge(0),), "flag": "--sim-latency",
                                                    "help": "fixed latency per query (benchmarks)"})
    seed: int = field(default=0, metadata={"help": "seed of the simulated answers"})
    profile: str = field(default=DEFAULT_SIM_PROFILE, metadata={
        "rules": (AfterValidator(_profile_name),),
        "help": "named profile the knobs come from: a generic one or one of the run's task"})
    float_anchor: float | None = field(
        default=None,
        metadata={"help": "float answers are this reading (+ float_noise) whatever the frame, in the task's "
                          "units; None: read the frame"},
    )
    mcq_bottom_halfwidth: float | None = field(
        default=None,
        metadata={"rules": (Ge(0),),
                  "help": "a reader's MCQ dead zone: readings within this distance of its resting point get its "
                          "resting label (the task's units, its reader's label_at); None: true labels"},
    )
    box_anchor_x: float | None = field(
        default=None, metadata={"help": "boxes are drawn around the agent at this reading, not the frame's (the "
                                        "task's units); None: read it"}
    )
    query_flicker: float = field(
        default=0.0,
        metadata={"rules": (Interval(ge=0, le=1),),
                  "help": "P(a neighbouring MCQ label) drawn afresh at every query, as a sampling VLM at "
                          "temperature > 0 gives: the same frame can get another label next time (never cached)"},
    )

    def __post_init__(self) -> None:
        _profile_name(self.profile)

    @classmethod
    def of_profile(cls, name: str, task: ProfileOwner | None = None, **overrides: Any) -> SimKnobs:
        """The knobs of profile ``name`` (generic or ``task``'s) with ``overrides`` laid over them."""
        problem = profile_problem(name, task)
        if problem:
            raise ValueError(problem + ".")
        return cls(**{**sim_profiles(task)[name], **overrides, "profile": name})


#: The generic profiles every task offers (a task adds its own: ``Task.sim_profiles``).
SIM_PROFILES: dict[str, Mapping[str, Any]] = {
    "ideal": {"flicker": 0.0, "float_noise": 0.0, "box_noise_px": 0.0, "box_failure": 0.0, "patch_px": 1},
    DEFAULT_SIM_PROFILE: {},
}

_PROFILE_KNOBS = tuple(f.name for f in dataclasses.fields(SimKnobs) if f.name != "profile")


@dataclass(frozen=True)
class SimProfile:
    """A task's named set of ``SimKnobs`` values (``Task.sim_profiles``); others keep their default."""

    name: str
    knobs: Mapping[str, Any]

    def __post_init__(self) -> None:
        _profile_name(self.name)
        if self.name in SIM_PROFILES:
            raise ValueError(f"simulated-VLM profile '{self.name}' is a generic one; give the task's profile "
                             "another name")
        unknown = [k for k in self.knobs if k not in _PROFILE_KNOBS]
        if unknown:
            raise ValueError(f"simulated-VLM profile '{self.name}': unknown knob '{unknown[0]}'"
                             f"{did_you_mean(unknown[0], _PROFILE_KNOBS)}; a profile sets SimKnobs fields "
                             f"({', '.join(_PROFILE_KNOBS)})")


class ProfileOwner(Protocol):
    """What the profile lookup needs of a ``tasks.base.Task`` (a layer above this one)."""

    @property
    def name(self) -> str: ...

    @property
    def sim_profiles(self) -> tuple[SimProfile, ...]: ...


def sim_profiles(task: ProfileOwner | None = None) -> dict[str, Mapping[str, Any]]:
    """The profiles a run of ``task`` may name: the generic ones, then the task's own."""
    table = dict(SIM_PROFILES)
    if task is not None:
        for profile in task.sim_profiles:
            if profile.name in table:
                raise ValueError(f"task '{task.name}' offers the simulated-VLM profile '{profile.name}' twice")
            table[profile.name] = profile.knobs
    return table


def profile_problem(name: str, task: ProfileOwner | None = None) -> str | None:
    """Why a run of ``task`` may not name profile ``name`` (None: it may)."""
    offered = sim_profiles(task)
    if name in offered:
        return None
    where = "" if task is None else f" for task {task.name}"
    return (f"unknown simulated-VLM profile '{name}'{where}{did_you_mean(name, offered)}; "
            f"choose from {', '.join(offered)}")


#: Knobs added after results were produced: at these values they stay out of every hash and cache key.
NEUTRAL_SIM_KNOBS: dict[str, Any] = {
    "profile": DEFAULT_SIM_PROFILE, "float_anchor": None, "mcq_bottom_halfwidth": None, "box_anchor_x": None,
    "query_flicker": 0.0,
}


def sim_identity(knobs: SimKnobs) -> dict[str, Any]:
    """The knobs as they enter hashes: ``NEUTRAL_SIM_KNOBS`` at their neutral value left out."""
    values = {f.name: getattr(knobs, f.name) for f in dataclasses.fields(knobs)}
    return {k: v for k, v in values.items() if k not in NEUTRAL_SIM_KNOBS or NEUTRAL_SIM_KNOBS[k] != v}


def resolve_sim_profile(sim: Mapping[str, Any], task: ProfileOwner | None = None) -> dict[str, Any]:
    """A raw ``[vlm.sim]`` table with its profile's values beneath the keys set explicitly."""
    name = sim.get("profile")
    offered = sim_profiles(task)
    if not isinstance(name, str) or (name not in offered and task is None):
        return dict(sim)
    if name not in offered:
        raise BadInput(f"vlm.sim.profile: {profile_problem(name, task)}.")
    return {**offered[name], **sim}


@dataclass(frozen=True)
class VLMConfig:
    """Which VLM answers, and how (the API key itself is never stored, logged or hashed)."""

    backend: str = field(default="sim", metadata={"rules": (AfterValidator(one_of(BACKENDS, "VLM backend")),),
                                                  "flag": "--vlm",
                                                  "help": "sim (the SIMULATED VLM), hf, openai or replay"})
    model: str | None = field(default=None, metadata={"help": "hf: hub id or local folder; openai: served model name"})
    base_url: str | None = field(default=None, metadata={"help": "openai: server URL, e.g. http://host:8000/v1"})
    api_key_env: str = field(default="OPENAI_API_KEY", metadata={"help": "openai: variable holding the API key"})
    device: str | None = field(default=None, metadata={"help": "hf: torch device (None: cuda if present)"})
    dtype: str = field(default="auto", metadata={"help": "hf: torch dtype (auto, float32, float16, bfloat16)"})
    max_new_tokens: int = field(default=32, metadata={"rules": (Ge(1),), "help": "hf/openai: answer length cap"})
    timeout_s: float = field(default=30.0, metadata={"rules": (Gt(0),), "flag": "--timeout",
                                                     "help": "openai: seconds per request"})
    retries: int = field(default=3, metadata={"rules": (Ge(0),), "help": "openai: retries with backoff"})
    transcript_in: Path | None = field(default=None, metadata={
        "flag": "--transcript", "help": "replay: JSONL transcript (None: the paper's Table 1 transcript)"})
    cache_path: Path | None = field(default=DEFAULT_CACHE, metadata={"help": "sqlite file of the response cache"})
    use_cache: bool = field(default=True, metadata={"flag": "--cache/--no-cache",
                                                    "help": "read and write the response cache"})
    max_queries: int | None = field(default=None, metadata={
        "rules": (Ge(0),), "help": "labels a run may ask of the VLM; past it the nearest prototype's (None: no cap)"})
    sim: SimKnobs = field(default_factory=SimKnobs)
    mcq_mode: str = field(default="auto", metadata={
        "rules": (AfterValidator(one_of(MCQ_MODES, "MCQ mode")),),
        "help": "auto (option log-probabilities where the backend can score, else generation), logprob or generate"})
    max_concurrency: int = field(default=8, metadata={
        "rules": (Ge(1),), "help": "openai: requests in flight at once; hf: frames per batched forward pass"})


#: VLM settings that change speed, not answers: never in a run's identity.
SPEED_ONLY_VLM: tuple[str, ...] = ("cache_path", "use_cache", "timeout_s", "retries", "api_key_env",
                                   "max_concurrency")
#: Settings added after runs were recorded: at these values they stay out of the identity.
NEUTRAL_VLM: dict[str, Any] = {"mcq_mode": "auto", "max_queries": None}


def vlm_identity(cfg: VLMConfig) -> dict[str, Any]:
    """``cfg`` as it enters a run's identity: what can change an answer (``sim`` knobs for ``sim`` only)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        if f.name in SPEED_ONLY_VLM or (f.name in NEUTRAL_VLM and NEUTRAL_VLM[f.name] == value):
            continue
        if f.name == "sim":
            if cfg.backend == "sim":
                out["sim"] = to_jsonable(sim_identity(value))
            continue
        out[f.name] = to_jsonable(value)
    return out
