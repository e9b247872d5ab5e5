"""Writability checks create nothing and name the blocking path."""

from __future__ import annotations

from pathlib import Path

from vlmrl_cli.core.paths import file_problem, folder_problem


def _tree(root: Path) -> list[Path]:
    return sorted(root.rglob("*"))


def test_a_missing_folder_under_a_writable_one_is_fine_and_not_created(tmp_path: Path) -> None:
    assert folder_problem(tmp_path / "a" / "b") is None
    assert file_problem(tmp_path / "a" / "c.sqlite") is None
    assert _tree(tmp_path) == []


def test_a_file_in_the_way_is_named(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    problem = folder_problem(tmp_path / "f" / "out")
    assert problem is not None and str(tmp_path / "f") in problem
    assert file_problem(tmp_path) is not None  # a folder is not a file
    assert _tree(tmp_path) == [tmp_path / "f"]


def test_a_pseudo_file_system_is_refused_even_for_root() -> None:
    assert folder_problem(Path("/proc/vlmrl-out")) is not None
