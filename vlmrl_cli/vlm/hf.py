"""A local image-text-to-text model (LLaVA, Qwen-VL, ...) run in-process through transformers.

Any model that ``AutoProcessor`` and ``AutoModelForImageTextToText`` can load works: a hub id
(``llava-hf/llava-1.5-7b-hf``, the paper's model) or a local folder written by
``save_pretrained``. transformers is imported only when a model is loaded, so the CLI starts
fast for the other backends.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vlmrl_cli.core.errors import BackendUnavailable, BadInput
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.vlm.config import PAPER_MODEL, VLMConfig
from vlmrl_cli.vlm.prompts import Prompt

logger = logging.getLogger(__name__)

DTYPES: tuple[str, ...] = ("auto", "float32", "float16", "bfloat16")


def resolve_device(requested: str | None) -> str:
    """The torch device to run on: ``requested`` if given, else ``cuda`` when present, else ``cpu``."""
    if requested:
        return requested
    import torch

    return "cuda" if torch.cuda.is_available() else "cpu"


def resolve_dtype(name: str, device: str) -> Any:
    """The ``torch.dtype`` named ``name``; ``auto`` is float16 on CUDA and float32 elsewhere.

    Example:
        >>> resolve_dtype("auto", "cpu")
        torch.float32
        >>> resolve_dtype("bfloat16", "cuda")
        torch.bfloat16
    """
    import torch

    if name not in DTYPES:
        raise BadInput(f"unknown --dtype '{name}'; choose one of {', '.join(DTYPES)}.")
    if name == "auto":
        return torch.float16 if device.startswith("cuda") else torch.float32
    return getattr(torch, name)


def _dtype_kwarg() -> str:
    """``from_pretrained``'s dtype keyword: ``dtype`` since transformers 4.56, ``torch_dtype`` before."""
    import transformers

    major, minor = (int(p) for p in transformers.__version__.split(".")[:2])
    return "dtype" if (major, minor) >= (4, 56) else "torch_dtype"


def _looks_like_path(model: str) -> bool:
    """True when ``model`` is meant as a filesystem path rather than an ``org/name`` hub id."""
    return (
        model.startswith(("/", ".", "~", "\\"))
        or model.count("/") > 1
        or "\\" in model
        or (len(model) > 1 and model[1] == ":")  # a Windows drive letter
    )


def _chain(exc: BaseException) -> list[BaseException]:
    """``exc`` and every exception it was raised from (``__cause__`` / ``__context__``)."""
    seen: list[BaseException] = []
    cur: BaseException | None = exc
    while cur is not None and cur not in seen:
        seen.append(cur)
        cur = cur.__cause__ or cur.__context__
    return seen


def _load_error(model: str, exc: BaseException) -> BackendUnavailable:
    """One sentence saying why ``model`` did not load and what to do about it."""
    names = {type(e).__name__ for e in _chain(exc)}
    head = f"cannot load the model '{model}' with transformers"
    if names & {"LocalEntryNotFoundError", "OfflineModeIsEnabled", "ConnectError", "ConnectionError"}:
        why = ("no such local folder and the Hugging Face hub is unreachable (or offline mode is on); "
               "pass --model PATH to a downloaded model folder")
    elif "GatedRepoError" in names:
        why = "the hub repository is gated; accept its licence on huggingface.co and log in with `hf auth login`"
    elif names & {"RepositoryNotFoundError", "RevisionNotFoundError"}:
        why = ("no such model on the Hugging Face hub (or it is private); check the id, "
               f"e.g. {PAPER_MODEL}, or pass --model PATH to a local folder")
    elif "EntryNotFoundError" in names:
        why = "the model has no processor or config files; it may not be a transformers image-text-to-text model"
    elif isinstance(exc, ImportError):
        why = f"a package it needs is missing ({_one_line(exc)}); install it and retry"
    elif isinstance(exc, ValueError) and "Unrecognized" in str(exc):
        why = "it is not an image-text-to-text model that AutoModelForImageTextToText knows; pick a VLM"
    else:
        why = f"{type(exc).__name__}: {_one_line(exc)}"
    return BackendUnavailable(f"{head}: {why}.")


def _one_line(exc: BaseException, limit: int = 200) -> str:
    """The first line of ``exc``'s message, trimmed, without a final full stop."""
    lines = str(exc).strip().splitlines()
    text = lines[0] if lines else type(exc).__name__
    return text[:limit].rstrip(". ")


def locate_model(cfg: VLMConfig) -> tuple[Path, bool]:
    """``(path, local)`` of ``cfg.model`` without loading it: a local folder with a config.json
    (``local``) or a hub id; ``BackendUnavailable`` for a missing model, a path that is no model
    folder. (A hub id is only checked when loading, or by ``hub_problem``.)"""
    if not cfg.model:
        raise BackendUnavailable(
            f"the hf backend needs --model: a Hugging Face hub id such as {PAPER_MODEL} "
            "or the path of a downloaded model folder."
        )
    model_id = cfg.model
    path = Path(model_id).expanduser()
    local = path.is_dir()
    if not local and (path.exists() or _looks_like_path(model_id)):
        raise BackendUnavailable(
            f"cannot load the model '{model_id}' with transformers: no such local folder; "
            "pass --model PATH to a downloaded model folder or a Hugging Face hub id."
        )
    if local and not (path / "config.json").is_file():
        raise BackendUnavailable(
            f"cannot load the model '{model_id}' with transformers: the folder has no config.json; "
            "pass --model the folder that save_pretrained (or `hf download`) wrote."
        )
    return path, local


