"""The response cache: keys separate every input, values survive reopening."""

from __future__ import annotations

from pathlib import Path

import pytest

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.frames.render import FrameRenderer
from vlmrl_cli.vlm.cache import ResponseCache, cache_key
from vlmrl_cli.vlm.client import VLMClient
from vlmrl_cli.vlm.config import SimKnobs
from vlmrl_cli.vlm.prompts import PROMPTS, PromptKind
from vlmrl_cli.vlm.sim import SimulatedVLM


def test_key_depends_on_every_part() -> None:
    base = ("sim", "m", "p", "abc")
    keys = {cache_key(*base)}
    for i in range(4):
        changed = list(base)
        changed[i] = changed[i] + "x"
        keys.add(cache_key(*changed))
    assert len(keys) == 5


def test_roundtrip_and_persistence(tmp_path: Path) -> None:
    path = tmp_path / "c.sqlite"
    cache = ResponseCache(path)
    key = cache_key("sim", "m", "p", "abc")
    cache.put(key, "sim", "m", "BOTTOM", 0.25)
    cache.close()
    reopened = ResponseCache(path)
    assert reopened.get(key) == ("BOTTOM", 0.25)
    assert reopened.get(cache_key("sim", "m", "p", "abd")) is None
    assert (reopened.hits, reopened.misses) == (1, 1)
    reopened.close()


def test_unwritable_cache_is_bad_input(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(BadInput):
        ResponseCache(blocker / "c.sqlite")


def test_client_serves_the_second_query_from_the_cache(tmp_path: Path) -> None:
    with FrameRenderer() as renderer:
        frame = renderer.render(-0.5)
    client = VLMClient(SimulatedVLM(SimKnobs()), cache=ResponseCache(tmp_path / "c.sqlite"))
    first = client.ask(PROMPTS[PromptKind.FLOAT], frame)
    second = client.ask(PROMPTS[PromptKind.FLOAT], frame)
    assert first.text == second.text and not first.cached and second.cached
    assert (client.stats.cache_hits, client.stats.cache_misses) == (1, 1)
    client.close()
