"""Whether this process can use a tracking store, found without MLflow and in well under a second:
commands check before they print anything or create any file, and ``store.connect`` before it
connects."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from tenacity import Retrying, retry_if_exception_type, stop_after_delay, wait_fixed

from vlmrl_cli.core.errors import BadInput

DEFAULT_TRACKING_URI = "sqlite:///mlflow.db"


def resolve_tracking_uri(uri: str | None) -> str:
    """``uri`` if given, else ``MLFLOW_TRACKING_URI``, else MLflow's sqlite default."""
    return uri or os.environ.get("MLFLOW_TRACKING_URI") or DEFAULT_TRACKING_URI


#: The URI schemes MLflow's own tracking stores take (``mlflow.tracking._tracking_service.utils``);
#: a plug-in adds its own through the ``mlflow.tracking_store`` entry point group.
MLFLOW_SCHEMES = ("", "file", "databricks", "databricks-uc", "uc", "http", "https", "sqlite", "postgresql",
                  "mysql", "mssql")


def _scheme(uri: str) -> str:
    """The store scheme of ``uri`` as MLflow reads it: ``postgresql+psycopg2`` is ``postgresql``,
    a Windows drive letter is a path.

    Example:
        >>> _scheme("sqlite:///m.db"), _scheme("postgresql+psycopg2://h/db"), _scheme("mlruns"), _scheme("nope://x")
        ('sqlite', 'postgresql', '', 'nope')
    """
    import urllib.parse

    scheme = urllib.parse.urlparse(uri).scheme.lower()
    if len(scheme) == 1:
        return ""
    return scheme.split("+", 1)[0]


def _unreachable(uri: str, why: str) -> str:
    return f"the MLflow tracking store '{uri}' cannot be reached: {why}"


def _sqlite_problem(uri: str, write: bool, existing: bool) -> str | None:
    """Why this process cannot use the sqlite database of ``uri`` (read, or read and write), or
    None; ``existing``: a missing database is refused rather than created. Read from the file
    system alone (a folder is probed with an anonymous temporary file, which leaves nothing; a
    database is opened read-only): a store in memory or named with a query, and a file that is no
    MLflow store, are refused before MLflow could add its tables to them."""
    if not uri.startswith("sqlite:///") or uri.removeprefix("sqlite:///") in ("", ":memory:"):
        return _unreachable(uri, "an in-memory sqlite store keeps nothing and each worker would open its own; "
                                 "pass --tracking-uri sqlite:///PATH/mlflow.db")
    if "?" in uri:
        return _unreachable(uri, "a sqlite tracking URI takes a file path and no query (?...), which MLflow would "
                                 "ignore; pass --tracking-uri sqlite:///PATH/mlflow.db")
    db_path = Path(uri.removeprefix("sqlite:///"))
    if str(db_path) == ".":
        return _unreachable(uri, "no database file is named; pass --tracking-uri sqlite:///PATH/mlflow.db")
    if existing and not db_path.is_file():
        return f"there is no tracking database at {db_path}; pass the --tracking-uri the runs were made with"
    if db_path.exists():
        if not db_path.is_file():
            return _unreachable(uri, f"{db_path} is not a file; pass --tracking-uri sqlite:///PATH/mlflow.db")
        try:
            with open(db_path, "r+b" if write else "rb"):
                pass
        except OSError as exc:
            return _unreachable(uri, f"{db_path} cannot be {'written' if write else 'read'} here ({exc.strerror})")
        foreign = _foreign_database(db_path)
        if foreign:
            return _unreachable(uri, f"{db_path} {foreign}; MLflow would add its tables to it. Pass --tracking-uri "
                                     "sqlite:///PATH/mlflow.db of an MLflow store, or a new file")
    if not write:
        return None
    folder = db_path.absolute().parent
    while not folder.exists():  # connect creates the missing folders under the nearest existing one
        folder = folder.parent
    if not folder.is_dir():
        return _unreachable(uri, f"{folder} is a file, not a folder; pass --tracking-uri sqlite:///PATH/mlflow.db")
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        return _unreachable(uri, f"no file can be written in {folder} ({exc.strerror}); pass --tracking-uri "
                                 "sqlite:///PATH/mlflow.db in a folder you can write")
    return None


