"""Move finished training runs between MLflow stores as one gzip JSON-lines file (export / import).

An export file is untrusted input: every record is checked (``Record``, ``check_binary``) and the
file against its digest line before a caller sees it, and nothing in it is unpickled. The format,
and what an import refuses, are in docs/commands/export-import.md.
"""

from __future__ import annotations

import base64
import binascii
import contextlib
import gzip
import hashlib
import io
import json
import tempfile
import zipfile
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, StrictFloat, StrictInt, ValidationError, model_validator

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.tracking import schema, store
from vlmrl_cli.tracking.lifecycle import tracked_run

FORMAT_NAME = "vlmrl-runs"
#: The format written; every older one (``READABLE``) is read, a newer one refused with "upgrade vlmrl".
FORMAT_VERSION = 2
FORMAT = f"{FORMAT_NAME}/{FORMAT_VERSION}"
READABLE = tuple(f"{FORMAT_NAME}/{v}" for v in range(1, FORMAT_VERSION + 1))
HISTORY_KEYS: tuple[str, ...] = (*schema.EPISODE_METRICS, schema.METRIC_EVAL_EPISODE_RETURN,
                                  schema.METRIC_EVAL_EPISODE_LENGTH, schema.METRIC_EVAL_EPISODE_SUCCESS)
TEXT_ARTIFACTS: tuple[str, ...] = (schema.ARTIFACT_CONFIG,)
#: What ``--models`` carries: the policy's weights and the observation statistics, neither a pickle.
MODEL_ARTIFACTS: tuple[str, ...] = (schema.ARTIFACT_POLICY, schema.ARTIFACT_NORMALIZER)
#: Pickles: an import refuses them unless the user trusts the file (``trust_pickle``).
PICKLED_ARTIFACTS: tuple[str, ...] = (schema.ARTIFACT_MODEL, schema.ARTIFACT_PICKLED_NORMALIZER)
# the source store's runs and processes; the episodes table is not exported (its histories are)
_DROPPED_TAGS = (schema.MLFLOW_PARENT_RUN_ID, schema.TAG_OWNER, schema.TAG_HEARTBEAT, schema.TAG_EPISODES_TABLE)
TAG_IMPORTED_FROM = f"{schema.TAG_PREFIX}imported_from"
#: The tags without which a record is no training run of vlmrl's (the resume key and the kind).
REQUIRED_TAGS = (schema.TAG_KIND, schema.TAG_ARM, schema.TAG_SEED, schema.TAG_CONFIG_HASH)
#: MLflow's limits (``mlflow.utils.validation``; importing it costs seconds, a test keeps them equal),
#: checked before anything is written so that an import cannot fail halfway.
MAX_KEY = 250
MAX_TAG_VALUE = 8000
MAX_PARAM_VALUE = 6000

