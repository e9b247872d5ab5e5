"""Where the numeric pin's cost comes from: torch's matrix products at PPO's shapes, pinned vs not.

PPO's policy and value networks here are two-layer MLPs of width 64 (preset paper: 16 envs,
minibatches of 64), so nearly all of the pin's cost (core.numeric_pin, ``MKL_CBWR=COMPATIBLE``:
MKL's SSE2 branch) is in ``addmm``/``mm`` calls of these shapes. Each mode runs in a fresh
process (the libraries read the variables once, at load), one thread, alternating twice:
``pinned, unpinned, unpinned, pinned``. Prints the microseconds of one call per shape and mode,
and the pinned/unpinned ratio of each shape's mean. `benchmarks/bench_training.py --parts 4`
measures what that costs a whole run.

Usage: python benchmarks/bench_pin_gemm.py [--reps 20000]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys

# (name, m, k, n): out = bias + (m x k) @ (k x n)
SHAPES = (
    ("rollout, first layer (16 envs, 2 -> 64)", 16, 2, 64),
    ("rollout, hidden layer (16 x 64 -> 64)", 16, 64, 64),
    ("rollout, action head (16 x 64 -> 3)", 16, 64, 3),
    ("minibatch, hidden layer (64 x 64 -> 64)", 64, 64, 64),
    ("minibatch, first layer (64 x 2 -> 64)", 64, 2, 64),
)

_PROBE = """
import os, sys, time
if os.environ.get("BENCH_PIN") == "1":
    from vlmrl_cli.core.numeric_pin import apply
    apply(warn=False)
import torch
torch.set_num_threads(1)
reps = int(sys.argv[1])
g = torch.Generator().manual_seed(0)
for m, k, n in [tuple(int(x) for x in s.split("x")) for s in sys.argv[2:]]:
    a, b, c = torch.randn(m, k, generator=g), torch.randn(k, n, generator=g), torch.randn(n, generator=g)
    for _ in range(reps // 10):
        torch.addmm(c, a, b)
    start = time.perf_counter()
    for _ in range(reps):
        torch.addmm(c, a, b)
    print((time.perf_counter() - start) / reps * 1e6, torch.backends.cpu.get_cpu_capability())
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--reps", type=int, default=20_000, help="timed calls per shape and process")
    opts = parser.parse_args()
    from vlmrl_cli.core.numeric_pin import unpinned_environ

    clean = unpinned_environ(os.environ) | {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    shapes = [f"{m}x{k}x{n}" for _, m, k, n in SHAPES]
    times: dict[str, list[list[float]]] = {"pinned": [], "unpinned": []}
    capability = {}
    for which in ("pinned", "unpinned", "unpinned", "pinned"):
        env = clean | {"BENCH_PIN": "1" if which == "pinned" else "0"}
        out = subprocess.run([sys.executable, "-c", _PROBE, str(opts.reps), *shapes], env=env, check=True,
                             capture_output=True, text=True).stdout.split("\n")
        rows = [line.split() for line in out if line.strip()]
        times[which].append([float(r[0]) for r in rows])
        capability[which] = rows[0][1]
    print(f"torch.addmm, one thread, {opts.reps:,} calls per shape, 2 fresh processes per mode "
          f"(torch capability: pinned {capability['pinned']}, unpinned {capability['unpinned']})")
    print(f"  {'shape':<42} {'pinned us':>10} {'unpinned us':>12} {'ratio':>6}")
    for i, (name, *_) in enumerate(SHAPES):
        pinned = statistics.fmean(t[i] for t in times["pinned"])
        unpinned = statistics.fmean(t[i] for t in times["unpinned"])
        print(f"  {name:<42} {pinned:>10.2f} {unpinned:>12.2f} {pinned / unpinned:>6.2f}")


if __name__ == "__main__":
    main()