def _foreign_database(db_path: Path) -> str | None:
    """Why the existing file ``db_path`` is no MLflow sqlite store, or None (an MLflow store, or an
    empty file, which MLflow makes one): read through a read-only connection, which writes nothing."""
    import sqlite3

    if db_path.stat().st_size == 0:
        return None
    try:
        with contextlib.closing(sqlite3.connect(f"{db_path.absolute().as_uri()}?mode=ro", uri=True)) as con:
            tables = {row[0] for row in con.execute("select name from sqlite_master where type = 'table'")}
    except sqlite3.Error as exc:
        return f"is not a sqlite database ({exc})"
    if tables and not {"alembic_version", "experiments", "runs"} <= tables:
        return f"is a sqlite database of another program ({len(tables)} table(s), none of MLflow's)"
    return None


#: The database drivers SQLAlchemy loads by default for MLflow's database stores (a ``+driver`` in
#: the scheme names another), with what to install.
DB_DRIVERS = {"postgresql": ("psycopg2", "psycopg2-binary"), "mysql": ("MySQLdb", "mysqlclient"),
              "mssql": ("pyodbc", "pyodbc")}


def _driver_problem(uri: str) -> str | None:
    """Why the database store of ``uri`` cannot be opened for want of its driver, or None: MLflow
    would print its header and then fail on the import after seconds.

    Example:
        >>> _driver_problem("postgresql+nosuchdriver://h/db").split(": ", 1)[1]
        'no Python module nosuchdriver for its database driver; install it (pip install nosuchdriver)'
    """
    import importlib.util
    import urllib.parse

    scheme = urllib.parse.urlparse(uri).scheme.lower()
    base, _, driver = scheme.partition("+")
    if base not in DB_DRIVERS:
        return None
    module, package = (driver, driver) if driver else DB_DRIVERS[base]
    if importlib.util.find_spec(module) is None:
        return _unreachable(uri, f"no Python module {module} for its database driver; install it (pip install "
                                 f"{package})")
    return None


def store_problem(uri: str | None, write: bool = True, existing: bool = False) -> str | None:
    """Why the tracking store of ``uri`` (resolved by ``resolve_tracking_uri``) cannot be used,
    or None, found without MLflow: a scheme no MLflow store takes, or a sqlite database that
    this process cannot read (``write`` False) or write, or that is missing (``existing``).
    A server's URI is not contacted here (``check_store`` does).

    Example:
        >>> store_problem("nope://x").endswith("MLflow has no store for the scheme 'nope' (a typo?); pass "
        ...     "sqlite:///PATH/mlflow.db or http://HOST:PORT")
        True
        >>> "cannot be reached: no file can be written in /proc" in store_problem("sqlite:////proc/vlmrl.db")
        True
    """
    import importlib.metadata

    resolved = resolve_tracking_uri(uri)
    scheme = _scheme(resolved)
    plugins = {ep.name for ep in importlib.metadata.entry_points(group="mlflow.tracking_store")}
    if scheme not in MLFLOW_SCHEMES and scheme not in plugins:
        return _unreachable(resolved, f"MLflow has no store for the scheme '{scheme}' (a typo?); pass "
                                      "sqlite:///PATH/mlflow.db or http://HOST:PORT")
    if scheme == "sqlite":
        return _sqlite_problem(resolved, write, existing)
    return _driver_problem(resolved)


def check_store(uri: str | None, write: bool = True, existing: bool = False, wait_s: float = 0.0) -> None:
    """``BadInput`` for a tracking store a command cannot use (``store_problem``; a server that
    does not answer after ``wait_s`` seconds), before MLflow is imported (MLflow itself retries a
    sqlite file it cannot open for over a minute, with some 40 lines of warnings)."""
    problem = store_problem(uri, write, existing)
    if problem:
        raise BadInput(problem + ".")
    resolved = resolve_tracking_uri(uri)
    if resolved.startswith(("http://", "https://")):
        _check_server(resolved, wait_s)


def _check_server(uri: str, wait_s: float = 0.0) -> None:
    """Fail fast on a tracking server that does not answer (MLflow's own client retries for
    minutes before giving up), after retrying for ``wait_s`` seconds."""
    import httpx

    retrying = Retrying(stop=stop_after_delay(wait_s), wait=wait_fixed(1.0),
                        retry=retry_if_exception_type(httpx.HTTPError), reraise=True)
    try:
        for attempt in retrying:
            with attempt:
                httpx.get(uri.rstrip("/") + "/health", timeout=5.0)
    except httpx.HTTPError as exc:
        raise BadInput(f"the MLflow tracking server '{uri}' cannot be reached; check --tracking-uri.") from exc
