"""MLflow connection, provenance tags and batched logging, all through an explicit ``MlflowClient``
(no global active run). The sqlite set-up lock and schema template: see docs/development.md."""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import filelock
from tenacity import Retrying, wait_exponential

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.core.numeric_pin import pin_record
from vlmrl_cli.core.provenance import cpu_paths, git_commit, package_versions
from vlmrl_cli.tracking import schema
from vlmrl_cli.tracking.access import check_store, resolve_tracking_uri

#: How long ``connect`` waits for another process to finish setting up the same sqlite store.
INIT_LOCK_TIMEOUT_S = 120.0


def connect(uri: str | None, wait_s: float = 0.0, write: bool = True, existing: bool = False) -> Any:
    """An ``MlflowClient`` for ``uri``, checked first as ``access.check_store`` does, then to answer."""
    import logging

    resolved = resolve_tracking_uri(uri)
    check_store(resolved, write, existing, wait_s)
    from mlflow.tracking import MlflowClient

    logging.getLogger("alembic").setLevel(logging.WARNING)
    logging.getLogger("mlflow").setLevel(logging.WARNING)
    lock: contextlib.AbstractContextManager[object] = contextlib.nullcontext()
    db_path: Path | None = None
    if resolved.startswith("sqlite:///"):
        db_path = Path(resolved.removeprefix("sqlite:///"))
        if not db_path.parent.exists():
            try:
                db_path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise BadInput(f"cannot create the folder of the tracking database {db_path}.") from exc
        lock = init_lock(db_path)
        # MLflow's sqlite store module takes ~1 s to import; import it before taking the lock,
        # so that a sweep's workers wait ~0.1 s for each other, not ~1 s
        import mlflow.store.tracking.sqlalchemy_store  # noqa: F401
    try:
        with lock:
            if db_path is not None and not db_path.exists():
                _start_from_template(db_path)
            client = MlflowClient(tracking_uri=resolved)
            client.search_experiments(max_results=1)
    except filelock.Timeout as exc:
        raise BadInput(f"another process has been setting up the MLflow store '{resolved}' for over "
                       f"{INIT_LOCK_TIMEOUT_S:.0f} s; try again when it has finished.") from exc
    except Exception as exc:  # MLflow raises many types for a bad store
        raise BadInput(f"the MLflow tracking store '{resolved}' cannot be reached; pass --tracking-uri "
                       "sqlite:///PATH/mlflow.db or start the server.") from exc
    finally:
        _remove_lock_file(lock)
    return client


def _start_from_template(db_path: Path) -> None:
    """Put a copy of ``schema_template()`` at the new ``db_path`` whole (a copy, then a hard link);
    where there is no template, or a file appeared meanwhile, MLflow opens or creates it itself."""
    template = schema_template()
    if template is None:
        return
    part = db_path.with_name(f".{db_path.name}.{os.getpid()}.part")
    try:
        shutil.copyfile(template, part)
        os.link(part, db_path)  # refuses to replace a file that appeared meanwhile
    except OSError:
        pass
    finally:
        part.unlink(missing_ok=True)


def schema_template() -> Path | None:
    """An empty sqlite store of this MLflow version's schema in the user's cache folder, built once
    (rebuilt if at another revision); None where it cannot be written (MLflow then builds each schema)."""
    import mlflow
    import platformdirs
    import sqlalchemy
    from mlflow.store.db.utils import _get_latest_schema_revision, _initialize_tables

    head = _get_latest_schema_revision()
    folder = platformdirs.user_cache_path("vlmrl")
    path = folder / f"mlflow-{mlflow.__version__}-schema.db"
    if _schema_revision(path) == head:
        return path
    lock = init_lock(path)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with lock:
            if _schema_revision(path) != head:  # MLflow's own schema creation, beside it, then renamed
                part = path.with_name(f"{path.name}.{os.getpid()}.part")
                part.unlink(missing_ok=True)
                engine = sqlalchemy.create_engine(f"sqlite:///{part}")
                try:
                    _initialize_tables(engine)
                except Exception as exc:  # an MLflow without this helper, or a failed migration: no template
                    raise OSError(f"cannot build MLflow's schema: {exc}") from exc
                finally:
                    engine.dispose()
                try:
                    os.replace(part, path)
                finally:
                    part.unlink(missing_ok=True)
    except (OSError, filelock.Timeout):
        return None
    finally:
        _remove_lock_file(lock)
    return path if _schema_revision(path) == head else None


