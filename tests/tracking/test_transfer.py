"""Export a store's finished runs to one file and import them elsewhere: resume and reports find them;
a crafted, damaged or edited file changes nothing, runs nothing and is refused in one line."""

from __future__ import annotations

import base64
import gzip
import hashlib
import io
import json
import pickle
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from vlmrl_cli.analysis.load import load_experiment
from vlmrl_cli.cli.app import app
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.tracking import store
from vlmrl_cli.tracking.transfer import (
    FORMAT,
    FORMAT_NAME,
    MAX_KEY,
    MAX_PARAM_VALUE,
    MAX_TAG_VALUE,
    TAG_IMPORTED_FROM,
    digest_line,
    export_runs,
    import_runs,
    read_export,
    read_records,
)

slow = pytest.mark.slow  # the tests of a trained store

runner = CliRunner()


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> str:
    root = tmp_path_factory.mktemp("source")
    uri = f"sqlite:///{root / 'm.db'}"
    result = runner.invoke(app, ["run", "--arms", "baseline,hybrid-shuffled", "--seeds", "2", "--preset", "smoke",
                                 "--workers", "1", "--set", "ppo.eval_episodes=2",
                                 "--set", f"vlm.cache_path={root / 'c.sqlite'}", "--tracking-uri", uri,
                                 "--experiment", "src"])
    assert result.exit_code == 0, result.output + result.stderr
    return uri


@slow
def test_a_round_trip_keeps_what_the_analysis_reads(source: str, tmp_path: Path) -> None:
    path = tmp_path / "runs.jsonl.gz"
    assert export_runs(store.connect(source), "src", path).written == 4
    records = list(read_records(path))
    assert {r["format"] for r in records} == {FORMAT} and all("config.json" in r["artifacts"] for r in records)
    assert not any(r["binary"] for r in records)  # models only on request

    target = store.connect(f"sqlite:///{tmp_path / 'new' / 'm.db'}")
    assert import_runs(target, path, "dst").written == 4
    before, after = load_experiment(store.connect(source), "src"), load_experiment(target, "dst")
    cols = ["arm", "seed", "config_hash", "budget", "eval_success_rate", "eval_mean_length"]
    pd.testing.assert_frame_equal(before.runs[cols], after.runs[cols])
    drop = ["run_id"]
    pd.testing.assert_frame_equal(before.episodes.drop(columns=drop), after.episodes.drop(columns=drop))
    pd.testing.assert_frame_equal(before.eval_episodes.drop(columns=drop), after.eval_episodes.drop(columns=drop))
    imported = target.search_runs([target.get_experiment_by_name("dst").experiment_id])
    assert all(r.info.status == "FINISHED" and TAG_IMPORTED_FROM in r.data.tags for r in imported)
    assert all("mlflow.parentRunId" not in r.data.tags for r in imported)

    again = import_runs(target, path, "dst")
    assert (again.written, again.skipped) == (0, 4)


@slow
def test_a_resumed_sweep_reuses_imported_runs(source: str, tmp_path: Path) -> None:
    path = tmp_path / "runs.jsonl.gz"
    export_runs(store.connect(source), "src", path, models=True)
    uri = f"sqlite:///{tmp_path / 'm.db'}"
    result = runner.invoke(app, ["import", str(path), "--tracking-uri", uri, "--experiment", "dst"])
    assert result.exit_code == 0 and "imported 4 run(s)" in result.output, result.output + result.stderr
    again = runner.invoke(app, ["export", "--out", str(tmp_path / "more.jsonl.gz"), "--tracking-uri", source,
                                "--experiment", "src", "--skip-exported", str(path)])
    assert again.exit_code == 2 and "not in the earlier exports (4 are)" in again.stderr
    dry = runner.invoke(app, ["run", "--arms", "baseline,hybrid-shuffled", "--seeds", "2", "--preset", "smoke",
                              "--set", "ppo.eval_episodes=2", "--tracking-uri", uri, "--experiment", "dst",
                              "--dry-run"])
    assert dry.exit_code == 0 and "4 FINISHED, 0 pending; nothing was trained" in dry.output, dry.output


@slow
def test_export_refuses_a_missing_experiment_and_import_a_foreign_file(source: str, tmp_path: Path) -> None:
    with pytest.raises(BadInput, match="does not exist"):
        export_runs(store.connect(source), "nope", tmp_path / "x.gz")
    assert not list(tmp_path.iterdir())
    bad = tmp_path / "bad.jsonl.gz"
    with gzip.open(bad, "wt") as f:
        f.write(json.dumps({"format": "other"}) + "\n")
    result = runner.invoke(app, ["import", str(bad), "--tracking-uri", f"sqlite:///{tmp_path / 's' / 'm.db'}"])
    assert result.exit_code == 2 and "not a vlmrl run export" in result.stderr
    assert not (tmp_path / "s").exists()


# --- untrusted files (no training: records of a committed export, then edited) ------------------

