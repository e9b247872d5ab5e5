"""What a user chooses about a study: one field per knob, light enough for `vlmrl --help`."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

from vlmrl_cli.core.fields import help_of
from vlmrl_cli.study.settings import StudySettings


def test_every_setting_says_what_it_is() -> None:
    assert all(help_of(f) for f in dataclasses.fields(StudySettings))


def test_the_settings_load_nothing_heavy() -> None:
    code = ("import sys, vlmrl_cli.study.settings\n"
            "print(sorted(m for m in ('pandas', 'scipy', 'torch', 'mlflow') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
