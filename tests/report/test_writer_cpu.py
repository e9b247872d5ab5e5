from __future__ import annotations

import pandas as pd

from vlmrl_cli.analysis.load import RUN_COLUMNS, ExperimentData
from vlmrl_cli.report.writer import _cpu_warnings


def _data(blas: list[str], torch: list[str]) -> ExperimentData:
    rows = [{c: None for c in RUN_COLUMNS} | {"arm": "hybrid", "seed": i, "cpu_numpy_simd": "X86_V3",
                                              "cpu_blas": b, "cpu_torch": t}
            for i, (b, t) in enumerate(zip(blas, torch, strict=True))]
    return ExperimentData("1", "e", pd.DataFrame(rows, columns=RUN_COLUMNS), pd.DataFrame(), pd.DataFrame())


def test_runs_from_one_cpu_path_raise_no_warning() -> None:
    assert _cpu_warnings(_data(["openblas Haswell"] * 3, ["AVX2"] * 3)) == []


def test_each_differing_cpu_path_gets_one_warning_naming_its_values() -> None:
    warns = _cpu_warnings(_data(["openblas Haswell", "openblas SkylakeX"], ["AVX2", "AVX512"]))
    assert len(warns) == 2
    assert "BLAS kernel" in warns[0] and "openblas Haswell; openblas SkylakeX" in warns[0]
    assert "torch" in warns[1] and "baseline included" in warns[1]


def test_the_cpu_tags_of_a_run_become_its_cpu_columns() -> None:
    from types import SimpleNamespace

    from vlmrl_cli.analysis.load import _run_row

    tags = {"vlmrl.cpu.numpy_simd": "AVX2", "vlmrl.cpu.blas": "openblas Haswell", "vlmrl.arm": "baseline"}
    run = SimpleNamespace(info=SimpleNamespace(run_id="r", end_time=0),
                          data=SimpleNamespace(tags=tags, params={}, metrics={}))
    row = _run_row(run)
    assert (row["cpu_numpy_simd"], row["cpu_blas"], row["cpu_torch"]) == ("AVX2", "openblas Haswell", "unrecorded")
