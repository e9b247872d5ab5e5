from __future__ import annotations

from types import SimpleNamespace

import pandas as pd
import pytest

from vlmrl_cli.analysis.load import RUN_COLUMNS, _run_row
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.report.writer import check_paths

PINNED = "x86-64-v3/1 (ATEN_CPU_CAPABILITY=avx2 MKL_CBWR=COMPATIBLE ONEDNN_MAX_CPU_ISA=AVX2; torch AVX2)"


def _runs(paths: list[str], models: list[str] | None = None) -> pd.DataFrame:
    models = models or ["AMD EPYC"] * len(paths)
    rows = [{c: None for c in RUN_COLUMNS} | {"arm": "hybrid", "seed": i, "numeric_path": p, "cpu_model": m}
            for i, (p, m) in enumerate(zip(paths, models, strict=True))]
    return pd.DataFrame(rows, columns=RUN_COLUMNS)


def test_runs_of_one_path_pass_whatever_cpu_computed_them() -> None:
    runs = _runs([PINNED] * 3, ["AMD EPYC", "Intel(R) Xeon(R) Platinum 8480+", "AMD EPYC"])
    assert check_paths(runs, allow_mixed=False) == []


def test_mixed_paths_are_refused_in_one_line_naming_each_path() -> None:
    other = "unpinned (run predates the numeric pin; torch AVX512)"
    with pytest.raises(BadInput) as err:
        check_paths(_runs([PINNED, PINNED, other]), allow_mixed=False)
    message = str(err.value)
    assert "\n" not in message and "--allow-mixed-paths" in message
    assert f"{PINNED}: 2 run(s)" in message and f"{other}: 1 run(s)" in message


def test_mixed_paths_are_a_warning_when_allowed() -> None:
    warns = check_paths(_runs([PINNED, "unpinned (x; torch AVX512)"]), allow_mixed=True)
    assert len(warns) == 1 and "2 numeric paths" in warns[0]


def _row(tags: dict[str, str]) -> dict[str, object]:
    run = SimpleNamespace(info=SimpleNamespace(run_id="r", end_time=0),
                          data=SimpleNamespace(tags=tags, params={}, metrics={}))
    return _run_row(run)


def test_the_cpu_tags_of_a_run_become_its_cpu_columns() -> None:
    row = _row({"vlmrl.cpu.numpy_simd": "AVX2", "vlmrl.cpu.blas": "openblas Haswell", "vlmrl.arm": "baseline"})
    assert (row["cpu_numpy_simd"], row["cpu_blas"], row["cpu_torch"]) == ("AVX2", "openblas Haswell", "unrecorded")
    assert str(row["numeric_path"]).startswith("unpinned (run predates the numeric pin")


def test_the_pin_tags_of_a_run_name_its_numeric_path() -> None:
    row = _row({"vlmrl.pin": "x86-64-v3/1", "vlmrl.pin.env": "MKL_CBWR=COMPATIBLE", "vlmrl.cpu.torch": "AVX2",
                "vlmrl.cpu.numpy_simd": "X86_V3,X86_V4", "vlmrl.cpu.model": "AMD EPYC"})
    assert row["numeric_path"] == "x86-64-v3/1 (MKL_CBWR=COMPATIBLE; torch AVX2)"  # numpy's level is not in it
    assert row["cpu_model"] == "AMD EPYC"
