"""nox sessions: tests, lint, bench, repro. Every session installs the CPU build of torch
first (a plain `torch` requirement can pull a multi-GB CUDA build)."""

from __future__ import annotations

import os
import time

import nox

nox.options.sessions = ["lint", "tests"]
nox.options.reuse_existing_virtualenvs = True
nox.options.default_venv_backend = "venv"

TORCH = os.environ.get("VLMRL_TORCH", "torch==2.13.0")


def _install(session: nox.Session, extras: str = "dev") -> None:
    session.install(TORCH)
    session.install("-e", f".[{extras}]")


@nox.session
def tests(session: nox.Session) -> None:
    """The test suite (what CI runs)."""
    _install(session)
    session.run("pytest", "-n", "2", "--dist", "loadfile", *session.posargs,
                env={"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"})


@nox.session
def lint(session: nox.Session) -> None:
    """ruff and mypy."""
    _install(session)
    session.run("ruff", "check", "vlmrl_cli", "tests", "noxfile.py", "benchmarks")
    session.run("mypy", "vlmrl_cli")


@nox.session
def bench(session: nox.Session) -> None:
    """Performance figures of the hybrid arm (prints measurements; not a test)."""
    _install(session)
    session.run("python", "benchmarks/bench_training.py", *session.posargs)


@nox.session
def repro(session: nox.Session) -> None:
    """Everything end to end on the embedded default (simulated VLM): taxonomy, the paper's
    four arms x 5 seeds with the `paper` preset, the report, into results/."""
    _install(session)
    start = time.perf_counter()
    session.run("python", "scripts/repro.py", *session.posargs)
    session.log(f"nox -s repro wall time: {time.perf_counter() - start:.0f} s")