def hub_problem(model_id: str, timeout_s: float = 10.0) -> str | None:
    """Why the hub id ``model_id`` cannot be loaded here, or None: it is in the local Hugging
    Face cache, or the hub answers for it (offline mode, ``HF_HUB_OFFLINE``, asks no server)."""
    import os

    from huggingface_hub import try_to_load_from_cache

    if isinstance(try_to_load_from_cache(model_id, "config.json"), str):
        return None
    if os.environ.get("HF_HUB_OFFLINE", "").strip().lower() in ("1", "true", "yes", "on"):
        return f"the model '{model_id}' is not in the local Hugging Face cache and HF_HUB_OFFLINE is set"
    try:
        from huggingface_hub import model_info

        model_info(model_id, timeout=timeout_s)
    except Exception as exc:  # no network, no such repository, gated: all say the same to a user
        why = _one_line(exc, 120)
        return f"the model '{model_id}' is neither in the local Hugging Face cache nor on the hub ({why})"
    return None


@dataclass
class _Loaded:
    processor: Any
    model: Any
    device: str
    dtype: Any


class HFBackend:
    """A transformers image-text-to-text model, greedy-decoded, answering one (prompt, frame).

    The prompt goes through the processor's chat template as one user turn holding the image
    and the text; only the newly generated tokens are decoded. A failure while generating (an
    odd tokenizer, a model that chokes on the image) is logged and answered with ``""`` so a
    probe over many frames carries on; the parsers count it as a failed answer.
    """

    name = "hf"
    simulated = False

    def __init__(self, model_id: str, loaded: _Loaded, max_new_tokens: int = 32) -> None:
        self.model = model_id
        self.max_new_tokens = max_new_tokens
        self._loaded: _Loaded | None = loaded

    def __repr__(self) -> str:
        device = self._loaded.device if self._loaded is not None else "closed"
        return f"HFBackend(model={self.model!r}, device={device!r})"

    @classmethod
    def from_config(cls, cfg: VLMConfig) -> HFBackend:
        """Load ``cfg.model`` (hub id or local folder) on ``cfg.device`` in ``cfg.dtype``.

        Raises ``BackendUnavailable`` with one sentence when the model cannot be loaded, and
        ``BadInput`` for an unknown dtype.
        """
        model_id = cfg.model or ""
        path, local = locate_model(cfg)
        device = resolve_device(cfg.device)
        dtype = resolve_dtype(cfg.dtype, device)
        source = str(path) if local else model_id
        try:
            from transformers import AutoModelForImageTextToText, AutoProcessor

            processor = AutoProcessor.from_pretrained(source, local_files_only=local)
            model: Any = AutoModelForImageTextToText.from_pretrained(
                source, local_files_only=local, **{_dtype_kwarg(): dtype}
            )
            model = model.to(device).eval()
        except Exception as exc:  # any load failure becomes one actionable sentence
            raise _load_error(model_id, exc) from exc
        return cls(model_id, _Loaded(processor, model, device, dtype), max_new_tokens=cfg.max_new_tokens)

    def _inputs(self, loaded: _Loaded, text: str, image: Any) -> Any:
        """Processor inputs for one user turn of (image, text), via the chat template if any."""
        processor = loaded.processor
        if getattr(processor, "chat_template", None):
            messages = [{"role": "user", "content": [{"type": "image"}, {"type": "text", "text": text}]}]
            text = processor.apply_chat_template(messages, add_generation_prompt=True, tokenize=False)
        # processors without a template (e.g. PaliGemma) insert their image tokens themselves
        inputs = processor(images=[image], text=[text], return_tensors="pt")
        return inputs.to(loaded.device, dtype=loaded.dtype)

    def answer(self, prompt: Prompt, frame: Frame) -> str:
        """The model's greedy answer to ``prompt`` about ``frame``; ``""`` if generation fails."""
        if self._loaded is None:
            raise BackendUnavailable(f"the hf backend for '{self.model}' was closed; build a new one.")
        loaded = self._loaded
        import torch
        from PIL import Image

        image = Image.fromarray(frame.pixels)
        try:
            inputs = self._inputs(loaded, prompt.text, image)
            with torch.inference_mode():
                out = loaded.model.generate(**inputs, do_sample=False, max_new_tokens=self.max_new_tokens)
            new_tokens = out[0, inputs["input_ids"].shape[1]:]
            tokenizer = getattr(loaded.processor, "tokenizer", loaded.processor)
            return str(tokenizer.decode(new_tokens, skip_special_tokens=True)).strip()
        except Exception as exc:  # a probe over many frames must not die on one bad generation
            logger.warning("hf model %s failed to answer (%s: %s); recording an empty answer",
                           self.model, type(exc).__name__, _one_line(exc))
            return ""

    def close(self) -> None:
        """Drop the model and processor so their memory can be freed."""
        self._loaded = None
