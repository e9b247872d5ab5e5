"""Bad input across every command, through the real entry point (``vlmrl_cli.cli.app.cli``).

Each case must exit 2 with exactly one ``error:`` line on stderr, and leave nothing behind: no
MLflow store, output folder, VLM cache or lock file, in the working folder or the temp folder.
click's own usage errors (an unknown flag, a value out of range) are in the table too: they
print the same one line as ours.
"""

from __future__ import annotations

import gzip
import json
import os
import resource
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from vlmrl_cli.cli.app import cli
from vlmrl_cli.tracking.transfer import FORMAT_NAME, FORMAT_VERSION

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
    ("taxonomy --sim-profile lava", "unknown simulated-VLM profile 'lava'"),
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
    # minibatches SB3 would truncate (it only warns) or refuse mid-run (batch_size 1, a rollout of 1)
    ("run --set ppo.batch_size=3", "does not divide ppo.n_envs x ppo.n_steps (16 x 16 = 256): SB3 would train on a "
                                   "truncated last minibatch of 1; use a batch_size that divides 256, e.g. 2 or 4"),
    ("run --set ppo.batch_size=100", "e.g. 64 or 128"),
    ("run --set ppo.batch_size=1", "ppo.batch_size (1) must be at least 2"),
    ("run --set ppo.n_envs=1 --set ppo.n_steps=1 --set ppo.batch_size=2", "exceeds ppo.n_envs x ppo.n_steps (1 x 1"),
    ("run --preset smoke --set ppo.n_steps=1 --set ppo.batch_size=3", "exceeds ppo.n_envs x ppo.n_steps (2 x 1"),
    ("run --task acrobot --set ppo.batch_size=48", "use a batch_size that divides"),
    # a --task module is read before it is imported: only a vlmrl task module runs (os.system ran, os.abort
    # killed vlmrl, `this` printed the Zen of Python, mlflow.__main__ ran MLflow's CLI)
    ("run --task os:system", "os.py does not import vlmrl_cli; it is not a vlmrl task module, and nothing of it ran"),
    ("run --task this:x", "this.py does not import vlmrl_cli"),
    ("taxonomy --task this:x", "this.py does not import vlmrl_cli"),
    ("run --task mlflow.__main__:cli", "__main__.py does not import vlmrl_cli"),
    ("run --task os.path:join", "no Python source file os/path.py"),
    ("run --task subprocess:Popen", "subprocess.py does not import vlmrl_cli"),
    ("run --task vlmrl_cli.tasks.base:Task", "is a type, not a vlmrl_cli.tasks.base.Task"),
    # a task named in a file resolves through the registry alone
    ("run --set task=this:x", "names a Python module; vlmrl imports a module only when you name it with --task"),
    ("report --user-task this:x", "this.py does not import vlmrl_cli"),
    # stores that keep nothing, ignore part of their URI or lack their driver
    ("run --tracking-uri sqlite:///:memory:", "an in-memory sqlite store keeps nothing"),
    ("run --tracking-uri sqlite://", "an in-memory sqlite store keeps nothing"),
    ("run --tracking-uri sqlite:///{tmp}/m.db?mode=ro", "takes a file path and no query"),
    ("report --tracking-uri sqlite:///{tmp}/m.db?mode=ro", "takes a file path and no query"),
    ("run --tracking-uri postgresql+nosuchdriver://u@127.0.0.1:9/db", "no Python module nosuchdriver"),
    ("run --set n_envs", "KEY=VALUE"),
    ("run --workers 0", "workers"),
    ("calibrate --workers 0", "Invalid value for '--workers'"),  # RunConfig.workers' Ge(1), as its range
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
    ("calibrate --grid ppo.batch_size=48,64", "ppo.batch_size (48) does not divide"),
    ("calibrate --out {tmp}/file/out", "output folder"),
    ("calibrate --seeds 0", "seeds"),
    # evaluate
    ("evaluate", "Missing argument"),
    ("evaluate 0123abcd --tracking-uri sqlite:///{tmp}/missing.db", "no tracking database"),
    ("evaluate 0123abcd --episodes 0", "Invalid value for '--episodes'"),
    ("evaluate 0123abcd --episodes 100000", "--episodes must be in 1..10,000"),
    # study
    ("study --alphas -1", "study.alphas = [-1.0]: must be finite and >= 0"),
    ("study --margin 0.9", "study.margin = 0.9: must be a ratio above 1"),
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
    # upper bounds, each with its reason (hung, crashed or trained for hours before: issue 50)
    ("run --set ppo.n_envs=1000000", "invalid ppo.n_envs = 1000000: at most 256; the envs of a run are copies"),
    ("run --set ppo.n_steps=10000000", "at most 65,536; the rollout buffer"),
    ("run --set ppo.timesteps=1000000000000000", "invalid ppo.timesteps = 1000000000000000: at most 100,000,000"),
    ("run --set ppo.timesteps=1e15", "invalid ppo.timesteps"),
    ("run --timesteps 1000000000000000", "at most 100,000,000"),
    ("run --set ppo.n_epochs=100000000000000000000000", "at most 100; each epoch is a full pass"),
    ("run --set ppo.eval_episodes=1000000", "at most 10,000; each is a whole episode"),
    ("run --seeds 100000000 --dry-run", "--seeds 100000000: at most 1,000 seeds"),
    ("study --seeds 100000000 --dry-run", "at most 1,000 seeds"),
    ("run --seed-list 4294967296", "seeds are at most 2,147,483,647"),
    ("taxonomy --states 100000000", "--states 100,000,000 is too many: at most 10,000"),
    ("taxonomy --task acrobot --states 100000000", "at most 10,000"),
    ("study --states 100000000 --dry-run", "at most 10,000"),
    ("run --set shaping.kin_scale=1e308", "invalid shaping.kin_scale = 1e+308: at most 1,000,000; a larger scale"),
    ("run --set shaping.alpha=1e9", "invalid shaping.alpha"),
    ("run --set shaping.confirm=1000000000", "at most 100; a milestone is confirmed"),
    # a repeated value: a second copy of its comparisons in the multiplicity family, or a silent last-wins
    ("study --alphas 5,5 --dry-run", "study.alphas = [5.0, 5.0]: lists 5 twice; list each value once"),
    ("study --flickers 0.1,0.1 --dry-run", "study.flickers = [0.1, 0.1]: lists 0.1 twice"),
    ("study --alphas 0,5 --dry-run", "study.alphas = [0.0, 5.0]: lists 0, which the dose-response always includes"),
    ("study --kin-scales 2,2.0 --dry-run", "study.kin_scales = [2.0, 2.0]: lists 2 twice"),
    ("study --profiles ideal,ideal --dry-run", "study.profiles = [\"ideal\", \"ideal\"]: lists ideal twice"),
    ("calibrate --grid ppo.n_envs=1,1 --dry-run", "the grid of ppo.n_envs lists 1 twice"),
    ("report --thresholds nan", "--thresholds must be finite numbers"),
    ("report --thresholds -190,-130,-190", "--thresholds lists -190 twice"),
    ("run --set ppo.n_envs=1 --set ppo.n_envs=2 --dry-run",
     "--set ppo.n_envs=1 and --set ppo.n_envs=2 set one key twice; set each key once"),
    # tracebacks and unclear refusals before
    ("run --experiment " + "x" * 600, "the experiment name is 600 characters long"),
    ("export --out {tmp}/x.jsonl.gz --experiment " + "x" * 600, "600 characters long"),
    ("run --experiment 'a\tb' --dry-run", "holds a tab, newline or other control character"),
    ("taxonomy --experiment 'a\nb'", "holds a tab, newline or other control character"),
    ("export --out /proc/x.jsonl.gz --tracking-uri sqlite:///{tmp}/missing.db", "cannot write the export file"),
    ("compare {tmp}/file --config-hash ''", "--config-hash is empty"),
    ("compare {tmp}/file --n-boot 1000000000000", "--n-boot 1,000,000,000,000 is too many: at most 100,000"),
    ("verify {tmp}/file --tracking-uri sqlite:///{tmp}/m.db",
     "--tracking-uri chooses a store's runs, and {tmp}/file is an export file: verify reads one or the other"),
    ("verify {tmp}/file --experiment x", "drop --experiment to verify the file"),
    ("run --arms baseline --sim-flicker 0.3 --dry-run", "--sim-flicker sets the simulated VLM, which no arm"),
    ("run --arms hybrid --vlm hf --model m --sim-seed 3 --dry-run", "these runs ask the 'hf' backend"),
    ("calibrate --sim-profile ideal --dry-run", "calibrate trains the baseline arm alone"),
]


