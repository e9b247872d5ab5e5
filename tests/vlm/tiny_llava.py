"""Build a tiny, randomly initialised LLaVA model offline and save it like a downloaded one.

The result is a folder that ``AutoProcessor`` / ``AutoModelForImageTextToText`` load exactly as
they load ``llava-hf/llava-1.5-7b-hf``: config, safetensors weights, a fast tokenizer (trained
here with ``tokenizers`` on a few sentences), a CLIP image processor and a chat template. The
weights are random, so the answers are garbage, which is what the parser tests want.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

IMAGE_SIZE = 28
PATCH_SIZE = 14
IMAGE_TOKEN = "<image>"
SPECIAL_TOKENS = ("<unk>", "<s>", "</s>", "<pad>", IMAGE_TOKEN)
CHAT_TEMPLATE = (
    "{% for message in messages %}{{ message['role'] | upper }}: "
    "{% for part in message['content'] %}"
    "{% if part['type'] == 'image' %}<image>{{ '\\n' }}"
    "{% elif part['type'] == 'text' %}{{ part['text'] }}{% endif %}"
    "{% endfor %}{{ '\\n' }}{% endfor %}"
    "{% if add_generation_prompt %}ASSISTANT:{% endif %}"
)
_CORPUS = (
    "The car is at x = -0.52 on the track.",
    "Box [120, 200, 180, 260] in pixel coordinates.",
    "LEFT_PEAK LEFT_SLOPE BOTTOM RIGHT_SLOPE NEAR_GOAL GOAL",
    "USER: ASSISTANT: answer with a number only",
    "0 1 2 3 4 5 6 7 8 9 . , - [ ]",
)


def build_tiny_llava(folder: Path, seed: int = 0, image_gain: float = 1.0) -> Path:
    """Write a tiny LLaVA (CLIP vision tower + Llama text model, ~43k parameters) to ``folder``.

    ``image_gain`` scales the projector's weights: at 1 the random model says the same whatever
    the image; at 30 its answers differ from frame to frame (what a batching test needs to see a
    frame's answer land in another's place). Needs no network: nothing is downloaded. Returns ``folder``.
    """
    import torch
    from tokenizers import Tokenizer, decoders, models, pre_tokenizers, trainers
    from transformers import (
        CLIPVisionConfig,
        LlamaConfig,
        LlavaConfig,
        LlavaForConditionalGeneration,
        LlavaProcessor,
        PreTrainedTokenizerFast,
    )

    image_processor_cls: Any
    try:  # transformers >= 5 names the torchvision-free processor explicitly
        from transformers import CLIPImageProcessorPil as image_processor_cls
    except ImportError:
        from transformers import CLIPImageProcessor as image_processor_cls

    raw = Tokenizer(models.BPE(unk_token="<unk>"))
    raw.pre_tokenizer = pre_tokenizers.ByteLevel(add_prefix_space=False)
    raw.decoder = decoders.ByteLevel()
    trainer = trainers.BpeTrainer(
        vocab_size=320, special_tokens=list(SPECIAL_TOKENS), initial_alphabet=pre_tokenizers.ByteLevel.alphabet()
    )
    raw.train_from_iterator(list(_CORPUS) * 8, trainer)
    tokenizer = PreTrainedTokenizerFast(
        tokenizer_object=raw, unk_token="<unk>", bos_token="<s>", eos_token="</s>", pad_token="<pad>",
        extra_special_tokens={"image_token": IMAGE_TOKEN},
    )
    ids: dict[str, int] = {}
    for tok in SPECIAL_TOKENS:
        token_id = raw.token_to_id(tok)
        assert token_id is not None, f"the trained tokenizer lost the special token {tok}"
        ids[tok] = token_id

    vision = CLIPVisionConfig(
        image_size=IMAGE_SIZE, patch_size=PATCH_SIZE, hidden_size=16, intermediate_size=32,
        num_hidden_layers=1, num_attention_heads=2, projection_dim=16,
    )
    text = LlamaConfig(
        vocab_size=raw.get_vocab_size(), hidden_size=32, intermediate_size=64, num_hidden_layers=1,
        num_attention_heads=2, num_key_value_heads=2, max_position_embeddings=256,
        bos_token_id=ids["<s>"], eos_token_id=ids["</s>"], pad_token_id=ids["<pad>"],
    )
    n_patches = (IMAGE_SIZE // PATCH_SIZE) ** 2
    config = LlavaConfig(
        vision_config=vision, text_config=text, image_token_index=ids[IMAGE_TOKEN],
        vision_feature_layer=-1, vision_feature_select_strategy="default", image_seq_length=n_patches,
    )
    torch.manual_seed(seed)
    model = LlavaForConditionalGeneration(config).eval()
    if image_gain != 1.0:
        with torch.no_grad():
            for name, param in model.named_parameters():
                if "multi_modal_projector" in name and name.endswith("weight"):
                    param.mul_(image_gain)
    image_processor = image_processor_cls(
        size={"shortest_edge": IMAGE_SIZE}, crop_size={"height": IMAGE_SIZE, "width": IMAGE_SIZE}
    )
    processor = LlavaProcessor(
        image_processor=image_processor, tokenizer=tokenizer, patch_size=PATCH_SIZE,
        vision_feature_select_strategy="default", num_additional_image_tokens=1, chat_template=CHAT_TEMPLATE,
    )
    folder.mkdir(parents=True, exist_ok=True)
    model.save_pretrained(folder)
    processor.save_pretrained(folder)
    return folder


def folder_size_bytes(folder: Path) -> int:
    """Total size of the files in ``folder``."""
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())
