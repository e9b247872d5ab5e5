"""Bad input across every command, through the real entry point (``vlmrl_cli.cli.app.cli``).

Each case must exit 2 with exactly one ``error:`` line on stderr, and leave nothing behind: no
MLflow store, output folder, VLM cache or lock file, in the working folder or the temp folder.
click's own usage errors (an unknown flag, a value out of range) are in the table too: they
print the same one line as ours.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from vlmrl_cli.cli.app import cli

#: (command line, a phrase the error line must contain); {tmp} is the test's folder, which holds
#: a plain file ``file``, so that ``{tmp}/file/x`` cannot be created.
CASES: list[tuple[str, str]] = [
    # the app itself
    ("bogus", "No such command 'bogus'"),
    ("--bogus", "No such option: --bogus"),
    # taxonomy
    ("taxonomy --states 0", "Invalid value for '--states'"),
    ("taxonomy --experiment ''", "an experiment needs a name"),
    ("taxonomy --tracking-uri ' '", "tracking URI"),
    ("taxonomy --out {tmp}/file/out", "output folder"),
    ("taxonomy --out /proc/vlmrl-out", "output folder"),
    ("taxonomy --cache-path {tmp}/file/c.sqlite", "response cache"),
    ("taxonomy --vlm replay --transcript {tmp}/missing.jsonl", "transcript"),
    ("taxonomy --vlm hf --model {tmp}/no-such-model", "no-such-model"),
    ("taxonomy --vlm openai --model m --base-url http://127.0.0.1:9/v1 --timeout 2 --retries 0", "127.0.0.1:9"),
    ("taxonomy --sim-profile lava", "Invalid value for '--sim-profile'"),
    # run
    ("run --seeds two", "Invalid value for '--seeds'"),
    ("run --sim-flicker 2", "Invalid value for '--sim-flicker'"),
    ("run --frobnicate", "No such option: --frobnicate"),
    ("run --arms teleport", "unknown arm 'teleport'"),
    ("run --arms baseline,,hybrid", "has an empty entry"),
    ("run --seeds 2 --seed-list 3", "--seeds and --seed-list both given"),
    ("run --seed-list 3,3", "lists a seed twice"),
    ("run --set shaping.alpha=-1", "shaping.alpha"),
    ("run --set shaping.kin_scale=-2", "shaping.kin_scale"),
    ("run --set shaping.alpha=nan", "finite number"),
    ("run --set ppo.nenvs=1", "did you mean 'ppo.n_envs'"),
    ("run --set n_envs", "KEY=VALUE"),
    ("run --workers 0", "workers"),
    ("run --timesteps -5", "timesteps"),
    ("run --experiment ''", "an experiment needs a name"),
    ("run --tracking-uri nope://x", "cannot be reached"),
    ("run --tracking-uri sqlite:///{tmp}/file/mlflow.db", "cannot be reached"),
    ("run --config {tmp}/missing.toml", "cannot read the config file"),
    ("run --arms hybrid --cache-path {tmp}/file/c.sqlite", "response cache"),
    ("run --arms hybrid --vlm replay", "transcript"),
    ("run --arms hybrid --vlm hf --model {tmp}/no-such-model", "no-such-model"),
    ("run --arms hybrid --vlm hf --model llava-hf/llava-1.5-7b-hf", "not in the local Hugging Face cache"),
    ("run --arms hybrid --vlm openai --model m --base-url http://127.0.0.1:9/v1 --timeout 2 --retries 0",
     "127.0.0.1:9"),
    # report
    ("report", "no tracking database"),
    ("report --tracking-uri sqlite:///{tmp}/missing.db", "no tracking database"),
    ("report --thresholds a,b", "thresholds"),
    ("report --window 0", "window"),
    ("report --margin 0.9", "margin is a ratio above 1"),
    ("report --out {tmp}/file/out", "output folder"),
    # calibrate
    ("calibrate --grid ppo.n_envs=1,2 --grid ppo.n_envs=4", "ppo.n_envs"),
    ("calibrate --grid ppo.nenvs=1,2", "did you mean 'ppo.n_envs'"),
    ("calibrate --grid ppo.n_envs", "KEY=VALUE"),
    ("calibrate --out {tmp}/file/out", "output folder"),
    ("calibrate --seeds 0", "seeds"),
    # evaluate
    ("evaluate", "Missing argument"),
    ("evaluate 0123abcd --tracking-uri sqlite:///{tmp}/missing.db", "no tracking database"),
    ("evaluate 0123abcd --episodes 0", "Invalid value for '--episodes'"),
    # study
    ("study --alphas -1", "alphas must be finite and >= 0"),
    ("study --margin 0.9", "--margin is a ratio above 1"),
    ("study --regime nope", "unknown preset 'nope'"),
    ("study --kin-scales x", "--kin-scales takes numbers"),
    ("study --out {tmp}/file/out", "output folder"),
    # export / import
    ("export --out {tmp}/x.jsonl.gz --tracking-uri sqlite:///{tmp}/missing.db", "no tracking database"),
    ("export --out {tmp}/file/x.jsonl.gz --tracking-uri sqlite:///{tmp}/missing.db", "x.jsonl.gz"),
    ("import {tmp}/missing.jsonl.gz --tracking-uri sqlite:///{tmp}/store.db", "missing.jsonl.gz"),
    ("import {tmp}/file --tracking-uri sqlite:///{tmp}/store.db", "cannot read the run export"),
    # verify
    ("verify {tmp}/missing.jsonl.gz", "no export file"),
    ("verify {tmp}/file", "cannot read the run export"),
    ("verify --tracking-uri sqlite:///{tmp}/missing.db", "no tracking database"),
    ("verify {tmp}/missing.jsonl.gz --sample 0", "--sample"),
    ("verify {tmp}/missing.jsonl.gz --workers 0", "--workers"),
]


def _leftovers(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


@pytest.mark.parametrize(("line", "needle"), CASES, ids=[line for line, _ in CASES])
def test_bad_input_exits_2_with_one_line_and_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], line: str, needle: str
) -> None:
    import shlex

    work, temp = tmp_path / "work", tmp_path / "temp"
    for folder in (work, temp):
        folder.mkdir()
    (tmp_path / "file").write_text("not a folder")
    monkeypatch.chdir(work)
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    for name, value in (("TMPDIR", temp), ("HF_HOME", temp / "hf"), ("HF_HUB_OFFLINE", "1")):
        monkeypatch.setenv(name, str(value))
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    before = _leftovers(tmp_path)
    code = cli(shlex.split(line.replace("{tmp}", str(tmp_path))))
    err = capsys.readouterr().err
    lines = [text for text in err.splitlines() if text.strip()]
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], lines
    assert _leftovers(tmp_path) == before  # no store, folder, cache or lock file anywhere
