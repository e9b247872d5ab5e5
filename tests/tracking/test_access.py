"""tracking.access: a store is checked without MLflow."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from vlmrl_cli.tracking import access


def test_resolve_prefers_argument_then_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MLFLOW_TRACKING_URI", "sqlite:///env.db")
    assert access.resolve_tracking_uri("sqlite:///arg.db") == "sqlite:///arg.db"
    assert access.resolve_tracking_uri(None) == "sqlite:///env.db"
    monkeypatch.delenv("MLFLOW_TRACKING_URI")
    assert access.resolve_tracking_uri(None) == access.DEFAULT_TRACKING_URI


def test_a_store_is_checked_without_mlflow_and_the_check_leaves_nothing(tmp_path: Path) -> None:
    assert access.store_problem(f"sqlite:///{tmp_path}/new/sub/mlflow.db") is None  # connect makes the folders
    assert access.store_problem(f"sqlite:///{tmp_path}/m.db", write=False, existing=True) is not None
    assert not list(tmp_path.iterdir())  # the folder was probed with an anonymous file
    code = ("import sys\nfrom vlmrl_cli.core.errors import BadInput\nfrom vlmrl_cli.tracking import access\n"
            "for uri in ('sqlite:////proc/vlmrl.db', 'nope://x'):\n"
            "    try:\n        access.check_store(uri)\n    except BadInput as exc:\n        print(exc)\n"
            "print('mlflow' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    lines = out.stdout.splitlines()
    assert "no file can be written in /proc" in lines[0] and "no store for the scheme 'nope'" in lines[1]
    assert lines[2] == "False"