def _schema_revision(path: Path) -> str | None:
    """The alembic revision of the sqlite file ``path`` (None: missing, or not an MLflow store)."""
    import sqlite3

    if not path.is_file():
        return None
    try:
        with contextlib.closing(sqlite3.connect(f"{path.as_uri()}?mode=ro", uri=True)) as con:
            row = con.execute("select version_num from alembic_version").fetchone()
    except sqlite3.Error:
        return None
    return None if row is None else str(row[0])


def _remove_lock_file(lock: object) -> None:
    """Delete the released lock file so that none is left in the temp folder (safe: a process that
    opens it afterwards makes a new one, and finds the schema complete)."""
    if isinstance(lock, filelock.BaseFileLock) and not lock.is_locked:
        with contextlib.suppress(OSError):
            os.unlink(lock.lock_file)


def connect_existing(uri: str | None) -> Any:
    """``connect`` for commands that read runs: a missing sqlite database is ``BadInput``, not created."""
    return connect(uri, write=False, existing=True)


def init_lock(db_path: Path) -> filelock.FileLock:
    """The inter-process lock (in the temp folder, keyed by the absolute path) every vlmrl process
    takes to connect to a sqlite database: MLflow migrates a fresh schema unlocked, and two at once
    can leave it half-migrated for good (MLflow 3.17; daizutabi/hydraflow#245)."""
    key = hashlib.sha256(str(db_path.resolve()).encode()).hexdigest()[:16]
    return filelock.FileLock(Path(tempfile.gettempdir()) / f"vlmrl-mlflow-{key}.lock", timeout=INIT_LOCK_TIMEOUT_S)


def ensure_experiment(client: Any, name: str) -> str:
    """The id of experiment ``name``, created if missing (artifacts in ``mlartifacts/`` beside a sqlite
    database), and restored if deleted."""
    from mlflow.exceptions import MlflowException

    exp = client.get_experiment_by_name(name)
    if exp is None:
        uri = client.tracking_uri
        root = (Path(uri.removeprefix("sqlite:///")).resolve().parent / "mlartifacts").as_uri() \
            if uri.startswith("sqlite:///") else None
        try:
            return str(client.create_experiment(name, artifact_location=root))
        except MlflowException:
            # another process (a second sweep started at the same moment) created it first
            exp = client.get_experiment_by_name(name)
            if exp is None:
                raise
    if exp.lifecycle_stage == "deleted":
        client.restore_experiment(exp.experiment_id)
    return str(exp.experiment_id)


def provenance_tags(vlm_label: str, simulated: bool) -> dict[str, str]:
    """Tags every vlmrl run carries: VLM (simulated said plainly), commit, versions, CPU paths, numeric pin."""
    commit = git_commit()
    tags = {schema.TAG_VLM: vlm_label, schema.TAG_SIMULATED: "true" if simulated else "false",
            schema.TAG_GIT_COMMIT: commit, schema.MLFLOW_GIT_COMMIT: commit,
            **{f"{schema.TAG_VERSION_PREFIX}{name}": v for name, v in package_versions().items()},
            **{f"{schema.TAG_CPU_PREFIX}{name}": path for name, path in cpu_paths().items()},
            **{f"{schema.TAG_PREFIX}{name}": v for name, v in pin_record().items()}}  # the pin and the CPU model
    if simulated:
        tags[schema.TAG_NOTE] = ("Produced with the SIMULATED VLM (a pixel-reading stand-in), not a real "
                                 "vision-language model.")
    return tags


