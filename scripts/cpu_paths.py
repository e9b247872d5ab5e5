"""Root-cause experiment for CPU-dependent results: which vectorised primitive moves a run?

Trains one (arm, seed) in this process (``vlmrl_cli.training.trace.native_returns``) and
prints where its native-return history first differs from an unperturbed run, with:

* ``--perturb exp|dot|einsum|matmul|mean``: that numpy function returns its usual result with
  about one element in three moved by one ULP (``np.nextafter``), which is the size of the
  difference between numpy's AVX-512 float64 ``exp`` and the scalar libm path used on AVX2
  CPUs, or between two BLAS kernels that sum in a different order;
* environment variables (``NPY_DISABLE_CPU_FEATURES``, ``OPENBLAS_CORETYPE``,
  ``ATEN_CPU_CAPABILITY``) set before Python starts: run it twice, once under them.

Example::

    python scripts/cpu_paths.py --arm hybrid --timesteps 100000 --perturb exp
    OPENBLAS_CORETYPE=Prescott python scripts/cpu_paths.py --arm semantic --timesteps 100000

A history equal to the reference under every perturbation means the arm does not depend on
how the CPU rounds those primitives.

What it showed (issue 12), on an AVX-512 machine (numpy dispatch X86_V3,X86_V4,AVX512_ICL;
OpenBLAS kernel SkylakeX), paper preset, seed 0, 100,000 steps, before the fix:

==============================================  =====================  =====================
forced path                                     hybrid                 semantic
==============================================  =====================  =====================
NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL"  identical              identical
OPENBLAS_CORETYPE=Haswell                       differs from ep. 234   differs from ep. 172
ATEN_CPU_CAPABILITY=avx2                        (baseline identical)
ATEN_CPU_CAPABILITY=default                     (baseline differs from ep. 128)
--perturb exp / dot / einsum                    identical              identical
==============================================  =====================  =====================

numpy's AVX-512 float64 ``exp`` differs from libm on 4.8% of inputs, but a 1-ulp change of a
float64 potential is lost when the reward becomes float32. The float32 luma product
``pixels @ weights`` of the frame features went through OpenBLAS ``sgemv``, whose SkylakeX
and Haswell kernels round differently: 3,471 feature values over all 601 grid frames changed
(up to 2.5e-6 relative), enough to move float32 rewards. After the fix (exact integer
features, a portable ``exp``, ``math.fsum``) every row above is identical for both arms.
"""

from __future__ import annotations

from vlmrl_cli.core.numeric_pin import apply as pin_numeric_path

pin_numeric_path()  # before torch and numpy load: the kernels every run of vlmrl computes with

import argparse
import functools
import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from vlmrl_cli.tasks.registry import get_task


def _perturbed(fn: Any) -> Any:
    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        out = fn(*args, **kwargs)
        arr = np.asarray(out)
        if arr.dtype.kind != "f" or arr.size == 0:
            return out
        flat = arr.reshape(-1).copy()
        idx = np.arange(flat.size)
        picked = (idx * 2654435761 + flat.size) % 3 == 0  # a fixed third of the elements
        flat[picked] = np.nextafter(flat[picked], np.inf)
        moved = flat.reshape(arr.shape)
        return moved if isinstance(out, np.ndarray) else np.float64(moved.reshape(()).item())

    return wrapper


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--arm", default="hybrid")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timesteps", type=int, default=100_000)
    parser.add_argument("--preset", default="paper")
    parser.add_argument("--perturb", choices=["exp", "dot", "einsum", "matmul", "mean"], action="append", default=[])
    parser.add_argument("--out", type=Path, help="write the history here (JSON)")
    parser.add_argument("--compare", type=Path, help="a history written by --out to compare with")
    args = parser.parse_args()

    import torch

    torch.set_num_threads(1)
    for name in args.perturb:
        setattr(np, name, _perturbed(getattr(np, name)))
    if "matmul" in args.perturb:  # the @ operator does not go through np.matmul's attribute
        print("note: --perturb matmul covers np.matmul calls only, not the @ operator", file=sys.stderr)

    import dataclasses

    from vlmrl_cli.training.config import RunConfig
    from vlmrl_cli.training.presets import preset_of
    from vlmrl_cli.training.trace import native_returns

    ppo = dataclasses.replace(preset_of(get_task("mountain-car"), args.preset), timesteps=args.timesteps)
    cfg = RunConfig(arms=(args.arm,), seeds=(args.seed,), preset=args.preset, ppo=ppo, workers=1)
    history = native_returns(cfg.jobs()[0])
    digest = hashlib.sha256(json.dumps(history).encode()).hexdigest()[:12]
    print(
        f"{args.arm} seed {args.seed}, {args.timesteps} steps, perturb={args.perturb or 'none'}: "
        f"{len(history)} episodes, history sha256 {digest}"
    )
    if args.out is not None:
        args.out.write_text(json.dumps(history))
    if args.compare is not None:
        ref = json.loads(args.compare.read_text())
        first = next((i for i, (a, b) in enumerate(zip(ref, history, strict=False)) if a != b), None)
        if first is None and len(ref) == len(history):
            print("identical to the reference")
        else:
            at = first if first is not None else min(len(ref), len(history))
            print(f"DIFFERS from the reference from episode {at} (of {len(ref)} / {len(history)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
