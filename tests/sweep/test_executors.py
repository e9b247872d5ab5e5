"""Executor choice and the checks made before anything is created."""

from __future__ import annotations

import dataclasses

import pytest

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.sweep import executors
from vlmrl_cli.training.config import RunConfig


@pytest.mark.parametrize(("address", "remote"), [
    (None, False), ("auto", False), ("local", False), ("127.0.0.1:6379", False), ("localhost:6379", False),
    ("ray://127.0.0.1:10001", False), ("10.0.0.5:6379", True), ("ray://head.cluster:10001", True),
])
def test_which_ray_addresses_are_other_machines(address: str | None, remote: bool) -> None:
    assert executors.is_remote_address(address) is remote


def test_a_remote_cluster_with_a_sqlite_store_is_refused_in_one_sentence() -> None:
    cfg = RunConfig(executor="ray", ray_address="10.0.0.5:6379", tracking_uri="sqlite:///m.db")
    with pytest.raises(BadInput) as info:
        executors.check_executor(cfg)
    message = str(info.value)
    assert "tracking server" in message and "--tracking-uri http://" in message
    assert message.count(". ") == 0  # one sentence
    executors.check_executor(dataclasses.replace(cfg, tracking_uri="http://10.0.0.5:5000"))


def test_ray_missing_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(executors, "find_spec", lambda name: None)
    with pytest.raises(BadInput, match=r"pip install 'vlmrl\[ray\]'"):
        executors.check_executor(RunConfig(executor="ray"))
    executors.check_executor(RunConfig(executor="local"))  # the local pool needs nothing


def test_execution_knobs_are_validated_and_never_hashed() -> None:
    with pytest.raises(BadInput, match="executor"):
        RunConfig(executor="slurm").validate()
    with pytest.raises(BadInput, match="twice heartbeat_s"):
        RunConfig(heartbeat_s=30, stale_after_s=40).validate()
    base = RunConfig(arms=("hybrid",), seeds=(0,))
    moved = dataclasses.replace(base, executor="ray", ray_address="10.0.0.5:6379", max_retries=5, heartbeat_s=5,
                                stale_after_s=60)
    assert base.jobs()[0].config_hash == moved.jobs()[0].config_hash


def test_the_sweep_s_own_process_loads_no_torch() -> None:
    """The pool's initializer and the default job import the worker in the worker: a `vlmrl run`
    process plans, dispatches and records without torch or stable-baselines3 (2.3 s of start-up)."""
    import subprocess
    import sys

    code = ("import sys; import vlmrl_cli.cli.app, vlmrl_cli.cli.run, vlmrl_cli.sweep.runner; "
            "import vlmrl_cli.sweep.preflight; "
            "from vlmrl_cli.sweep.executors import LocalExecutor; LocalExecutor(1).close(); "
            "print(sorted(m for m in ('torch', 'stable_baselines3') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr
