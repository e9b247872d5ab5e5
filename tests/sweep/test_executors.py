"""Executor choice and the checks made before anything is created."""

from __future__ import annotations

import dataclasses
import os

import pytest

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.sweep import executors
from vlmrl_cli.training.config import RunConfig, TrainJob
from vlmrl_cli.training.events import JobContext, JobResult


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


def _env_job(job: TrainJob, ctx: JobContext) -> JobResult:  # what a worker sees, reported as its run id
    import signal

    blocked = signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, [])
    ignored = signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    seen = f"{os.environ.get('VLMRL_TEST_PROBE')}|{blocked}|{ignored}|{os.getpid()}"
    return JobResult(job.name, seen, "FINISHED", 0.0)


def _ran(executor: executors.LocalExecutor, job: TrainJob) -> list[str]:
    executor.submit([job], _env_job, None)  # type: ignore[arg-type]
    results: list[JobResult] = []
    while executor.outstanding:
        results += executor.poll(0.2).results
    executor.close()
    return results[0].run_id.split("|")


def test_a_forked_worker_sees_the_sweep_s_environment_now_and_never_a_ctrl_c(monkeypatch: pytest.MonkeyPatch) -> None:
    """Workers fork from a fork server started once per process: each pool's workers still take
    the environment of the moment the pool is made (not the fork server's), and SIGINT stays
    blocked and ignored in them (the sweep alone handles a Ctrl-C)."""
    job = RunConfig(arms=("baseline",), seeds=(0,)).jobs()[0]
    monkeypatch.setenv("VLMRL_TEST_PROBE", "first")
    first = _ran(executors.LocalExecutor(1), job)
    monkeypatch.setenv("VLMRL_TEST_PROBE", "second")
    second = _ran(executors.LocalExecutor(1), job)
    assert first[:3] == ["first", "True", "True"] and second[:3] == ["second", "True", "True"]
    assert first[3] != second[3] and str(os.getpid()) not in (first[3], second[3])
