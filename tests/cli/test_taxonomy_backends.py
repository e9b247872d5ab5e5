"""`vlmrl taxonomy` with the real backends (openai over loopback HTTP, hf with a tiny model):
a clean one-line failure (exit 2, no traceback, no table) or a written Table 1."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from tests.vlm.fake_openai import FakeServer, down_url, status_only
from tests.vlm.tiny_llava import build_tiny_llava
from vlmrl_cli.cli.app import app

runner = CliRunner()  # click 8.2+: result.stderr is kept apart from result.stdout


def _taxonomy(d: Path, *args: str) -> Any:
    return runner.invoke(app, [
        "taxonomy", *args, "--states", "2", "--out", str(d), "--cache-path", str(d / "cache.sqlite"),
        "--tracking-uri", f"sqlite:///{d}/mlflow.db",
    ])


def _openai(d: Path, base_url: str) -> Any:
    return _taxonomy(d, "--vlm", "openai", "--base-url", base_url, "--model", "m", "--retries", "1",
                     "--timeout", "2")


def _assert_clean_failure(result: Any, d: Path) -> str:
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert "Traceback" not in result.output
    assert not (d / "table1.md").exists()
    return lines[0]


def test_openai_server_down(tmp_path: Path) -> None:
    line = _assert_clean_failure(_openai(tmp_path / "D", down_url()), tmp_path / "D")
    assert "unreachable" in line and "--base-url" in line


def test_openai_malformed_json(tmp_path: Path) -> None:
    with FakeServer(chat=status_only(200, "<html>not json</html>")) as server:
        line = _assert_clean_failure(_openai(tmp_path / "D", server.url), tmp_path / "D")
    assert "malformed response" in line


def test_openai_missing_base_url(tmp_path: Path) -> None:
    line = _assert_clean_failure(_taxonomy(tmp_path / "D", "--vlm", "openai", "--model", "m"), tmp_path / "D")
    assert "--base-url" in line


def test_hf_missing_model_path(tmp_path: Path) -> None:
    line = _assert_clean_failure(_taxonomy(tmp_path / "D", "--vlm", "hf", "--model", "/nonexistent"), tmp_path / "D")
    assert "/nonexistent" in line and "--model" in line


def test_openai_happy_path(tmp_path: Path) -> None:
    d = tmp_path / "D"
    with FakeServer() as server:
        result = _openai(d, server.url)
    assert result.exit_code == 0, result.output
    assert (d / "table1.md").is_file()
    assert "SIMULATED" not in result.output
    chats = server.on("/v1/chat/completions")
    assert chats and all(r.json()["model"] == "m" for r in chats)
    assert "openai:m" in result.stdout


@pytest.fixture(scope="module")
def tiny_llava(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The tiny random LLaVA of tests/vlm, with torch on one thread (its ops are too small to share)."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield build_tiny_llava(tmp_path_factory.mktemp("tiny-llava"))
    torch.set_num_threads(threads)


def test_hf_tiny_model_happy_path(tmp_path: Path, tiny_llava: Path) -> None:
    d = tmp_path / "D"
    result = _taxonomy(d, "--vlm", "hf", "--model", str(tiny_llava), "--device", "cpu", "--max-new-tokens", "8")
    assert result.exit_code == 0, result.output
    assert (d / "table1.md").is_file()
    assert f"hf:{tiny_llava}" in result.stdout