def _leftovers(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


def _refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], line: str,
             needle: str) -> tuple[str, float]:
    """Run ``vlmrl LINE`` as the table's cases run; check exit 2, one ``error:`` line holding
    ``needle`` and nothing left behind; return its stdout and its wall time (seconds)."""
    work, temp = tmp_path / "work", tmp_path / "temp"
    for folder in (work, temp):
        folder.mkdir(exist_ok=True)
    (tmp_path / "file").write_text("not a folder")
    monkeypatch.chdir(work)
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    for name, value in (("TMPDIR", temp), ("HF_HOME", temp / "hf"), ("HF_HUB_OFFLINE", "1")):
        monkeypatch.setenv(name, str(value))
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    before = _leftovers(tmp_path)
    start = time.monotonic()
    code = cli(shlex.split(line.replace("{tmp}", str(tmp_path))))
    elapsed = time.monotonic() - start
    captured = capsys.readouterr()
    lines = [text for text in captured.err.splitlines() if text.strip()]
    assert code == 2, captured.err
    needle = needle.replace("{tmp}", str(tmp_path))
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], lines
    assert _leftovers(tmp_path) == before  # no store, folder, cache or lock file anywhere
    return captured.out, elapsed


@pytest.mark.parametrize(("line", "needle"), CASES, ids=[line for line, _ in CASES])
def test_bad_input_exits_2_with_one_line_and_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], line: str, needle: str
) -> None:
    _refused(tmp_path, monkeypatch, capsys, line, needle)


