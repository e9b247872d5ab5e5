"""Whether this process can use a tracking store, found without MLflow in well under a second,
before a command prints anything or creates any file."""

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


#: The URI schemes of MLflow's own tracking stores (plug-ins add theirs as ``mlflow.tracking_store`` entry points).
MLFLOW_SCHEMES = ("", "file", "databricks", "databricks-uc", "uc", "http", "https", "sqlite", "postgresql",
                  "mysql", "mssql")


def _scheme(uri: str) -> str:
    """The store scheme of ``uri`` as MLflow reads it (a one-letter scheme is a Windows drive).

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
    """Why this process cannot read (or, with ``write``, write) the sqlite database of ``uri``, or
    None; ``existing``: a missing database is refused. Nothing is written (a folder is probed with
    an anonymous temporary file); a store in memory or with a query, or a foreign database, is refused."""
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
    """Why the existing file ``db_path`` is no MLflow sqlite store (an empty file is one), or None."""
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


#: The driver module SQLAlchemy loads by default for each database scheme, and its pip package.
DB_DRIVERS = {"postgresql": ("psycopg2", "psycopg2-binary"), "mysql": ("MySQLdb", "mysqlclient"),
              "mssql": ("pyodbc", "pyodbc")}


def _driver_problem(uri: str) -> str | None:
    """Why the database store of ``uri`` lacks its driver, or None (MLflow would fail after seconds)."""
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
    """Why the tracking store of ``uri`` cannot be used, or None: an unknown scheme, a missing
    driver, or a sqlite database this process cannot use (``_sqlite_problem``). No server is contacted."""
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
    """``BadInput`` for a tracking store a command cannot use (``store_problem``), or a server that
    does not answer within ``wait_s`` seconds, before MLflow is imported (MLflow retries for minutes)."""
    problem = store_problem(uri, write, existing)
    if problem:
        raise BadInput(problem + ".")
    resolved = resolve_tracking_uri(uri)
    if not resolved.startswith(("http://", "https://")):
        return
    import httpx

    retrying = Retrying(stop=stop_after_delay(wait_s), wait=wait_fixed(1.0),
                        retry=retry_if_exception_type(httpx.HTTPError), reraise=True)
    try:
        for attempt in retrying:
            with attempt:
                httpx.get(resolved.rstrip("/") + "/health", timeout=5.0)
    except httpx.HTTPError as exc:
        raise BadInput(f"the MLflow tracking server '{resolved}' cannot be reached; check --tracking-uri.") from exc
