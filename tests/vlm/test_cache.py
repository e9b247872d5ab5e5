"""The response cache: keys separate every input, values survive reopening."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.mountain_car_helpers import sim_vlm
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.tasks.mountain_car.prompts import PROMPTS
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer
from vlmrl_cli.vlm.cache import ResponseCache, cache_key
from vlmrl_cli.vlm.client import VLMClient
from vlmrl_cli.vlm.config import SimKnobs
from vlmrl_cli.vlm.prompts import PromptKind


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
    reopened.close()


def test_unwritable_cache_is_bad_input(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(BadInput):
        ResponseCache(blocker / "c.sqlite")


def test_client_serves_the_second_query_from_the_cache(tmp_path: Path) -> None:
    with FrameRenderer() as renderer:
        frame = renderer.render(-0.5)
    client = VLMClient(sim_vlm(SimKnobs()), cache=ResponseCache(tmp_path / "c.sqlite"))
    first = client.ask(PROMPTS[PromptKind.FLOAT], frame)
    second = client.ask(PROMPTS[PromptKind.FLOAT], frame)
    assert first.text == second.text and not first.cached and second.cached
    assert (client.stats.cache_hits, client.stats.cache_misses) == (1, 1)
    client.close()


def _rows_on_disk(path: Path) -> int:
    import sqlite3

    with sqlite3.connect(str(path)) as db:
        return int(db.execute("SELECT COUNT(*) FROM responses").fetchone()[0])


def test_answers_are_written_in_batches_and_served_while_pending(tmp_path: Path) -> None:
    path = tmp_path / "c.sqlite"
    cache = ResponseCache(path, batch=3, max_age_s=3600.0)
    keys = [cache_key("sim", "m", "p", str(i)) for i in range(4)]
    for i, key in enumerate(keys[:2]):
        cache.put(key, "sim", "m", f"A{i}", 0.1)
    assert _rows_on_disk(path) == 0  # pending: no commit yet
    assert cache.get(keys[1]) == ("A1", 0.1)  # but served from memory
    cache.put(keys[2], "sim", "m", "A2", 0.1)
    assert _rows_on_disk(path) == 3  # the third answer fills the batch
    cache.put(keys[3], "sim", "m", "A3", 0.1)
    cache.close()  # close writes what is pending
    assert _rows_on_disk(path) == 4


def test_an_old_pending_answer_is_written_without_a_full_batch(tmp_path: Path) -> None:
    path = tmp_path / "c.sqlite"
    cache = ResponseCache(path, batch=100, max_age_s=0.0)  # a slow backend: flush at once
    cache.put(cache_key("sim", "m", "p", "a"), "sim", "m", "BOTTOM", 2.0)
    assert _rows_on_disk(path) == 1
    cache.close()


def test_a_bad_batch_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="batch"):
        ResponseCache(tmp_path / "c.sqlite", batch=0)