#: Every command that takes --tracking-uri, with the arguments it needs to reach the store.
STORE_COMMANDS = ["run", "run --arms baseline --seeds 1 --preset smoke", "calibrate", "study", "taxonomy",
                  "taxonomy --task acrobot", "report", "evaluate 0123abcd", "export --out {tmp}/x.jsonl.gz", "verify",
                  "import {tmp}/runs.jsonl.gz"]
UNUSABLE_STORES = [
    # MLflow retried this one for 25 s and 51 s, printing some 40 lines, after the run's 3-line header
    ("sqlite:////proc/vlmrl.db", ("no file can be written in /proc", "no tracking database at /proc/vlmrl.db")),
    ("sqlite:///{tmp}/file/mlflow.db", ("{tmp}/file is a file, not a folder", "no tracking database at")),
    ("nope://x", ("MLflow has no store for the scheme 'nope'",) * 2),
]


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
@pytest.mark.parametrize("command", STORE_COMMANDS)
@pytest.mark.parametrize(("uri", "needles"), UNUSABLE_STORES, ids=[uri for uri, _ in UNUSABLE_STORES])
def test_an_unusable_store_is_one_line_within_2_s_before_any_header(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], command: str, uri: str,
    needles: tuple[str, str]
) -> None:
    if command.startswith("import"):
        _export(tmp_path / "runs.jsonl.gz", [_record(0)])
    reads = command.split()[0] in ("report", "evaluate", "export", "verify")  # a store that must exist already
    needle = needles[1] if reads else needles[0]
    out, elapsed = _refused(tmp_path, monkeypatch, capsys, f"{command} --tracking-uri {uri}",
                            needle.replace("{tmp}", str(tmp_path)))
    assert out == ""  # no header, banner or cost line before the refusal
    assert elapsed < 2.0


# --- export files: a sample larger than the file, a newer format ----------------------------