class BatchLogger:
    """Buffers metrics for ``log_batch`` (a point alone costs ~4 ms in sqlite, 1000 about the same),
    written at ``max_buffer`` points or ``max_age_s`` seconds. A failed write keeps the buffer for the
    next; ``flush`` retries for ``retry_s`` seconds, then raises. Each ``log`` call gets its own
    strictly increasing ms timestamp: MLflow keeps one row per (key, value, step, timestamp), so two
    identical episodes at one step would otherwise collapse."""

    def __init__(self, client: Any, run_id: str, max_buffer: int = 900, max_age_s: float = 5.0,
                 clock: Callable[[], float] = time.monotonic, retry_s: float = 300.0,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        if max_age_s < 0:
            raise ValueError(f"max_age_s must be >= 0, got {max_age_s}")
        self._client = client
        self._run_id = run_id
        self._max = max_buffer
        self._max_age = max_age_s
        self._clock = clock
        self._buffer: list[Any] = []
        self._last_ts = 0
        self._last_flush = clock()
        self._retry_s = retry_s
        self._sleep = sleep
        self.failed_writes = 0

    def log(self, metrics: Mapping[str, float], step: int) -> None:
        from mlflow.entities import Metric

        ts = max(int(time.time() * 1000), self._last_ts + 1)
        self._last_ts = ts
        self._buffer.extend(Metric(k, float(v), ts, int(step)) for k, v in metrics.items())
        if len(self._buffer) >= self._max or self._clock() - self._last_flush >= self._max_age:
            try:
                self._write()
            except Exception:  # kept in the buffer; the next write tries again
                self.failed_writes += 1
                self._last_flush = self._clock()

    def flush(self) -> None:
        """Write everything buffered, retrying a failing store for ``retry_s`` seconds."""
        deadline = self._clock() + self._retry_s
        retrying = Retrying(stop=lambda state: self._clock() >= deadline, wait=wait_exponential(max=30.0),
                            sleep=self._sleep, reraise=True)
        for attempt in retrying:
            with attempt:
                try:
                    self._write()
                except Exception:
                    self.failed_writes += 1
                    raise

    def _write(self) -> None:
        while self._buffer:
            self._client.log_batch(self._run_id, metrics=self._buffer[:1000])
            del self._buffer[:1000]  # only once the store took them
        self._last_flush = self._clock()


def log_params(client: Any, run_id: str, params: Mapping[str, str]) -> None:
    """Log params in batches of 100 (MLflow's limit), values cut to MLflow's 6000 chars."""
    from mlflow.entities import Param

    items = [Param(k, str(v)[:6000]) for k, v in params.items()]
    for i in range(0, len(items), 100):
        client.log_batch(run_id, params=items[i : i + 100])


def set_tags(client: Any, run_id: str, tags: Mapping[str, str]) -> None:
    from mlflow.entities import RunTag

    client.log_batch(run_id, tags=[RunTag(k, str(v)) for k, v in tags.items()])


def log_artifacts(client: Any, run_id: str, paths: Iterable[Path], artifact_path: str | None = None) -> None:
    for path in paths:
        if path.is_dir():
            client.log_artifacts(run_id, str(path), artifact_path)
        elif path.exists():
            client.log_artifact(run_id, str(path), artifact_path)


def download_artifacts(client: Any, run_id: str, names: Iterable[str], dst: Path) -> None:
    """Download the run's artifacts ``names`` into the existing folder ``dst``, without progress bars."""
    from unittest import mock

    from mlflow.environment_variables import MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR

    with mock.patch.dict(os.environ, {MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR.name: "false"}):
        for name in names:
            client.download_artifacts(run_id, name, str(dst))
