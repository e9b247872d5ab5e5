"""A local image-text-to-text model (LLaVA, Qwen-VL, ...) run in-process through transformers.

Any model that ``AutoProcessor`` and ``AutoModelForImageTextToText`` can load works: a hub id
(``llava-hf/llava-1.5-7b-hf``, the paper's model) or a local folder written by
``save_pretrained``. transformers is imported only when a model is loaded, so the CLI starts
fast for the other backends.
"""

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


def _chunks(frames: Sequence[Frame], size: int) -> Iterator[Sequence[Frame]]:
    """``frames`` in consecutive slices of at most ``size``."""
    for i in range(0, len(frames), max(1, size)):
        yield frames[i:i + max(1, size)]


def _cache_kwarg(model: Any) -> str:
    """``forward``'s KV-cache keyword: ``cache`` in newer transformers, ``past_key_values`` before."""
    import inspect

    return "cache" if "cache" in inspect.signature(model.forward).parameters else "past_key_values"


def _kv_cache(output: Any) -> Any:
    """The KV cache a forward pass returned (``cache`` or, in older transformers, ``past_key_values``)."""
    cache = output.get("cache") if hasattr(output, "get") else None
    return cache if cache is not None else output.past_key_values


@dataclass
class _Loaded:
    processor: Any
    model: Any
    device: str
    dtype: Any


class HFBackend:
    """A transformers image-text-to-text model, greedy-decoded, answering (prompt, frame) one at a
    time (``answer``) or a round of frames in batches (``answer_many``), and scoring an MCQ's
    options by their log-probabilities (``score_many``).

    The prompt goes through the processor's chat template as one user turn holding the image
    and the text; only the newly generated tokens are decoded. A failure while generating (an
    odd tokenizer, a model that chokes on the image) is logged and answered with ``""`` so a
    probe over many frames carries on; the parsers count it as a failed answer.
    """

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
        return cls(model_id, _Loaded(processor, model, device, dtype), max_new_tokens=cfg.max_new_tokens,
                   batch_size=cfg.max_concurrency)

    def _chat_text(self, loaded: _Loaded, text: str) -> str:
        """``text`` as one user turn holding the image, through the chat template if any."""
        processor = loaded.processor
        if getattr(processor, "chat_template", None):
            messages = [{"role": "user", "content": [{"type": "image"}, {"type": "text", "text": text}]}]
            return str(processor.apply_chat_template(messages, add_generation_prompt=True, tokenize=False))
        return text  # processors without a template (e.g. PaliGemma) insert their image tokens themselves

    def _inputs(self, loaded: _Loaded, text: str, images: Sequence[Any]) -> Any:
        """Processor inputs for one user turn of (image, text) per image, padded on the left (a
        decoder continues each row from its last token) when the rows differ in length."""
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

    def _decoded(self, loaded: _Loaded, out: Any, prompt_len: int) -> list[str]:
        tokenizer = getattr(loaded.processor, "tokenizer", loaded.processor)
        return [str(tokenizer.decode(row[prompt_len:], skip_special_tokens=True)).strip() for row in out]

    def _generate(self, loaded: _Loaded, prompt: Prompt, frames: Sequence[Frame]) -> list[str]:
        """Greedy answers about ``frames`` from one batched ``generate``."""
        import torch
        from PIL import Image

        inputs = self._inputs(loaded, prompt.text, [Image.fromarray(f.pixels) for f in frames])
        with torch.inference_mode():
            out = loaded.model.generate(**inputs, do_sample=False, max_new_tokens=self.max_new_tokens)
        return self._decoded(loaded, out, inputs["input_ids"].shape[1])

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
        """The greedy answers about ``frames``, in order, from batched ``generate`` calls of at most
        ``batch_size`` frames (left-padded): what ``answer`` says of each. A batch that fails is
        asked again frame by frame, so one bad frame costs only its own answer."""
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

    # -- MCQ by option log-probability --------------------------------------------------------

    def option_ids(self, prompt: Prompt) -> list[list[int]]:
        """The token ids of each of ``prompt.options`` as the model would write it after the
        prompt: the tail of the tokenised (prompt + answer), where the prompt's own tokens are its
        head, else the answer tokenised alone. The answer is the label after a space unless the
        template ends in whitespace (LLaVA-1.5's ``ASSISTANT:`` is followed by `` BOTTOM``; a
        template ending in a newline, as Qwen's, by ``BOTTOM``)."""
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
        """Each option's log-probability about each of ``frames``: one prefill of the prompt and
        image per frame (batched, left-padded), whose last position scores every option's first
        token; options of several tokens continue from a copy of the prefill's KV cache, all in
        one more forward pass."""
        loaded = self._loaded_or_refuse()
        assert prompt.options is not None
        ids = self.option_ids(prompt)
        out: list[OptionScores | None] = []
        for chunk in _chunks(frames, self.batch_size):
            rows = self._option_logprobs(loaded, prompt, chunk, ids)
            out.extend(OptionScores(prompt.options, tuple(row)) for row in rows)
        return out

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
                pad = 0
                cont = torch.tensor([tok[:-1] + [pad] * (longest - len(tok)) for tok in ids], device=mask.device)
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
        """Drop the model and processor so their memory can be freed."""
        self._loaded = None
