"""The forced-path probe's CPU check: an override that needs CPU flags is skipped, not run into a
SIGILL, on a CPU without them."""

from __future__ import annotations

from pathlib import Path

from tests.training.cpu_probe import AVX512, NEEDS, OVERRIDES, cpu_flags


def test_cpu_flags_reads_the_first_flags_line(tmp_path: Path) -> None:
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nflags\t\t: fpu avx2 fma\n\nprocessor\t: 1\nflags\t\t: avx512f\n")
    zen3 = cpu_flags(str(info))
    assert zen3 == {"fpu", "avx2", "fma"}
    assert cpu_flags(str(tmp_path / "missing")) == frozenset()
    assert NEEDS["aten-avx512"] - zen3 == AVX512  # what the test would skip for, on such a CPU


def test_every_needed_override_exists() -> None:
    assert set(NEEDS) <= set(OVERRIDES)
