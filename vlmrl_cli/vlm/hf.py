"""A local image-text-to-text model run in-process through transformers. See docs/real-vlm.md."""

from __future__ import annotations

import logging
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vlmrl_cli.core.errors import BackendUnavailable, BadInput
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.vlm.base import OptionScores
from vlmrl_cli.vlm.config import PAPER_MODEL, VLMConfig
from vlmrl_cli.vlm.prompts import Prompt

logger = logging.getLogger(__name__)

DTYPES: tuple[str, ...] = ("auto", "float32", "float16", "bfloat16")


def resolve_dtype(name: str, device: str) -> Any:
    """The ``torch.dtype`` named ``name``; ``auto`` is float16 on CUDA and float32 elsewhere."""
    import torch

    if name not in DTYPES:
        raise BadInput(f"unknown --dtype '{name}'; choose one of {', '.join(DTYPES)}.")
    if name == "auto":
        return torch.float16 if device.startswith("cuda") else torch.float32
    return getattr(torch, name)


def _dtype_kwarg() -> str:
    """``from_pretrained``'s dtype keyword (``torch_dtype`` before transformers 4.56)."""
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


def _load_error(model: str, exc: BaseException) -> BackendUnavailable:
    """One sentence saying why ``model`` did not load and what to do about it."""
    names: set[str] = set()
    seen: list[BaseException] = []
    cur: BaseException | None = exc
    while cur is not None and cur not in seen:  # exc and every exception it was raised from
        seen.append(cur)
        names.add(type(cur).__name__)
        cur = cur.__cause__ or cur.__context__
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
    """``(path, local)`` of ``cfg.model`` without loading it: a model folder or a hub id (unchecked)."""
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
    """Why the hub id ``model_id`` cannot be loaded here (None: cached locally or on the hub)."""
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


def _chunks(frames: Sequence[Frame], size: int) -> Iterator[Sequence[Frame]]:
    for i in range(0, len(frames), max(1, size)):
        yield frames[i:i + max(1, size)]


def _cache_kwarg(model: Any) -> str:
    """``forward``'s KV-cache keyword (``past_key_values`` in older transformers)."""
    import inspect

    return "cache" if "cache" in inspect.signature(model.forward).parameters else "past_key_values"


def _kv_cache(output: Any) -> Any:
    cache = output.get("cache") if hasattr(output, "get") else None
    return cache if cache is not None else output.past_key_values


@dataclass
class _Loaded:
    processor: Any
    model: Any
    device: str
    dtype: Any


