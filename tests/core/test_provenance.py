"""Provenance: which commit a result names, and when it calls it dirty."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vlmrl_cli.core import provenance
from vlmrl_cli.core.provenance import config_hash, flatten, git_commit


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=repo, capture_output=True, text=True, check=True).stdout.strip()


@pytest.fixture()
def repo(tmp_path: Path) -> Path:
    """A repo shaped like vlmrl's: code in a package folder, committed outputs in results/."""
    root = tmp_path / "repo"
    (root / "pkg").mkdir(parents=True)
    (root / "results").mkdir()
    (root / "pkg" / "code.py").write_text("x = 1\n")
    (root / "results" / "table.csv").write_text("a\n1\n")
    _git(root, "init", "-q")
    _git(root, "add", ".")
    _git(root, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "init")
    return root


def test_a_clean_tree_gives_the_bare_commit(repo: Path) -> None:
    assert git_commit(repo) == _git(repo, "rev-parse", "HEAD")


def test_rewritten_results_do_not_make_the_commit_dirty(repo: Path) -> None:
    # A repro rewrites committed outputs; the code that produced them is still the commit's.
    (repo / "results" / "table.csv").write_text("a\n2\n")
    assert not git_commit(repo).endswith("-dirty")
    assert not git_commit(repo / "pkg").endswith("-dirty")


def test_changed_code_anywhere_in_the_tree_is_dirty_even_when_asked_from_a_subfolder(repo: Path) -> None:
    (repo / "pkg" / "code.py").write_text("x = 2\n")
    sha = _git(repo, "rev-parse", "HEAD")
    assert git_commit(repo) == f"{sha}-dirty"
    (repo / "pkg" / "code.py").write_text("x = 1\n")
    (repo / "top.txt").write_text("t\n")
    _git(repo, "add", "top.txt")
    assert git_commit(repo / "pkg") == f"{sha}-dirty"  # a staged change outside pkg/ counts too


def test_outside_any_repository_the_commit_is_unknown(tmp_path: Path) -> None:
    assert git_commit(tmp_path) == "unknown"


def test_by_default_the_commit_is_that_of_vlmrls_own_source_not_the_callers_cwd(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # not a repository
    assert git_commit() == git_commit(provenance._SOURCE.parent)


@given(st.dictionaries(st.text(min_size=1, max_size=5), st.integers() | st.text(max_size=5), max_size=6))
def test_config_hash_ignores_key_order_and_sees_every_value(cfg: dict[str, object]) -> None:
    reordered = dict(reversed(list(cfg.items())))
    assert config_hash(reordered) == config_hash(cfg)
    for key in cfg:
        assert config_hash({**cfg, key: ["changed"]}) != config_hash(cfg)


def test_flatten_gives_dotted_string_params() -> None:
    assert flatten({"ppo": {"gamma": 0.99, "n_envs": 16}, "arms": ["a", "b"], "vlm": None, "cache": True}) == {
        "ppo.gamma": "0.99", "ppo.n_envs": "16", "arms": '["a", "b"]', "vlm": "null", "cache": "true"}


def test_a_copy_of_the_package_that_git_does_not_track_names_no_commit(
        repo: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # e.g. vlmrl installed into an ignored .venv inside someone else's repository
    fake = repo / ".venv" / "vlmrl_cli" / "core" / "provenance.py"
    fake.parent.mkdir(parents=True)
    fake.write_text("")
    monkeypatch.setattr(provenance, "_SOURCE", fake)
    assert git_commit() == "unknown"
    assert git_commit(repo) == _git(repo, "rev-parse", "HEAD")  # an explicit folder is still read


def test_cpu_paths_name_numpy_simd_blas_and_torch() -> None:
    from vlmrl_cli.core.provenance import cpu_paths

    paths = cpu_paths()
    assert set(paths) == {"numpy_simd", "blas", "torch"}
    assert all(paths.values())


def test_cpu_paths_see_a_forced_blas_kernel() -> None:
    import os
    import subprocess
    import sys

    from vlmrl_cli.core.provenance import cpu_paths

    if not cpu_paths()["blas"].startswith("openblas"):
        pytest.skip("this numpy does not use OpenBLAS")
    code = "from vlmrl_cli.core.provenance import cpu_paths; print(cpu_paths()['blas'])"

    def forced(core: str) -> str:
        out = subprocess.run([sys.executable, "-c", code], env=os.environ | {"OPENBLAS_CORETYPE": core},
                             capture_output=True, text=True, check=True)
        return out.stdout.strip()

    assert forced("Haswell") == "openblas Haswell"
    assert forced("Nehalem") not in ("openblas Haswell", "")


def test_a_blas_kernel_loaded_twice_is_named_once() -> None:
    # scipy ships its own copy of OpenBLAS: with both loaded, the tag must not depend on whether
    # scipy was imported before the run was tagged
    import scipy.linalg

    scipy.linalg.svd([[1.0, 0.0], [0.0, 1.0]])
    entries = provenance.cpu_paths()["blas"].split(";")
    assert len(entries) == len(set(entries))