_Key = Annotated[str, Field(min_length=1, max_length=MAX_KEY, pattern=r"^[A-Za-z0-9_.\-/ :]+$")]
_Millis = Annotated[StrictInt, Field(ge=0)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class History(_Strict):
    """One metric's points: as many steps, timestamps (ms) and values."""

    step: list[StrictInt]
    ts: list[StrictInt]
    value: list[StrictFloat]

    @model_validator(mode="after")
    def _same_lengths(self) -> History:
        if not len(self.step) == len(self.ts) == len(self.value):
            raise ValueError(f"step, ts and value have {len(self.step)}, {len(self.ts)} and {len(self.value)} "
                             "points; each point needs all three")
        return self


class Record(_Strict):
    """One exported run, as ``read_records`` requires it before anyone reads it."""

    format: str
    source_run_id: Annotated[str, Field(pattern=r"^[0-9A-Za-z_-]{1,64}$")]
    run_name: Annotated[str, Field(max_length=MAX_KEY)] | None = None
    start_time: _Millis | None = None
    end_time: _Millis | None = None
    tags: dict[_Key, Annotated[str, Field(max_length=MAX_TAG_VALUE)]]
    params: dict[_Key, Annotated[str, Field(max_length=MAX_PARAM_VALUE)]]
    latest: dict[_Key, tuple[StrictInt, _Millis, StrictFloat]]
    histories: dict[str, History]
    artifacts: dict[str, str]
    binary: dict[str, str] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _a_training_run(self) -> Record:
        missing = [t for t in REQUIRED_TAGS if not self.tags.get(t)]
        if missing:
            raise ValueError(f"tags: {', '.join(missing)} missing; a record is one training run of vlmrl's")
        if self.tags[schema.TAG_KIND] != schema.KIND_TRAIN:
            raise ValueError(f"tags: {schema.TAG_KIND} is {self.tags[schema.TAG_KIND]!r}, not a training run")
        unknown = sorted(set(self.histories) - set(HISTORY_KEYS))
        if unknown:
            raise ValueError(f"histories: {unknown[0]!r} is none of {', '.join(HISTORY_KEYS)}")
        twice = sorted(set(self.latest) & set(HISTORY_KEYS))
        if twice:
            raise ValueError(f"latest: {twice[0]!r} has a history; it is not a last value")
        for field, names, allowed in (("artifacts", self.artifacts, TEXT_ARTIFACTS),
                                      ("binary", self.binary, MODEL_ARTIFACTS + PICKLED_ARTIFACTS)):
            bad = sorted(set(names) - set(allowed))
            if bad:
                raise ValueError(f"{field}: the artifact name {bad[0]!r} is none of {', '.join(allowed)} (an "
                                 "artifact is named, never a path)")
        try:
            parsed = json.loads(self.artifacts.get(schema.ARTIFACT_CONFIG, "{}"))
        except json.JSONDecodeError as exc:
            raise ValueError(f"artifacts: {schema.ARTIFACT_CONFIG} is not JSON ({exc.msg})") from None
        if not isinstance(parsed, dict):
            raise ValueError(f"artifacts: {schema.ARTIFACT_CONFIG} is not a JSON object")
        return self


@dataclass(frozen=True)
class TransferSummary:
    """Runs written (or created) and runs skipped as present."""

    written: int
    skipped: int = 0


@dataclass(frozen=True)
class ExportFile:
    """The checked records of an export file, and whether it had a digest to check (format 1 has none)."""

    path: Path
    records: list[dict[str, Any]]
    digest_checked: bool


def _history(client: Any, run_id: str, key: str) -> dict[str, list[Any]]:
    points = sorted(client.get_metric_history(run_id, key), key=lambda p: (p.step, p.timestamp))
    return {"step": [int(p.step) for p in points], "ts": [int(p.timestamp) for p in points],
            "value": [float(p.value) for p in points]}


def _record(client: Any, run: Any, models: bool, workdir: Path) -> dict[str, Any]:
    run_id = run.info.run_id
    # metrics without a history (e.g. train/*) keep their last value, at step 0 and the run's end time
    when = int(run.info.end_time or run.info.start_time or 0)
    latest = {k: [0, when, float(v)] for k, v in run.data.metrics.items() if k not in HISTORY_KEYS}
    present = {a.path for a in client.list_artifacts(run_id)}
    model_files = (schema.ARTIFACT_MODEL, schema.ARTIFACT_NORMALIZER, schema.ARTIFACT_PICKLED_NORMALIZER)
    wanted = [n for n in (*TEXT_ARTIFACTS, *(model_files if models else ())) if n in present]
    store.download_artifacts(client, run_id, wanted, workdir)
    binary: dict[str, bytes] = {}
    if schema.ARTIFACT_MODEL in wanted:  # its policy.pth entry alone: the rest of the zip is cloudpickle
        with zipfile.ZipFile(workdir / schema.ARTIFACT_MODEL) as archive:
            binary[schema.ARTIFACT_POLICY] = archive.read(schema.ARTIFACT_POLICY)
    # the normaliser's arrays, or an older run's pickle
    normalizer = next((n for n in model_files[1:] if n in wanted), None)
    if normalizer is not None:
        binary[normalizer] = (workdir / normalizer).read_bytes()
    return {
        "format": FORMAT, "source_run_id": run_id, "run_name": run.info.run_name,
        "start_time": run.info.start_time, "end_time": run.info.end_time,
        "tags": dict(run.data.tags), "params": dict(run.data.params), "latest": latest,
        "histories": {key: _history(client, run_id, key) for key in HISTORY_KEYS if key in run.data.metrics},
        "artifacts": {n: (workdir / n).read_text(encoding="utf-8") for n in wanted if n in TEXT_ARTIFACTS},
        "binary": {n: base64.b64encode(blob).decode("ascii") for n, blob in binary.items()},
    }


def export_runs(client: Any, experiment: str, path: Path, models: bool = False,
                skip: set[str] | None = None) -> TransferSummary:
    """Write the FINISHED training runs of ``experiment`` but those in ``skip`` to ``path``
    (``write_records``); ``BadInput`` when none is left."""
    runs = schema.finished_train_runs(client, experiment)
    before = len(runs)
    runs = [r for r in runs if r.info.run_id not in (skip or set())]
    if not runs:
        raise BadInput(f"MLflow experiment '{experiment}' has no FINISHED training run to export"
                       + (f" that is not in the earlier exports ({before} are)." if before else "."))

    def records() -> Iterator[dict[str, Any]]:
        for run in runs:
            with tempfile.TemporaryDirectory(prefix="vlmrl-export-") as tmp:
                yield _record(client, run, models, Path(tmp))

    write_records(path, records())
    return TransferSummary(len(runs), before - len(runs))


def write_records(path: Path, records: Iterable[dict[str, Any]]) -> int:
    """Write ``records`` and their digest line to the gzip JSON-lines file ``path`` through a
    temporary name (a failed write leaves no partial file); how many were written."""
    partial = path.with_name(path.name + ".partial")
    digest, count = hashlib.sha256(), 0
    try:
        with gzip.open(partial, "wt", encoding="utf-8", compresslevel=9) as out:
            for record in records:
                line = json.dumps(record, separators=(",", ":")) + "\n"
                out.write(line)
                digest.update(line.encode("utf-8"))
                count += 1
            out.write(json.dumps(digest_line(count, digest.hexdigest()), separators=(",", ":")) + "\n")
        partial.replace(path)
    except OSError as exc:
        raise BadInput(f"cannot write the export file {path} ({exc.strerror or exc}).") from None
    finally:
        partial.unlink(missing_ok=True)
    return count


def digest_line(records: int, sha256: str) -> dict[str, Any]:
    """The last line of an export file: the record count and the sha256 of their lines' bytes."""
    return {"format": FORMAT, "records": records, "sha256": sha256}


def record_problem(record: object) -> str | None:
    """Why the parsed line ``record`` is no run record this package reads, in one line, or None.

    Example:
        >>> record_problem({"format": FORMAT, "source_run_id": "abc"})
        'tags: Field required (and 4 more: params, latest, histories, artifacts)'
    """
    tag = record.get("format") if isinstance(record, dict) else None
    if tag not in READABLE:
        name, _, version = str(tag).partition("/")
        if name == FORMAT_NAME and version.isdigit() and int(version) > FORMAT_VERSION:
            return f"written by a newer vlmrl (format {int(version)}; this one reads up to {FORMAT_VERSION}): " \
                "upgrade vlmrl"
        return f"not a vlmrl run export ({FORMAT})"
    try:
        Record.model_validate(record)
    except ValidationError as exc:  # one line: the first problem (where, what), and how many more
        errors = exc.errors(include_url=False, include_input=False)
        where = ".".join(str(p) for p in errors[0]["loc"])
        what = str(errors[0]["msg"]).removeprefix("Value error, ")
        line = f"{where}: {what}" if where else what
        if len(errors) > 1:
            shown = list(dict.fromkeys(".".join(str(p) for p in e["loc"][:1]) for e in errors[1:]))
            line += f" (and {len(errors) - 1} more: {', '.join(shown[:4])}{', ...' if len(shown) > 4 else ''})"
        return line[:400]
    return None


def read_export(path: Path) -> ExportFile:
    """Every record of the export file ``path`` once the whole file has passed its checks
    (``record_problem``, ``check_binary``, the digest line); ``BadInput`` naming the line otherwise."""
    records: list[dict[str, Any]] = []
    digest = hashlib.sha256()
    trailer: dict[str, Any] | None = None
    try:
        with gzip.open(path, "rt", encoding="utf-8") as lines:
            for n, line in enumerate(lines, start=1):
                if trailer is not None:
                    raise BadInput(f"{path}, line {n}: a line after the digest line; the file was edited.")
                try:
                    parsed = json.loads(line)
                except json.JSONDecodeError as exc:
                    raise BadInput(f"{path}, line {n}: not JSON ({exc.msg}); the file is damaged.") from None
                if isinstance(parsed, dict) and "sha256" in parsed and "source_run_id" not in parsed:
                    trailer = parsed
                    continue
                problem = record_problem(parsed)
                if problem:
                    raise BadInput(f"{path}, line {n}: {problem}.")
                check_binary(parsed)
                digest.update(line.encode("utf-8"))
                records.append(parsed)
    except (OSError, EOFError, zlib.error, UnicodeDecodeError) as exc:
        raise BadInput(f"cannot read the run export {path}: {exc}.") from None
    if not records:
        raise BadInput(f"{path} holds no run; write one with `vlmrl export`.")
    versions = {r["format"] for r in records}
    if versions == {f"{FORMAT_NAME}/1"} and trailer is None:
        return ExportFile(path, records, False)
    if len(versions) > 1:
        raise BadInput(f"{path} mixes formats {', '.join(sorted(versions))}; the file was edited.")
    if trailer is None:
        raise BadInput(f"{path} has no digest line: the file is truncated or was edited; export it again.")
    if trailer != digest_line(len(records), digest.hexdigest()):
        raise BadInput(f"{path}: its records do not match its digest line: the file was edited or damaged; "
                       "export it again.")
    return ExportFile(path, records, True)


def read_records(path: Path) -> Iterator[dict[str, Any]]:
    """The checked records of an export file (``read_export``)."""
    yield from read_export(path).records


def check_binary(record: dict[str, Any]) -> None:
    """``BadInput`` unless every model file of ``record`` is base64 of what its name says:
    ``policy.pth`` tensors that ``torch.load(weights_only=True)`` reads, ``vecnormalize.npz``
    numeric arrays that ``numpy.load(allow_pickle=False)`` reads (neither runs anything); a pickle
    is not opened here (``refuse_pickles``)."""
    for name, text in record.get("binary", {}).items():
        where = f"run {record['source_run_id']}: {name}"
        try:
            blob = base64.b64decode(text, validate=True)
        except (binascii.Error, ValueError):
            raise BadInput(f"{where} is not base64; the file is damaged.") from None
        try:
            if name == schema.ARTIFACT_POLICY:
                import torch

                state = torch.load(io.BytesIO(blob), map_location="cpu", weights_only=True)
                if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
                    raise TypeError("not a dictionary of tensors")
            elif name == schema.ARTIFACT_NORMALIZER:
                import numpy as np

                with np.load(io.BytesIO(blob), allow_pickle=False) as saved:
                    if any(saved[key].dtype.kind not in "biuf" for key in saved.files):
                        raise TypeError("an array of other values")
        except Exception as exc:  # whatever a crafted file makes the readers raise: refused, not run
            raise BadInput(f"{where} is not a plain {'tensor' if name == schema.ARTIFACT_POLICY else 'array'} "
                           f"file ({type(exc).__name__}); nothing of it was loaded.") from None


def refuse_pickles(export: ExportFile, trust_pickle: bool = False) -> None:
    """``BadInput`` for a pickled model file in ``export`` unless the user trusts the file: a store
    that keeps one hands it to whoever evaluates the run."""
    pickled = [(r["source_run_id"], n) for r in export.records for n in r.get("binary", {}) if n in PICKLED_ARTIFACTS]
    if pickled and not trust_pickle:
        raise BadInput(f"{export.path}: run {pickled[0][0]}: {pickled[0][1]} is a pickle, and loading a pickle runs "
                       "whatever code it holds; import it with --trust-pickle only if you trust where the file "
                       "came from.")


def _create(client: Any, experiment_id: str, record: dict[str, Any], created: list[str]) -> None:
    from mlflow.entities import Metric

    tags = {k: v for k, v in record["tags"].items() if k not in _DROPPED_TAGS}
    tags[TAG_IMPORTED_FROM] = record["source_run_id"]
    run = client.create_run(experiment_id, start_time=record["start_time"], tags=tags,
                            run_name=record.get("run_name"))
    run_id = run.info.run_id
    created.append(run_id)
    # never left RUNNING, and a failed import is FAILED: never taken for a finished run
    with tracked_run(client, run_id) as handle:
        handle.end_time = record["end_time"]
        store.log_params(client, run_id, record["params"])
        metrics = [Metric(k, float(v), int(ts), int(step)) for k, (step, ts, v) in record["latest"].items()]
        for key, h in record["histories"].items():
            metrics += [Metric(key, float(v), int(ts), int(s)) for s, ts, v in zip(h["step"], h["ts"], h["value"],
                                                                                   strict=True)]
        for i in range(0, len(metrics), 1000):
            client.log_batch(run_id, metrics=metrics[i : i + 1000])
        with tempfile.TemporaryDirectory(prefix="vlmrl-import-") as tmp:
            # the names are plain file names (Record checks them)
            files = {Path(tmp) / name: text.encode("utf-8") for name, text in record["artifacts"].items()}
            files |= {Path(tmp) / name: base64.b64decode(blob) for name, blob in record.get("binary", {}).items()}
            for file, blob in files.items():
                file.write_bytes(blob)
            store.log_artifacts(client, run_id, list(files))


def import_runs(client: Any, path: Path | ExportFile, experiment: str, trust_pickle: bool = False) -> TransferSummary:
    """Create the runs of the export ``path`` (or a file ``read_export`` has read) in ``experiment``
    (created if missing), skipping those already there. All or nothing: the whole file is checked
    first, and a failure while writing deletes the runs (and the experiment) this call made."""
    export = path if isinstance(path, ExportFile) else read_export(path)
    refuse_pickles(export, trust_pickle)
    existed = client.get_experiment_by_name(experiment) is not None
    experiment_id = store.ensure_experiment(client, experiment)
    present = schema.search_all(client, experiment_id,
                                schema.runs_filter({schema.TAG_KIND: schema.KIND_TRAIN}, finished=True))
    keys = {schema.job_key(r.data.tags) for r in present}
    sources = {r.data.tags[TAG_IMPORTED_FROM] for r in present if TAG_IMPORTED_FROM in r.data.tags}
    written = skipped = 0
    created: list[str] = []
    try:
        for record in export.records:
            key = schema.job_key(record["tags"])
            if key in keys or record["source_run_id"] in sources:
                skipped += 1
            else:
                _create(client, experiment_id, record, created)
                keys.add(key)
                written += 1
    except BaseException:
        # FAILED, then deleted (MLflow keeps deleted runs out of every search); a store that fails
        # here too leaves them FAILED at worst (tracked_run), never FINISHED
        for run_id in created:
            with contextlib.suppress(Exception):
                client.set_terminated(run_id, "FAILED")
            with contextlib.suppress(Exception):
                client.delete_run(run_id)
        if not existed:
            with contextlib.suppress(Exception):
                client.delete_experiment(experiment_id)
        raise
    return TransferSummary(written, skipped)
