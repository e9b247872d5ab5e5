"""One frozen configuration object for choosing and tuning a VLM backend."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from annotated_types import Ge, Gt, Interval
from pydantic import AfterValidator

from vlmrl_cli import paper
from vlmrl_cli.core.fields import one_of

BACKENDS: tuple[str, ...] = ("sim", "hf", "openai", "replay")
PAPER_MODEL = "llava-hf/llava-1.5-7b-hf"
PAPER_TRANSCRIPT = paper.TABLE1_TRANSCRIPT
DEFAULT_CACHE = Path(".vlmrl-cache") / "responses.sqlite"


DEFAULT_SIM_PROFILE = "default"


def _known_profile(value: str) -> str:
    return one_of(lambda: SIM_PROFILES, "simulated-VLM profile")(value)


@dataclass(frozen=True)
class SimKnobs:
    """Knobs of the simulated VLM (``sim``). All randomness but ``query_flicker``'s is a pure
    function of (seed, prompt, image bytes), so the same frame always gets the same answer;
    ``query_flicker > 0`` makes the VLM stochastic (a fresh draw per query, from a stream seeded
    by (seed, the run's seed)), and its answers then bypass every cache.

    ``profile`` names the set of knob values the others were resolved from (``SIM_PROFILES``);
    build a profile's knobs with ``SimKnobs.of_profile``. The dataclass defaults are the
    ``default`` profile, today's simulated VLM, whose answers never change."""

    flicker: float = field(default=0.1, metadata={"rules": (Interval(ge=0, le=1),),
                                                  "help": "P(answer a neighbouring MCQ label)"})
    float_noise: float = field(default=0.25, metadata={"rules": (Ge(0),),
                                                       "help": "std of the float answer, in x units"})
    box_noise_px: float = field(default=20.0, metadata={"rules": (Ge(0),), "help": "std of box corner jitter, pixels"})
    box_failure: float = field(default=0.2, metadata={"rules": (Interval(ge=0, le=1),),
                                                      "help": "P(box format collapse)"})
    patch_px: int = field(default=28, metadata={"rules": (Ge(1),),
                                                "help": "spatial resolution: car seen on this pixel grid"})
    latency_s: float = field(default=0.0, metadata={"rules": (Ge(0),), "help": "fixed latency per query (benchmarks)"})
    seed: int = field(default=0, metadata={"help": "seed of the simulated answers"})
    profile: str = field(default=DEFAULT_SIM_PROFILE, metadata={"rules": (AfterValidator(_known_profile),),
                                                                "help": "named profile the knobs come from"})
    float_anchor: float | None = field(
        default=None,
        metadata={"help": "float answers are this value (+ float_noise) whatever the frame; None: read the car"},
    )
    mcq_bottom_halfwidth: float | None = field(
        default=None,
        metadata={"rules": (Ge(0),),
                  "help": "MCQ answers BOTTOM within this distance (x units) of the valley; None: true zones"},
    )
    box_anchor_x: float | None = field(
        default=None, metadata={"help": "boxes are drawn around the car at this x, not the frame's; None: read it"}
    )
    query_flicker: float = field(
        default=0.0,
        metadata={"rules": (Interval(ge=0, le=1),),
                  "help": "P(a neighbouring MCQ label) drawn afresh at every query, as a sampling VLM at "
                          "temperature > 0 gives: the same frame can get another label next time (never cached)"},
    )

    def __post_init__(self) -> None:
        if self.profile not in SIM_PROFILES:
            raise ValueError(f"unknown simulated-VLM profile '{self.profile}'; choose from {', '.join(SIM_PROFILES)}.")

    @classmethod
    def of_profile(cls, name: str, **overrides: Any) -> SimKnobs:
        """The knobs of profile ``name`` with ``overrides`` laid over them: an explicit knob beats
        the profile's value.

        Example:
            >>> k = SimKnobs.of_profile("ideal", flicker=0.3)
            >>> k.profile, k.flicker, k.float_noise
            ('ideal', 0.3, 0.0)
            >>> SimKnobs.of_profile("default") == SimKnobs()
            True
        """
        if name not in SIM_PROFILES:
            raise ValueError(f"unknown simulated-VLM profile '{name}'; choose from {', '.join(SIM_PROFILES)}.")
        return cls(**{**SIM_PROFILES[name], **overrides, "profile": name})


#: Named sets of ``SimKnobs`` values (knobs not named keep their dataclass default).
#: ``ideal``: no noise and a one-pixel grid. ``default``: today's knobs (the results so far).
#: ``llava-table1``: the failure pattern of the paper's Table 1 (LLaVA-1.5-7B): the float answer
#: is nearly constant (0.378, 0.386 for x = -0.50, -0.69), the MCQ answers BOTTOM on both frames
#: (a dead zone around the valley reaching past x = -0.69), and boxes either collapse to
#: ``Error [0, 0, 0, 0]`` or sit far from the car (columns 450-480, i.e. x ~ 0.2).
SIM_PROFILES: dict[str, Mapping[str, Any]] = {
    "ideal": {"flicker": 0.0, "float_noise": 0.0, "box_noise_px": 0.0, "box_failure": 0.0, "patch_px": 1},
    DEFAULT_SIM_PROFILE: {},
    "llava-table1": {
        "flicker": 0.0,
        "float_noise": 0.005,
        "float_anchor": 0.38,
        "mcq_bottom_halfwidth": 0.45,
        "box_failure": 0.5,
        "box_noise_px": 10.0,
        "box_anchor_x": 0.2,
        "patch_px": 56,
    },
}

#: Knobs added after results were produced with the default ones, and the values that leave the
#: answers as before: while they hold these values they stay out of every hash and cache key,
#: so existing runs and cached answers keep theirs.
NEUTRAL_SIM_KNOBS: dict[str, Any] = {
    "profile": DEFAULT_SIM_PROFILE, "float_anchor": None, "mcq_bottom_halfwidth": None, "box_anchor_x": None,
    "query_flicker": 0.0,
}


def sim_identity(knobs: SimKnobs) -> dict[str, Any]:
    """The knobs as they enter hashes: every field, minus the ``NEUTRAL_SIM_KNOBS`` at their neutral value.

    Example:
        >>> "profile" in sim_identity(SimKnobs()), sim_identity(SimKnobs.of_profile("ideal"))["profile"]
        (False, 'ideal')
    """
    values = {f.name: getattr(knobs, f.name) for f in dataclasses.fields(knobs)}
    return {k: v for k, v in values.items() if k not in NEUTRAL_SIM_KNOBS or NEUTRAL_SIM_KNOBS[k] != v}


def resolve_sim_profile(sim: Mapping[str, Any]) -> dict[str, Any]:
    """A raw ``[vlm.sim]`` table (the keys some layer set) with its profile's values beneath the
    keys set explicitly; unchanged when it names no profile or an unknown one (the schema says so).

    Example:
        >>> resolve_sim_profile({"profile": "ideal", "flicker": 0.3})["flicker"]
        0.3
        >>> resolve_sim_profile({"profile": "ideal"})["patch_px"]
        1
    """
    name = sim.get("profile")
    if not isinstance(name, str) or name not in SIM_PROFILES:
        return dict(sim)
    return {**SIM_PROFILES[name], **sim}


@dataclass(frozen=True)
class VLMConfig:
    """Which VLM answers, and how. ``api_key_env`` names an environment variable; the key
    itself is never stored, logged or hashed."""

    backend: str = field(default="sim", metadata={"rules": (AfterValidator(one_of(BACKENDS, "VLM backend")),),
                                                  "help": "sim (the SIMULATED VLM), hf, openai or replay"})
    model: str | None = field(default=None, metadata={"help": "hf: hub id or local folder; openai: served model name"})
    base_url: str | None = field(default=None, metadata={"help": "openai: server URL, e.g. http://host:8000/v1"})
    api_key_env: str = field(default="OPENAI_API_KEY", metadata={"help": "openai: variable holding the API key"})
    device: str | None = field(default=None, metadata={"help": "hf: torch device (None: cuda if present)"})
    dtype: str = field(default="auto", metadata={"help": "hf: torch dtype (auto, float32, float16, bfloat16)"})
    max_new_tokens: int = field(default=32, metadata={"rules": (Ge(1),), "help": "hf/openai: answer length cap"})
    timeout_s: float = field(default=30.0, metadata={"rules": (Gt(0),), "help": "openai: seconds per request"})
    retries: int = field(default=3, metadata={"rules": (Ge(0),), "help": "openai: retries with backoff"})
    transcript_in: Path | None = field(default=None, metadata={
        "help": "replay: JSONL transcript (None: the paper's Table 1 transcript)"})
    cache_path: Path | None = field(default=DEFAULT_CACHE, metadata={"help": "sqlite file of the response cache"})
    use_cache: bool = field(default=True, metadata={"help": "read and write the response cache"})
    sim: SimKnobs = field(default_factory=SimKnobs)