def _record(seed: int, fmt: str = f"{FORMAT_NAME}/1", task: str | None = None) -> dict[str, object]:
    """A minimal record of format 1 (no digest line to write)."""
    config = {"seed": seed, "arm": {"name": "baseline"}, **({"task": task} if task else {})}
    return {"format": fmt, "source_run_id": f"run{seed:04d}abcdef", "run_name": f"baseline-s{seed}",
            "start_time": 0, "end_time": 1, "tags": {"vlmrl.kind": "train", "vlmrl.arm": "baseline",
                                                     "vlmrl.seed": str(seed), "vlmrl.config_hash": "0123456789ab"},
            "params": {}, "latest": {},
            "histories": {"episode/native_return": {"step": [1], "ts": [1], "value": [-200.0]}},
            "artifacts": {"config.json": json.dumps(config)}, "binary": {}}


def _export(path: Path, records: list[dict[str, object]]) -> Path:
    with gzip.open(path, "wt", encoding="utf-8") as out:
        out.writelines(json.dumps(r) + "\n" for r in records)
    return path


def test_a_sample_larger_than_the_file_is_refused_with_its_run_count(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    # verifying the whole file instead took 13 minutes, unannounced
    _export(tmp_path / "runs.jsonl.gz", [_record(seed) for seed in range(3)])
    _refused(tmp_path, monkeypatch, capsys, "verify {tmp}/runs.jsonl.gz --sample 999",
             f"--sample 999 is more than the 3 run(s) {tmp_path}/runs.jsonl.gz holds; pass --sample 3 or fewer")
    _refused(tmp_path, monkeypatch, capsys, "verify {tmp}/runs.jsonl.gz --seed 1 --sample 2",
             "more than the 3 run(s)")


@pytest.mark.parametrize("command", ["verify {tmp}/runs.jsonl.gz", "verify {tmp}/runs.jsonl.gz --user-task this:x"])
def test_a_task_module_named_in_an_export_is_never_imported(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    records = [_record(seed, task="this:x") for seed in range(4)]
    for record, arm in zip(records, ("baseline", "hybrid") * 2, strict=True):
        record["tags"].update({"vlmrl.task": "this:x", "vlmrl.arm": arm})  # type: ignore[attr-defined]
        record["latest"] = {"eval/mean_return": [0, 1, -200.0 + len(arm)]}
    _export(tmp_path / "runs.jsonl.gz", records)
    words = "this.py does not import vlmrl_cli" if "--user-task" in command else "names a Python module"
    _refused(tmp_path, monkeypatch, capsys, command, words)
    assert "Zen" not in capsys.readouterr().out


@pytest.mark.parametrize("command", ["verify {tmp}/runs.jsonl.gz", "import {tmp}/runs.jsonl.gz --tracking-uri "
                                     "sqlite:///{tmp}/store.db", "compare {tmp}/runs.jsonl.gz --out {tmp}/cmp"])
def test_an_export_of_a_newer_format_says_to_upgrade(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    newer = FORMAT_VERSION + 1
    _export(tmp_path / "runs.jsonl.gz", [_record(0, f"vlmrl-runs/{newer}")])
    _refused(tmp_path, monkeypatch, capsys, command,
             f"written by a newer vlmrl (format {newer}; this one reads up to {FORMAT_VERSION}): upgrade vlmrl")


# --- another program's database, a text file posing as one: refused, and never written ---------


def _foreign(tmp_path: Path) -> Path:
    import sqlite3

    path = tmp_path / "other.db"
    con = sqlite3.connect(path)
    con.execute("create table notes (id integer primary key, text text)")
    con.execute("insert into notes (text) values ('mine')")
    con.commit()
    con.close()
    return path


@pytest.mark.parametrize("command", ["run --dry-run", "run", "report", "export --out {tmp}/x.jsonl.gz",
                                     "verify", "taxonomy --states 2"])
@pytest.mark.parametrize(("make", "words"), [(_foreign, "is a sqlite database of another program"),
                                             (lambda t: (t / "text.db", (t / "text.db").write_text("hello\n"))[0],
                                              "is not a sqlite database")])
def test_a_database_that_is_no_mlflow_store_is_refused_and_left_as_it_was(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], command: str, make,  # type: ignore[no-untyped-def]
    words: str
) -> None:
    import hashlib

    db = make(tmp_path)
    before = hashlib.sha256(db.read_bytes()).hexdigest()
    _refused(tmp_path, monkeypatch, capsys, f"{command} --tracking-uri sqlite:///{db}", words)
    assert hashlib.sha256(db.read_bytes()).hexdigest() == before


# --- the time a refusal takes, in a fresh process ----------------------------------------------

#: One refusal of a flag's value per command, each of which loaded its analysis stack (pandas, scipy,
#: matplotlib, MLflow) before checking its flags: 3.6-9.1 CPU-seconds on an idle 2-core machine.
TIMED = [
    "report --thresholds -190,-190",
    "report --tracking-uri sqlite:///{tmp}/missing.db",
    "evaluate 0123abcd --tracking-uri sqlite:///{tmp}/missing.db",
    "compare {tmp}/missing.jsonl.gz",
    "export --out /proc/x.jsonl.gz --tracking-uri sqlite:///{tmp}/missing.db",
    "import {tmp}/missing.jsonl.gz --tracking-uri sqlite:///{tmp}/store.db",
    "study --alphas 5,5 --dry-run",
    "study --out {tmp}/file/out --dry-run",
    "calibrate --grid ppo.n_envs=1,1 --dry-run",
    "calibrate --out {tmp}/file/out --dry-run",
    "taxonomy --states 100000000",
    "taxonomy --out {tmp}/file/out",
    "run --set ppo.n_envs=1000000",
    "verify --tracking-uri sqlite:///{tmp}/missing.db",
    # item 2's stores and files
    "run --tracking-uri sqlite:///:memory:",
    "report --tracking-uri sqlite:///{tmp}/m.db?mode=ro",
    "run --tracking-uri postgresql+nosuchdriver://u@127.0.0.1:9/db",
    "run --tracking-uri sqlite:///{tmp}/file",
    "import {tmp}/file --tracking-uri sqlite:///{tmp}/store.db",
]
#: Packages that take a second or more to load between them, none of which a refusal needs.
HEAVY = ("pandas", "scipy", "matplotlib", "mlflow", "torch", "stable_baselines3")


@pytest.mark.parametrize("line", TIMED)
def test_a_refusal_takes_under_2_cpu_seconds_in_a_fresh_process(tmp_path: Path, line: str) -> None:
    """``python -m vlmrl_cli LINE`` in a fresh process (the entry point users run, imports included)
    exits 2 in under 2 CPU-seconds, without loading ``HEAVY``.

    Measured as the child's CPU time (``resource.getrusage(RUSAGE_CHILDREN)``: user + system), not
    wall time, so that other work on a shared machine does not fail it; on an idle machine the two
    agree (about 0.5 s here). ``-X importtime`` lists every module the child loaded."""
    (tmp_path / "file").write_text("not a folder")
    work = tmp_path / "work"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "MLFLOW_TRACKING_URI"}
    env |= {"TMPDIR": str(tmp_path), "HF_HUB_OFFLINE": "1", "PYTHONPATH": str(Path(__file__).parents[2])}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run([sys.executable, "-X", "importtime", "-m", "vlmrl_cli",
                           *shlex.split(line.replace("{tmp}", str(tmp_path)))],
                          cwd=work, env=env, capture_output=True, text=True, timeout=120, check=False)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_s = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    imported = {row.rsplit("|", 1)[-1].strip() for row in done.stderr.splitlines() if row.startswith("import time:")}
    errors = [row for row in done.stderr.splitlines() if row.startswith("error: ")]
    assert done.returncode == 2 and len(errors) == 1, done.stderr[-2000:]
    assert not imported & set(HEAVY), (line, sorted(imported & set(HEAVY)))
    assert cpu_s < 2.0, f"{line}: {cpu_s:.2f} CPU-seconds"
    assert sorted(p.name for p in work.iterdir()) == []
