from __future__ import annotations

import multiprocessing
import os
import socket
import sqlite3
from multiprocessing.synchronize import Barrier
from pathlib import Path

import filelock
import pytest

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.tracking import store


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_down_http_server_is_bad_input_quickly() -> None:
    with pytest.raises(BadInput, match="cannot be reached"):
        store.connect(f"http://127.0.0.1:{_closed_port()}")


def test_unwritable_sqlite_location_is_bad_input(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(BadInput):
        store.connect(f"sqlite:///{blocker}/sub/mlflow.db")


def _connect_at_once(barrier: Barrier, uri: str) -> None:
    import mlflow  # noqa: F401  (the slow import happens before the barrier, so the connects collide)

    barrier.wait(timeout=120)
    store.ensure_experiment(store.connect(uri), "vlmrl")


@pytest.mark.parametrize("template", [True, False], ids=["from-the-template", "by-mlflow"])
def test_processes_creating_one_fresh_sqlite_store_at_once_all_succeed(tmp_path: Path, template: bool,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    # A sweep's workers, a second sweep or `vlmrl report` can open a new mlflow.db together.
    # MLflow migrates a fresh schema without a lock; without ``init_lock`` most of these
    # processes failed ("table experiments already exists", "duplicate column name: step").
    # Both ways a new store comes about: a copy of the schema template (which the first process
    # builds, under a lock of its own) and, where the user's cache folder cannot be made
    # (platformdirs reads XDG_CACHE_HOME on Linux), MLflow's migrations in the first process.
    (tmp_path / "not-a-folder").write_text("")
    cache = tmp_path / ("cache" if template else "not-a-folder")
    monkeypatch.setenv("XDG_CACHE_HOME", str(cache))
    uri = f"sqlite:///{tmp_path}/mlflow.db"
    ctx = multiprocessing.get_context("spawn")
    barrier = ctx.Barrier(3)
    procs = [ctx.Process(target=_connect_at_once, args=(barrier, uri)) for _ in range(3)]
    for proc in procs:
        proc.start()
    for proc in procs:
        proc.join(timeout=240)
    assert [proc.exitcode for proc in procs] == [0, 0, 0]
    client = store.connect(uri)
    assert {e.name for e in client.search_experiments()} == {"vlmrl", "Default"}


def _schema(db: Path) -> tuple[set[tuple[object, ...]], list[tuple[str, ...]], list[tuple[object, ...]]]:
    """A store's tables and indexes, schema revision and experiments. A statement is compared as the
    set of its lines: MLflow's own migrations order a table's constraints differently from one
    process to the next."""
    con = sqlite3.connect(db)
    try:
        return ({(kind, name, table, frozenset(line.strip().rstrip(",") for line in (sql or "").splitlines()))
                 for kind, name, table, sql in con.execute("select type, name, tbl_name, sql from sqlite_master")},
                con.execute("select * from alembic_version").fetchall(),
                con.execute("select experiment_id, name, artifact_location, lifecycle_stage "
                            "from experiments").fetchall())
    finally:
        con.close()


@pytest.fixture
def user_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The user's cache folder that ``store.schema_template`` uses, moved under ``tmp_path``."""
    import platformdirs

    folder = tmp_path / "cache" / "vlmrl"
    monkeypatch.setattr(platformdirs, "user_cache_path", lambda *args, **kwargs: folder)
    return folder


def test_a_new_store_is_the_schema_mlflow_makes_copied_from_the_template(
        tmp_path: Path, user_cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from mlflow.tracking import MlflowClient

    monkeypatch.chdir(tmp_path)  # the Default experiment's artifact root is the working folder's
    MlflowClient(tracking_uri=f"sqlite:///{tmp_path}/own.db").search_experiments()
    template = store.schema_template()
    assert template is not None and template.parent == user_cache
    store.connect(f"sqlite:///{tmp_path}/copy.db")
    assert _schema(tmp_path / "copy.db") == _schema(tmp_path / "own.db")
    assert _schema(tmp_path / "copy.db")[2] == [(0, "Default", str(tmp_path / "mlruns" / "0"), "active")]
    # the template has no experiment (MLflow adds Default to each copy, with that process's folder);
    # no partial file is left beside either
    assert _schema(template)[2] == []
    assert [p.name for p in [*tmp_path.iterdir(), *user_cache.iterdir()] if p.name.endswith(".part")] == []


def test_a_broken_template_is_rebuilt_and_without_a_cache_folder_mlflow_makes_the_schema(
        tmp_path: Path, user_cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import platformdirs
    from mlflow.tracking import MlflowClient

    monkeypatch.chdir(tmp_path)
    MlflowClient(tracking_uri=f"sqlite:///{tmp_path}/own.db").search_experiments()
    # a template that is not a database (a crash, another tool) is rebuilt before it is copied
    template = store.schema_template()
    assert template is not None
    template.write_bytes(b"not a database")
    store.ensure_experiment(store.connect(f"sqlite:///{tmp_path}/a.db"), "vlmrl")
    assert _schema(tmp_path / "a.db")[:2] == _schema(tmp_path / "own.db")[:2]
    assert _schema(template)[:2] == _schema(tmp_path / "own.db")[:2]
    # a cache folder that cannot be made: no template, and the store is made as MLflow makes it
    (tmp_path / "file").write_text("")
    monkeypatch.setattr(platformdirs, "user_cache_path", lambda *args, **kwargs: tmp_path / "file" / "vlmrl")
    assert store.schema_template() is None
    store.connect(f"sqlite:///{tmp_path}/b.db")
    assert _schema(tmp_path / "b.db") == _schema(tmp_path / "own.db")


def test_the_init_lock_is_per_database_file(tmp_path: Path) -> None:
    held = store.init_lock(tmp_path / "a.db")
    with held:
        # the same file, however it is spelled, waits; another file does not
        with pytest.raises(filelock.Timeout):
            store.init_lock(tmp_path / "x" / ".." / "a.db").acquire(timeout=0.1)
        other = store.init_lock(tmp_path / "b.db")
        other.acquire(timeout=0.1)
        other.release()


def test_artifacts_live_beside_the_sqlite_database(tmp_path: Path) -> None:
    client = store.connect(f"sqlite:///{tmp_path}/db/mlflow.db")
    exp = client.get_experiment(store.ensure_experiment(client, "e"))
    assert exp.artifact_location == (tmp_path / "db" / "mlartifacts").as_uri()
    # idempotent: the same id the second time
    assert store.ensure_experiment(client, "e") == exp.experiment_id


def test_an_experiment_created_by_another_process_in_between_is_reused(tmp_path: Path) -> None:
    from mlflow.exceptions import MlflowException

    client = store.connect(f"sqlite:///{tmp_path}/mlflow.db")
    real_id = client.create_experiment("e")

    class LateClient:  # sees no "e", then loses the race to create it
        tracking_uri = client.tracking_uri
        lookups = 0

        def get_experiment_by_name(self, name: str) -> object:
            self.lookups += 1
            return None if self.lookups == 1 else client.get_experiment_by_name(name)

        def create_experiment(self, name: str, artifact_location: str | None = None) -> str:
            raise MlflowException(f"Experiment(name={name}) already exists.")

    assert store.ensure_experiment(LateClient(), "e") == real_id


def test_batch_logger_flushes_every_point(tmp_path: Path) -> None:
    client = store.connect(f"sqlite:///{tmp_path}/mlflow.db")
    run = client.create_run(store.ensure_experiment(client, "e"))
    logger = store.BatchLogger(client, run.info.run_id, max_buffer=7)
    for step in range(25):
        logger.log({"a": step, "b": -step}, step=step)
    logger.flush()
    history = client.get_metric_history(run.info.run_id, "a")
    assert sorted(m.step for m in history) == list(range(25))
    assert {m.value for m in client.get_metric_history(run.info.run_id, "b")} == {-float(s) for s in range(25)}


class _CountingClient:
    def __init__(self) -> None:
        self.batches: list[int] = []

    def log_batch(self, run_id: str, metrics: list) -> None:  # type: ignore[type-arg]
        self.batches.append(len(metrics))


def test_batch_logger_writes_a_stale_buffer_without_waiting_for_it_to_fill() -> None:
    """A slow run must show its curves live: a point older than max_age_s is written on the next log."""
    now = [0.0]
    client = _CountingClient()
    logger = store.BatchLogger(client, "r", max_buffer=900, max_age_s=5.0, clock=lambda: now[0])
    logger.log({"a": 1.0}, step=1)
    now[0] = 4.9
    logger.log({"a": 2.0}, step=2)
    assert client.batches == []  # young and small: still buffered
    now[0] = 5.0
    logger.log({"a": 3.0}, step=3)
    assert client.batches == [3]
    now[0] = 9.0
    logger.log({"a": 4.0}, step=4)
    assert client.batches == [3]  # the age counts from the last write, not from the start
    now[0] = 10.0
    logger.log({"a": 5.0}, step=5)
    assert client.batches == [3, 2]


def test_batch_logger_rejects_a_negative_age() -> None:
    with pytest.raises(ValueError, match="max_age_s"):
        store.BatchLogger(_CountingClient(), "r", max_age_s=-1.0)


def test_simulated_runs_are_labelled() -> None:
    tags = store.provenance_tags("sim:pixel-reader (SIMULATED VLM, not a real model)", simulated=True)
    assert tags["vlmrl.simulated"] == "true"
    assert "SIMULATED" in tags["vlmrl.note"]
    assert "vlmrl.version.torch" in tags
    assert "vlmrl.note" not in store.provenance_tags("hf:model", simulated=False)


def test_identical_records_at_the_same_step_are_all_kept(tmp_path: Path) -> None:
    """Two envs can finish identical episodes at the same global step; both must be stored."""
    client = store.connect(f"sqlite:///{tmp_path}/mlflow.db")
    run = client.create_run(store.ensure_experiment(client, "e"))
    logger = store.BatchLogger(client, run.info.run_id)
    for _ in range(3):
        logger.log({"episode/native_return": -200.0, "episode/success": 0.0}, step=400)
    logger.flush()
    for key in ("episode/native_return", "episode/success"):
        assert len(client.get_metric_history(run.info.run_id, key)) == 3


def test_connect_existing_refuses_a_missing_database_and_creates_nothing(tmp_path: Path) -> None:
    with pytest.raises(BadInput, match="no tracking database"):
        store.connect_existing(f"sqlite:///{tmp_path}/missing/mlflow.db")
    assert list(tmp_path.iterdir()) == []
    store.connect(f"sqlite:///{tmp_path}/db/mlflow.db")
    assert store.connect_existing(f"sqlite:///{tmp_path}/db/mlflow.db") is not None


def test_download_artifacts_restores_the_progress_bar_setting(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "true")
    client = store.connect(f"sqlite:///{tmp_path}/mlflow.db")
    run = client.create_run(store.ensure_experiment(client, "e"))
    (tmp_path / "a.txt").write_text("hello")
    store.log_artifacts(client, run.info.run_id, [tmp_path / "a.txt"])
    dst = tmp_path / "dst"
    dst.mkdir()
    store.download_artifacts(client, run.info.run_id, ["a.txt"], dst)
    assert (dst / "a.txt").read_text() == "hello"
    assert os.environ["MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR"] == "true"


class _FlakyClient:
    """A store that refuses ``failures`` writes (a tracking server restarting), then takes them."""

    def __init__(self, failures: int) -> None:
        self.failures = failures
        self.points: list[float] = []

    def log_batch(self, run_id: str, metrics: list) -> None:  # type: ignore[type-arg]
        if self.failures > 0:
            self.failures -= 1
            raise ConnectionError("tracking server down")
        self.points.extend(m.value for m in metrics)


def test_batch_logger_keeps_points_a_down_store_refused_and_writes_them_later() -> None:
    now = [0.0]
    client = _FlakyClient(failures=2)
    logger = store.BatchLogger(client, "r", max_buffer=2, clock=lambda: now[0], sleep=lambda s: None)
    for i in range(6):  # the first two writes fail; nothing is dropped
        logger.log({"a": float(i)}, step=i)
    assert logger.failed_writes == 2
    logger.flush()
    assert client.points == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]


def test_batch_logger_flush_retries_then_gives_up_after_retry_s() -> None:
    now = [0.0]
    slept: list[float] = []

    def sleep(s: float) -> None:
        slept.append(s)
        now[0] += s

    client = _FlakyClient(failures=10**6)
    logger = store.BatchLogger(client, "r", clock=lambda: now[0], retry_s=20.0, sleep=sleep)
    logger.log({"a": 1.0}, step=0)
    with pytest.raises(ConnectionError):
        logger.flush()
    assert slept[:4] == [1.0, 2.0, 4.0, 8.0] and sum(slept) >= 20.0
    client.failures = 0
    logger.flush()  # the point survived the failed flush
    assert client.points == [1.0]


def test_connect_leaves_no_lock_file_in_the_temp_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import tempfile

    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    store.connect(f"sqlite:///{tmp_path}/mlflow.db")
    assert list(temp.iterdir()) == []
