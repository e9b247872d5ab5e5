"""nox sessions: tests, lint, bench, repro, study. Every session installs the CPU build of torch
first (a plain `torch` requirement can pull a multi-GB CUDA build)."""

from __future__ import annotations

import os
import tempfile
import time

import nox

nox.options.sessions = ["tests"]
nox.options.reuse_existing_virtualenvs = True
nox.options.default_venv_backend = "venv"

TORCH = os.environ.get("VLMRL_TORCH", "torch==2.13.0")


def _install(session: nox.Session, extras: str = "dev") -> None:
    session.install(TORCH)
    session.install("-e", f".[{extras}]")


def _lint(session: nox.Session) -> None:
    session.run("ruff", "check", "vlmrl_cli", "tests", "noxfile.py", "benchmarks", "scripts", "docs/hooks.py")
    session.run("mypy", "vlmrl_cli", "tests", "benchmarks", "scripts", "docs/hooks.py")


def _docs(session: nox.Session) -> None:
    # tempfile, not session.create_tmp(): that also points TMPDIR into .nox/ (inside the checkout) for
    # every later command, which puts pytest's temporary folders inside a git repository and Ray's
    # socket paths past the length a Unix socket allows
    with tempfile.TemporaryDirectory(prefix="vlmrl-site-") as site:
        session.run("mkdocs", "build", "--strict", "--site-dir", site)


@nox.session
def tests(session: nox.Session) -> None:
    """ruff, mypy, the docs site (mkdocs --strict), then the test suite, in one environment (what CI
    runs), with the Ray extra."""
    _install(session, "dev,ray")
    _lint(session)
    _docs(session)
    # whole files per worker, in tests/conftest.py's order (the files with the most slow tests first);
    # xdist's own reordering (by number of tests) would start the few long files last
    session.run("pytest", "-n", "2", "--dist", "loadfile", "--no-loadscope-reorder", *session.posargs,
                env={"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"})


@nox.session
def docs(session: nox.Session) -> None:
    """Build the documentation site (mkdocs --strict) into site/."""
    _install(session)
    session.run("mkdocs", "build", "--strict")


@nox.session
def lint(session: nox.Session) -> None:
    """ruff and mypy only."""
    _install(session, "dev,ray")
    _lint(session)


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


@nox.session
def study(session: nox.Session) -> None:
    """`vlmrl study` with its defaults (regime paper-unreliable; baseline, hybrid, its placebo
    hybrid-shuffled, kinematic and semantic x 20 seeds; the alpha x kin_scale dose-response with its
    placebo cells; hybrid vs hybrid-no-lock under per-query flicker) into results/study/; MLflow in
    results/_scratch/ (git-ignored). Resumable: rerun after an interruption. Extra arguments go to
    `vlmrl study` (e.g. `nox -s study -- --seeds 3`)."""
    _install(session)
    scratch = os.path.join("results", "_scratch")
    os.makedirs(scratch, exist_ok=True)
    start = time.perf_counter()
    session.run("vlmrl", "study", "--out", os.path.join("results", "study"), "--tracking-uri",
                f"sqlite:///{os.path.abspath(os.path.join(scratch, 'mlflow.db'))}", *session.posargs)
    session.log(f"nox -s study wall time: {time.perf_counter() - start:.0f} s")
