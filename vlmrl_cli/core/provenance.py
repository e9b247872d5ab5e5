"""Provenance recorded with every result: git commit, package versions, config hash."""

from __future__ import annotations

import dataclasses
import enum
import functools
import hashlib
import json
import platform
import subprocess
from importlib import metadata
from pathlib import Path
from typing import Any

_PACKAGES = ("vlmrl", "torch", "gymnasium", "stable-baselines3", "transformers", "mlflow",
             "numpy", "pandas", "scipy", "pygame-ce", "pygame",  # pygame draws the frames
             "mujoco")  # draws Pusher's, on Mesa (``mesa`` below)


def to_jsonable(obj: Any) -> Any:
    """Dataclasses, enums and paths as plain JSON values (for hashing and logging); a dataclass
    field that only carries a value resolved from the others (``core.fields.CARRIED``) is left out."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)
                if not f.metadata.get("carried")}
    if isinstance(obj, enum.Enum):
        return obj.value
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    return obj


def config_hash(obj: Any) -> str:
    """A short stable hash of a config object's JSON form (12 hex digits)."""
    blob = json.dumps(to_jsonable(obj), sort_keys=True).encode()
    return hashlib.sha256(blob).hexdigest()[:12]


def flatten(obj: Any, prefix: str = "") -> dict[str, str]:
    """Nested config as dotted keys -> strings (MLflow params)."""
    out: dict[str, str] = {}
    data = to_jsonable(obj)
    if isinstance(data, dict):
        for k, v in data.items():
            key = f"{prefix}.{k}" if prefix else str(k)
            if isinstance(v, dict):
                out.update(flatten(v, key))
            else:
                out[key] = json.dumps(v) if isinstance(v, (list, bool)) or v is None else str(v)
    return out


_SOURCE = Path(__file__).resolve()  # this file: git is asked about the checkout that holds it
# Outputs, not code: a run that rewrites committed results must not call its own commit dirty.
_WHOLE_TREE_BUT_OUTPUTS = (":/", ":(top,exclude)results")


def git_commit(cwd: Path | None = None) -> str:
    """The git commit of vlmrl's own source (``cwd``: the package's folder), ``-dirty`` if tracked code
    outside ``results/`` changed, or ``unknown`` where git does not track this very file."""
    where = _SOURCE.parent if cwd is None else cwd
    try:
        if cwd is None:  # raises unless this very file is tracked by the repository around it
            subprocess.run(["git", "ls-files", "--error-unmatch", _SOURCE.name], cwd=where,
                           capture_output=True, check=True, timeout=5)
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=where, capture_output=True,
                             text=True, check=True, timeout=5).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--",
                                *_WHOLE_TREE_BUT_OUTPUTS],
                               cwd=where, capture_output=True, text=True, check=True, timeout=5).stdout.strip()
        return f"{sha}-dirty" if dirty else sha
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def package_versions() -> dict[str, str]:
    """Versions of the packages a result depends on (read once per process: ~35 ms)."""
    return dict(_package_versions())


@functools.cache
def _package_versions() -> dict[str, str]:
    versions = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    versions["mesa"] = mesa_version()
    return versions


def mesa_version() -> str:
    """The installed Mesa (MuJoCo's offscreen OpenGL), from the Debian package database, or "unknown".

    Example:
        >>> isinstance(mesa_version(), str)
        True
    """
    for package in ("libgl1-mesa-dri", "libegl-mesa0", "libosmesa6"):
        try:
            found = subprocess.run(["dpkg-query", "-W", "-f=${Version}", package], capture_output=True, text=True,
                                   timeout=5, check=False)
        except (OSError, subprocess.SubprocessError):
            return "unknown"
        if found.returncode == 0 and found.stdout.strip():
            return f"{found.stdout.strip()} ({package})"
    return "unknown"


def cpu_paths() -> dict[str, str]:
    """The CPU code paths this process computes with: ``numpy_simd`` (numpy's active dispatch targets,
    e.g. ``X86_V3,X86_V4,AVX512_ICL``), ``blas`` (library and kernel, e.g. ``openblas SkylakeX``) and
    ``torch`` (ATen's CPU capability)."""
    paths: dict[str, str] = {}
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

        paths["numpy_simd"] = ",".join(t for t in __cpu_dispatch__ if __cpu_features__.get(t)) or "baseline"
    except ImportError:  # another numpy layout: say so rather than guess
        paths["numpy_simd"] = "unknown"
    try:
        from threadpoolctl import threadpool_info

        blas = [i for i in threadpool_info() if i.get("user_api") == "blas"]
        # each kernel once: scipy, once imported, loads a second copy of the same OpenBLAS
        kernels = dict.fromkeys(f"{i.get('internal_api')} {i.get('architecture', '?')}" for i in blas)
        paths["blas"] = ";".join(kernels) or "none loaded"
    except ImportError:
        paths["blas"] = "unknown"
    try:
        import torch

        paths["torch"] = str(torch.backends.cpu.get_cpu_capability())
    except ImportError:
        paths["torch"] = "not installed"
    return paths
