"""One frozen configuration object for choosing and tuning a VLM backend."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from vlmrl_cli import paper

BACKENDS: tuple[str, ...] = ("sim", "hf", "openai", "replay")
PAPER_MODEL = "llava-hf/llava-1.5-7b-hf"
PAPER_TRANSCRIPT = paper.TABLE1_TRANSCRIPT
DEFAULT_CACHE = Path(".vlmrl-cache") / "responses.sqlite"


@dataclass(frozen=True)
class SimKnobs:
    """Knobs of the simulated VLM (``sim``). All randomness is a pure function of
    (seed, prompt, image bytes), so the same frame always gets the same answer."""

    flicker: float = field(default=0.1, metadata={"help": "P(answer a neighbouring MCQ label)"})
    float_noise: float = field(default=0.25, metadata={"help": "std of the float answer, in x units"})
    box_noise_px: float = field(default=20.0, metadata={"help": "std of box corner jitter, pixels"})
    box_failure: float = field(default=0.2, metadata={"help": "P(box format collapse)"})
    patch_px: int = field(default=28, metadata={"help": "spatial resolution: car seen on this pixel grid"})
    latency_s: float = field(default=0.0, metadata={"help": "fixed latency per query (benchmarks)"})
    seed: int = field(default=0, metadata={"help": "seed of the simulated answers"})


@dataclass(frozen=True)
class VLMConfig:
    """Which VLM answers, and how. ``api_key_env`` names an environment variable; the key
    itself is never stored, logged or hashed."""

    backend: str = "sim"
    model: str | None = None
    base_url: str | None = None
    api_key_env: str = "OPENAI_API_KEY"
    device: str | None = None
    dtype: str = "auto"
    max_new_tokens: int = 32
    timeout_s: float = 30.0
    retries: int = 3
    transcript_in: Path | None = None
    cache_path: Path | None = DEFAULT_CACHE
    use_cache: bool = True
    sim: SimKnobs = field(default_factory=SimKnobs)
