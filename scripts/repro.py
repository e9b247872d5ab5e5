"""End-to-end reproduction on the embedded default (the SIMULATED VLM), driven by `nox -s repro`.

Stages (each a real `vlmrl` command, resumable through the MLflow store):
  1. vlmrl taxonomy  -> results/taxonomy/
  2. vlmrl run       -> baseline, hybrid, kinematic, semantic x 5 seeds, preset `paper`
  3. vlmrl report    -> results/report/
  4. vlmrl export    -> results/report/runs.jsonl.gz (what `vlmrl verify` retrains)
and a manifest (results/manifest.json) with versions, commands, commit and wall times of every
invocation (a rerun resumes: finished training runs are not redone).
The MLflow database stays in results/_scratch/ (git-ignored), never committed.

Usage: python scripts/repro.py [--seeds N] [--arms a,b] [--timesteps T] [--workers W]
"""

from __future__ import annotations

from vlmrl_cli.core.numeric_pin import apply as pin_numeric_path

pin_numeric_path()  # before torch and numpy load: the kernels every run of vlmrl computes with

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

from vlmrl_cli.core.numeric_pin import pin_record
from vlmrl_cli.core.provenance import cpu_paths, git_commit, package_versions

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results"
SCRATCH = RESULTS / "_scratch"
EXPERIMENT = "vlmrl-repro"


def stage(name: str, args: list[str], log: list[dict[str, object]]) -> None:
    command = [sys.executable, "-m", "vlmrl_cli", *args]
    shown = "vlmrl " + " ".join(args)
    print(f"\n=== {name}: {shown}", flush=True)
    start = time.perf_counter()
    rc = subprocess.call(command, cwd=ROOT)
    wall = time.perf_counter() - start
    log.append({"stage": name, "command": shown, "exit_code": rc, "wall_s": round(wall, 1)})
    print(f"=== {name}: exit {rc} after {wall:.0f} s", flush=True)
    if rc != 0:
        raise SystemExit(f"repro stopped: stage '{name}' exited {rc}; rerun to resume.")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--arms", default="baseline,hybrid,kinematic,semantic")
    parser.add_argument("--preset", default="paper")
    parser.add_argument("--timesteps", type=int, default=None)
    parser.add_argument("--workers", type=int, default=None)
    opts = parser.parse_args()

    # Read before any stage writes: the commit that produced these results.
    commit = git_commit(ROOT)
    SCRATCH.mkdir(parents=True, exist_ok=True)
    uri = f"sqlite:///{SCRATCH / 'mlflow.db'}"
    start = time.perf_counter()
    log: list[dict[str, object]] = []
    stage("taxonomy", ["taxonomy", "--vlm", "sim", "--out", "results/taxonomy", "--tracking-uri", uri], log)
    run_args = ["run", "--arms", opts.arms, "--seeds", str(opts.seeds), "--preset", opts.preset,
                "--experiment", EXPERIMENT, "--tracking-uri", uri]
    if opts.timesteps is not None:
        run_args += ["--timesteps", str(opts.timesteps)]
    if opts.workers is not None:
        run_args += ["--workers", str(opts.workers)]
    stage("run", run_args, log)
    stage("report", ["report", "--experiment", EXPERIMENT, "--tracking-uri", uri, "--out", "results/report"], log)
    # the runs themselves, committed beside the report: `vlmrl verify results/report/runs.jsonl.gz`
    stage("export", ["export", "--experiment", EXPERIMENT, "--tracking-uri", uri, "--out",
                     "results/report/runs.jsonl.gz"], log)
    wall = time.perf_counter() - start

    invocation = {
        "commit": commit,
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "machine": {"platform": platform.platform(), "processor": platform.machine(), "cpus": os.cpu_count(),
                    "cpu_paths": cpu_paths(), "numeric_pin": pin_record()},
        "versions": package_versions(),
        "stages": log,
        "wall_s": round(wall, 1),
    }
    # A rerun resumes from MLflow (finished runs are not retrained), so earlier invocations stay
    # in the manifest: the one that trained keeps its wall time and commit.
    path = RESULTS / "manifest.json"
    previous: list[dict[str, object]] = []
    if path.exists():
        old = json.loads(path.read_text())
        previous = old.get("invocations", [old]) if isinstance(old, dict) else []
    manifest = {
        "what": "nox -s repro on the embedded default VLM backend: the SIMULATED VLM, not a real model",
        "mlflow": f"{uri} (not committed), experiment '{EXPERIMENT}'",
        "invocations": [*previous, invocation],
    }
    path.write_text(json.dumps(manifest, indent=2) + "\n")
    print(f"\nrepro finished in {wall:.0f} s ({wall / 60:.1f} min); manifest: results/manifest.json")


if __name__ == "__main__":
    main()
