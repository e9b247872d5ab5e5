"""The ``vlmrl`` entry point's process settings, made before the app loads."""

from __future__ import annotations

import os

import pytest

from vlmrl_cli.cli import entry


def test_the_entry_point_chooses_a_headless_video_driver_unless_the_user_chose_one(
        monkeypatch: pytest.MonkeyPatch) -> None:
    import vlmrl_cli.cli.app as app
    import vlmrl_cli.core.numeric_pin as numeric_pin

    monkeypatch.setattr(numeric_pin, "apply", lambda: None)  # this process is pinned already, by its own rules
    monkeypatch.setattr(app, "main", lambda: None)
    monkeypatch.delenv("SDL_VIDEODRIVER", raising=False)
    entry.main()
    assert os.environ["SDL_VIDEODRIVER"] == "dummy"
    monkeypatch.setenv("SDL_VIDEODRIVER", "offscreen")
    entry.main()
    assert os.environ["SDL_VIDEODRIVER"] == "offscreen"