COMMITTED = Path(__file__).resolve().parents[2] / "results" / "zoo-reference" / "runs-mountain-car-continuous.jsonl.gz"


def _write(path: Path, records: list[dict], digest: bool = True) -> Path:
    """``records`` as an export file, with the digest line of this format when ``digest``."""
    lines = [json.dumps(r, separators=(",", ":")) + "\n" for r in records]
    with gzip.open(path, "wt", encoding="utf-8") as out:
        out.writelines(lines)
        if digest:
            sha = hashlib.sha256("".join(lines).encode("utf-8")).hexdigest()
            out.write(json.dumps(digest_line(len(lines), sha)) + "\n")
    return path


def _records(n: int = 2) -> list[dict]:
    return [{**r, "format": FORMAT} for r in list(read_records(COMMITTED))[:n]]


def _import(tmp_path: Path, path: Path, *args: str):  # type: ignore[no-untyped-def]
    return runner.invoke(app, ["import", str(path), "--tracking-uri", f"sqlite:///{tmp_path / 'store' / 'm.db'}",
                               "--experiment", "dst", *args])


def _refused(result, words: str) -> None:  # type: ignore[no-untyped-def]
    assert result.exit_code == 2, result.output + result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and words in lines[0], result.stderr


class Payload:
    """A pickle that, once loaded, creates the file ``marker``: what a crafted artifact would run."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):  # type: ignore[no-untyped-def]
        return (Path.touch, (self.marker,))


def _b64(blob: bytes) -> str:
    return base64.b64encode(blob).decode("ascii")


@pytest.mark.parametrize("name", ["/tmp/vlmrl-evil.txt", "../../evil.txt", "config.json/../../evil.txt",
                                  "sub/config.json", "..", ""])
@pytest.mark.parametrize("field", ["artifacts", "binary"])
def test_an_artifact_name_that_is_a_path_is_refused_and_nothing_is_written(tmp_path: Path, name: str,
                                                                           field: str) -> None:
    records = _records()
    records[1][field] = {**records[1][field], name: "eA=="}
    result = _import(tmp_path, _write(tmp_path / "x.jsonl.gz", records))
    _refused(result, "line 2: ")
    assert "is none of" in result.stderr and "never a path" in result.stderr
    assert not (tmp_path / "store").exists() and not Path("/tmp/vlmrl-evil.txt").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.jsonl.gz"]


def _zip_with_data(payload: bytes) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("data", json.dumps({"policy_class": {":serialized:": _b64(payload)}}))
        archive.writestr("policy.pth", payload)
    return buffer.getvalue()


def _npz_with_objects() -> bytes:
    buffer = io.BytesIO()
    np.savez(buffer, obs_mean=np.array([object()], dtype=object))
    return buffer.getvalue()


@pytest.mark.parametrize(("name", "make", "words"), [
    ("vecnormalize.pkl", lambda p: pickle.dumps(p), "is a pickle, and loading a pickle runs whatever code it holds"),
    ("model.zip", lambda p: _zip_with_data(pickle.dumps(p)), "is a pickle"),
    ("policy.pth", lambda p: pickle.dumps(p), "is not a plain tensor file"),
    ("policy.pth", lambda p: _torch_pickle(p), "is not a plain tensor file"),
    ("vecnormalize.npz", lambda p: _npz_with_objects(), "is not a plain array file"),
    ("vecnormalize.npz", lambda p: pickle.dumps(p), "is not a plain array file"),
])
def test_a_pickle_payload_in_any_artifact_runs_nothing_and_is_refused(tmp_path: Path, name: str, make,  # type: ignore[no-untyped-def]
                                                                      words: str) -> None:
    marker = tmp_path / "ran"
    records = _records()
    records[0]["binary"] = {name: _b64(make(Payload(marker)))}
    result = _import(tmp_path, _write(tmp_path / "x.jsonl.gz", records))
    _refused(result, words)
    assert not marker.exists() and not (tmp_path / "store").exists()


def _torch_pickle(payload: object) -> bytes:
    import torch

    buffer = io.BytesIO()
    torch.save({"weight": payload}, buffer)
    return buffer.getvalue()


def test_a_trusted_pickle_is_stored_and_never_loaded_by_import(tmp_path: Path) -> None:
    marker = tmp_path / "ran"
    records = _records(1)
    records[0]["binary"] = {"vecnormalize.pkl": _b64(pickle.dumps(Payload(marker)))}
    result = _import(tmp_path, _write(tmp_path / "x.jsonl.gz", records), "--trust-pickle")
    assert result.exit_code == 0, result.output + result.stderr
    client = store.connect(f"sqlite:///{tmp_path / 'store' / 'm.db'}")
    run = client.search_runs([client.get_experiment_by_name("dst").experiment_id])[0]
    assert {a.path for a in client.list_artifacts(run.info.run_id)} == {"config.json", "vecnormalize.pkl"}
    assert not marker.exists()


def _truncated(path: Path) -> Path:
    _write(path, _records())
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    return path


def _edit(mutate):  # type: ignore[no-untyped-def]
    def make(path: Path) -> Path:
        records = _records()
        mutate(records[1])
        return _write(path, records)
    return make


@pytest.mark.parametrize(("make", "words"), [
    (lambda p: (p.write_bytes(b""), p)[1], "holds no run"),
    (lambda p: (p.write_bytes(b"not gzip at all"), p)[1], "cannot read the run export"),
    (_truncated, "cannot read the run export"),
    (lambda p: _write(p, [*_records(), {"format": FORMAT}], digest=False), "line 3: source_run_id: Field required"),
    (_edit(lambda r: r["tags"].pop("vlmrl.arm")), "line 2: tags: vlmrl.arm missing"),
    (_edit(lambda r: r["histories"]["episode/length"]["ts"].pop()), "line 2: histories.episode/length: "),
    (_edit(lambda r: r["histories"]["episode/length"]["value"].__setitem__(0, "7")),
     "line 2: histories.episode/length.value.0: Input should be a valid number"),
    (_edit(lambda r: r["latest"].__setitem__("perf/wall_s", [0, 1, "fast"])), "line 2: latest.perf/wall_s.2"),
    (_edit(lambda r: r.__setitem__("tags", "x")), "line 2: tags: Input should be a valid dictionary"),
    (_edit(lambda r: r["tags"].__setitem__("vlmrl.kind", "sweep")), "not a training run"),
    (_edit(lambda r: r["artifacts"].__setitem__("config.json", "{")), "config.json is not JSON"),
    (_edit(lambda r: r.__setitem__("extra", 1)), "line 2: extra: Extra inputs are not permitted"),
])
def test_a_damaged_or_malformed_export_is_refused_before_any_store_exists(tmp_path: Path, make,  # type: ignore[no-untyped-def]
                                                                          words: str) -> None:
    result = _import(tmp_path, make(tmp_path / "x.jsonl.gz"))
    _refused(result, words)
    assert not (tmp_path / "store").exists()


def test_an_edited_export_is_refused_by_its_digest(tmp_path: Path) -> None:
    good = _write(tmp_path / "good.jsonl.gz", _records())
    with gzip.open(good, "rt", encoding="utf-8") as f:
        lines = f.readlines()
    tampered = tmp_path / "tampered.jsonl.gz"
    with gzip.open(tampered, "wt", encoding="utf-8") as out:
        out.writelines([lines[0].replace('"vlmrl.seed":"0"', '"vlmrl.seed":"7"'), *lines[1:]])
    _refused(_import(tmp_path, tampered), "do not match its digest line")
    dropped = tmp_path / "dropped.jsonl.gz"
    with gzip.open(dropped, "wt", encoding="utf-8") as out:
        out.writelines(lines[:1] + lines[2:])  # a run removed, the digest kept
    _refused(_import(tmp_path, dropped), "do not match its digest line")
    _refused(_import(tmp_path, _write(tmp_path / "bare.jsonl.gz", _records(), digest=False)), "has no digest line")
    assert not (tmp_path / "store").exists()
    result = _import(tmp_path, good)
    assert result.exit_code == 0 and "imported 2 run(s)" in result.output and "no digest" not in result.output


def test_a_format_1_file_is_read_and_says_it_has_no_digest(tmp_path: Path) -> None:
    assert read_export(COMMITTED).digest_checked  # the committed files got their digest line appended
    old = _write(tmp_path / "old.jsonl.gz", [{**r, "format": f"{FORMAT_NAME}/1"} for r in _records()], digest=False)
    assert not read_export(old).digest_checked
    result = _import(tmp_path, old)
    assert result.exit_code == 0 and "(format 1: the file carries no digest to check)" in result.output, result.output


def test_an_import_that_fails_midway_leaves_the_store_as_it_was(tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    uri = f"sqlite:///{tmp_path / 'm.db'}"
    client = store.connect(uri)
    export = _write(tmp_path / "x.jsonl.gz", _records(3))
    calls = []
    real = store.log_artifacts

    def failing(*args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(1)
        if len(calls) == 3:
            raise OSError("disk full")
        return real(*args, **kwargs)

    monkeypatch.setattr(store, "log_artifacts", failing)
    with pytest.raises(OSError, match="disk full"):
        import_runs(client, export, "dst")
    exp = client.get_experiment_by_name("dst")
    assert exp.lifecycle_stage == "deleted"
    assert not client.search_runs([exp.experiment_id])  # the two runs written before the failure are gone
    monkeypatch.setattr(store, "log_artifacts", real)
    assert import_runs(client, export, "dst").written == 3  # the deleted runs do not count as present


def test_the_record_limits_are_mlflow_s() -> None:
    from mlflow.utils import validation

    assert (MAX_KEY, MAX_TAG_VALUE, MAX_PARAM_VALUE) == (
        validation.MAX_ENTITY_KEY_LENGTH, validation.MAX_TAG_VAL_LENGTH, validation.MAX_PARAM_VAL_LENGTH)
