from __future__ import annotations

import pandas as pd

from vlmrl_cli.analysis.load import CPU_COLUMNS, RUN_COLUMNS, ExperimentData
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
    assert set(CPU_COLUMNS.values()) <= set(RUN_COLUMNS)
