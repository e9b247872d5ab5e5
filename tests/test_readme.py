"""The README is a front door: short, its commands the ones CI and the docs run, its links alive."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def test_the_readme_is_at_most_8000_characters() -> None:
    assert len(README) <= 8000, len(README)


def test_the_first_screen_holds_the_path_to_a_committed_number() -> None:
    screen = "\n".join(README.splitlines()[:40])
    assert "pip install -e" in screen and "vlmrl compare results/" in screen
    assert "SIMULATED VLM" in screen
    figure = re.search(r"as committed in\s+\[`(results/[^`]+)`\]", screen)
    assert figure is not None and (ROOT / figure.group(1)).is_file()


def test_the_test_command_is_the_one_ci_runs() -> None:
    assert "python3 -m pip install nox && python3 -m nox -s tests" in README
    assert "python3 -m nox -s tests" in (ROOT / ".ci" / "run").read_text(encoding="utf-8")


def test_every_relative_link_resolves() -> None:
    links = [link.split("#")[0] for link in re.findall(r"\]\(([^)\s]+)\)", README) if "://" not in link]
    assert links and not [link for link in links if not (ROOT / link).exists()]