class HFBackend:
    """A transformers VLM, greedy, in batches; a failed generation is logged and answered ``""``."""

    name = "hf"
    simulated = False
    can_score = True

    def __init__(self, model_id: str, loaded: _Loaded, max_new_tokens: int = 32, batch_size: int = 8) -> None:
        self.model = model_id
        self.max_new_tokens = max_new_tokens
        self.batch_size = batch_size
        self._loaded: _Loaded | None = loaded

    def __repr__(self) -> str:
        device = self._loaded.device if self._loaded is not None else "closed"
        return f"HFBackend(model={self.model!r}, device={device!r})"

    @classmethod
    def from_config(cls, cfg: VLMConfig) -> HFBackend:
        """Load ``cfg.model`` on ``cfg.device`` (None: cuda if present) in ``cfg.dtype``."""
        model_id = cfg.model or ""
        path, local = locate_model(cfg)  # before torch loads: a wrong path fails fast
        import torch

        device = cfg.device or ("cuda" if torch.cuda.is_available() else "cpu")
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
        return cls(model_id, _Loaded(processor, model, device, dtype), max_new_tokens=cfg.max_new_tokens,
                   batch_size=cfg.max_concurrency)

    def _chat_text(self, loaded: _Loaded, text: str) -> str:
        processor = loaded.processor
        if getattr(processor, "chat_template", None):
            messages = [{"role": "user", "content": [{"type": "image"}, {"type": "text", "text": text}]}]
            return str(processor.apply_chat_template(messages, add_generation_prompt=True, tokenize=False))
        return text  # processors without a template (e.g. PaliGemma) insert their image tokens themselves

    def _inputs(self, loaded: _Loaded, text: str, images: Sequence[Any]) -> Any:
        """Processor inputs of one (image, text) user turn per image, left-padded."""
        processor = loaded.processor
        chat = self._chat_text(loaded, text)
        tokenizer = getattr(processor, "tokenizer", None)
        if tokenizer is not None:
            tokenizer.padding_side = "left"
        inputs = processor(images=list(images), text=[chat] * len(images), padding=True, return_tensors="pt")
        return inputs.to(loaded.device, dtype=loaded.dtype)

    def _loaded_or_refuse(self) -> _Loaded:
        if self._loaded is None:
            raise BackendUnavailable(f"the hf backend for '{self.model}' was closed; build a new one.")
        return self._loaded

    def _generate(self, loaded: _Loaded, prompt: Prompt, frames: Sequence[Frame]) -> list[str]:
        """Greedy answers about ``frames`` from one batched ``generate``."""
        import torch
        from PIL import Image

        inputs = self._inputs(loaded, prompt.text, [Image.fromarray(f.pixels) for f in frames])
        with torch.inference_mode():
            out = loaded.model.generate(**inputs, do_sample=False, max_new_tokens=self.max_new_tokens)
        tokenizer = getattr(loaded.processor, "tokenizer", loaded.processor)
        start = inputs["input_ids"].shape[1]
        return [str(tokenizer.decode(row[start:], skip_special_tokens=True)).strip() for row in out]

    def answer(self, prompt: Prompt, frame: Frame) -> str:
        """The model's greedy answer to ``prompt`` about ``frame``; ``""`` if generation fails."""
        loaded = self._loaded_or_refuse()
        try:
            return self._generate(loaded, prompt, [frame])[0]
        except Exception as exc:  # a probe over many frames must not die on one bad generation
            logger.warning("hf model %s failed to answer (%s: %s); recording an empty answer",
                           self.model, type(exc).__name__, _one_line(exc))
            return ""

    def answer_many(self, prompt: Prompt, frames: Sequence[Frame]) -> list[str]:
        """``answer`` of each frame, from batches of ``batch_size``; a failed batch is asked frame by frame."""
        loaded = self._loaded_or_refuse()
        answers: list[str] = []
        for chunk in _chunks(frames, self.batch_size):
            try:
                answers.extend(self._generate(loaded, prompt, chunk))
            except Exception as exc:
                logger.warning("hf model %s failed on a batch of %d (%s: %s); asking frame by frame",
                               self.model, len(chunk), type(exc).__name__, _one_line(exc))
                answers.extend(self.answer(prompt, f) for f in chunk)
        return answers

    def option_ids(self, prompt: Prompt) -> list[list[int]]:
        """The token ids of each option as the model would write it after the prompt (and a space)."""
        if not prompt.options:
            raise ValueError("option log-probabilities need an MCQ prompt with options (mcq_prompt)")
        loaded = self._loaded_or_refuse()
        tokenizer = getattr(loaded.processor, "tokenizer", loaded.processor)
        chat = self._chat_text(loaded, prompt.text)
        space = "" if chat[-1:].isspace() else " "
        head = list(tokenizer(chat, add_special_tokens=False)["input_ids"])
        ids = []
        for option in prompt.options:
            whole = list(tokenizer(chat + space + option, add_special_tokens=False)["input_ids"])
            tail = whole[len(head):] if whole[:len(head)] == head and len(whole) > len(head) else \
                list(tokenizer(space + option, add_special_tokens=False)["input_ids"])
            if not tail:
                raise ValueError(f"the option '{option}' tokenises to nothing")
            ids.append(tail)
        return ids

    def score_many(self, prompt: Prompt, frames: Sequence[Frame]) -> list[OptionScores | None]:
        """Each option's log-probability about each frame: a prefill, then one pass over later tokens."""
        loaded = self._loaded_or_refuse()
        assert prompt.options is not None
        ids = self.option_ids(prompt)
        return [OptionScores(prompt.options, tuple(row)) for chunk in _chunks(frames, self.batch_size)
                for row in self._option_logprobs(loaded, prompt, chunk, ids)]

    def _option_logprobs(self, loaded: _Loaded, prompt: Prompt, frames: Sequence[Frame],
                         ids: list[list[int]]) -> list[list[float]]:
        import torch
        from PIL import Image

        inputs = self._inputs(loaded, prompt.text, [Image.fromarray(f.pixels) for f in frames])
        mask = inputs["attention_mask"]
        positions = (mask.cumsum(-1) - 1).clamp(min=0)
        with torch.inference_mode():
            pre = loaded.model(**inputs, position_ids=positions, use_cache=True)
            first = torch.log_softmax(pre.logits[:, -1, :].float(), dim=-1)  # (B, V)
            scores = torch.stack([first[:, tok[0]] for tok in ids], dim=1)  # (B, O)
            longest = max(len(tok) for tok in ids)
            if longest > 1:  # the options' later tokens: one pass over (frame, option) rows
                n_opt, batch = len(ids), len(frames)
                cont = torch.tensor([tok[:-1] + [0] * (longest - len(tok)) for tok in ids], device=mask.device)
                real = torch.tensor([[1] * (len(tok) - 1) + [0] * (longest - len(tok)) for tok in ids],
                                    device=mask.device, dtype=mask.dtype)
                cache = _kv_cache(pre)
                cache.batch_repeat_interleave(n_opt)
                cont_ids = cont.repeat(batch, 1)  # row b * O + o: frame b, option o
                cont_mask = torch.cat([mask.repeat_interleave(n_opt, dim=0), real.repeat(batch, 1)], dim=1)
                start = mask.sum(-1).repeat_interleave(n_opt).unsqueeze(1)
                cont_pos = start + torch.arange(longest - 1, device=mask.device).unsqueeze(0)
                nxt = loaded.model(input_ids=cont_ids, attention_mask=cont_mask, position_ids=cont_pos,
                                   use_cache=True, **{_cache_kwarg(loaded.model): cache})
                logp = torch.log_softmax(nxt.logits.float(), dim=-1)  # (B*O, L-1, V)
                for o, tok in enumerate(ids):
                    for j in range(1, len(tok)):
                        scores[:, o] += logp[o::n_opt, j - 1, tok[j]]
        return [[float(v) for v in row] for row in scores.cpu()]

    def close(self) -> None:
        self._loaded = None
