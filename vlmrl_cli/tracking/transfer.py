"""Move finished training runs between MLflow stores as one compact file (export / import).

A study trained on a cluster, or over several sessions on machines that do not keep their
store, must be readable and resumable elsewhere. ``export_runs`` writes every FINISHED training
run of an experiment (``vlmrl.kind=train``) as one JSON line of a gzip file: its name, times,
tags and params, the last value of every metric, the full histories that the analysis reads
(the per-episode ``episode/*`` metrics and the detached evaluation's ``eval/episode_*``, with
their steps and timestamps, so points logged at one step keep their order), ``config.json``,
and the model files when asked. ``import_runs`` recreates them in another store as FINISHED
runs with the same tags, so a sweep's resume rule (a FINISHED run with the same arm, seed and
config hash) finds them and never trains them again, and ``vlmrl report`` reads them as it reads
runs trained there. A run already present (same arm, seed and config hash FINISHED, or imported
from the same source run) is skipped, so importing twice changes nothing.

Format (``FORMAT``), one object per line::

    {"format": "vlmrl-runs/1", "source_run_id": ..., "run_name": ..., "start_time": ms, "end_time": ms,
     "tags": {...}, "params": {...}, "latest": {key: [0, end_time, last value]},
     "histories": {key: {"step": [...], "ts": [...], "value": [...]}},
     "artifacts": {"config.json": "<text>"}, "binary": {"model.zip": "<base64>"}}
"""

from __future__ import annotations

import base64
import gzip
import json
import tempfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.tracking import schema, store
from vlmrl_cli.tracking.lifecycle import tracked_run

FORMAT_NAME = "vlmrl-runs"
#: The version of the format this package writes and reads; a file of a newer one is refused with
#: "upgrade vlmrl".
FORMAT_VERSION = 1
FORMAT = f"{FORMAT_NAME}/{FORMAT_VERSION}"
HISTORY_KEYS: tuple[str, ...] = (
    schema.METRIC_NATIVE_RETURN, schema.METRIC_LENGTH, schema.METRIC_SUCCESS, schema.METRIC_SHAPED_RETURN,
    schema.METRIC_EVAL_EPISODE_RETURN, schema.METRIC_EVAL_EPISODE_LENGTH, schema.METRIC_EVAL_EPISODE_SUCCESS,
)
TEXT_ARTIFACTS: tuple[str, ...] = ("config.json",)
MODEL_ARTIFACTS: tuple[str, ...] = ("model.zip", "vecnormalize.pkl")
#: Tags that name the source store's runs or processes; an imported run gets ``TAG_IMPORTED_FROM``.
# the per-episode table is not exported (its histories are): an imported run reads those
_DROPPED_TAGS = (schema.MLFLOW_PARENT_RUN_ID, schema.TAG_OWNER, schema.TAG_HEARTBEAT, schema.TAG_EPISODES_TABLE)
TAG_IMPORTED_FROM = f"{schema.TAG_PREFIX}imported_from"


@dataclass(frozen=True)
class TransferSummary:
    """What an export or import did: runs written (or created) and runs skipped as present."""

    written: int
    skipped: int = 0


def _history(client: Any, run_id: str, key: str) -> dict[str, list[Any]]:
    points = sorted(client.get_metric_history(run_id, key), key=lambda p: (p.step, p.timestamp))
    return {"step": [int(p.step) for p in points], "ts": [int(p.timestamp) for p in points],
            "value": [float(p.value) for p in points]}


def _record(client: Any, run: Any, models: bool, workdir: Path) -> dict[str, Any]:
    run_id = run.info.run_id
    # other metrics keep their last value only (their histories, e.g. train/*, serve MLflow's UI, not
    # the analysis), at step 0 and the run's end time
    when = int(run.info.end_time or run.info.start_time or 0)
    latest = {k: [0, when, float(v)] for k, v in run.data.metrics.items() if k not in HISTORY_KEYS}
    present = {a.path for a in client.list_artifacts(run_id)}
    wanted = [n for n in (*TEXT_ARTIFACTS, *(MODEL_ARTIFACTS if models else ())) if n in present]
    store.download_artifacts(client, run_id, wanted, workdir)
    return {
        "format": FORMAT,
        "source_run_id": run_id,
        "run_name": run.info.run_name,
        "start_time": run.info.start_time,
        "end_time": run.info.end_time,
        "tags": dict(run.data.tags),
        "params": dict(run.data.params),
        "latest": latest,
        "histories": {key: _history(client, run_id, key) for key in HISTORY_KEYS if key in run.data.metrics},
        "artifacts": {n: (workdir / n).read_text(encoding="utf-8") for n in wanted if n in TEXT_ARTIFACTS},
        "binary": {n: base64.b64encode((workdir / n).read_bytes()).decode("ascii")
                   for n in wanted if n in MODEL_ARTIFACTS},
    }


def exported_ids(paths: Sequence[Path]) -> set[str]:
    """The source run ids already in the export files ``paths`` (for an incremental export)."""
    return {r["source_run_id"] for p in paths for r in read_records(p)}


def export_runs(client: Any, experiment: str, path: Path, models: bool = False,
                progress: Callable[[int, int], None] | None = None, skip: set[str] | None = None) -> TransferSummary:
    """Write the FINISHED training runs of ``experiment`` to the gzip JSON-lines file ``path``
    (written to a temporary name first, so a failed export leaves no partial file), but those whose
    run id is in ``skip`` (exported before: ``skipped`` counts them). ``progress(done, total)`` is
    called after each run. ``BadInput`` when there is nothing to export."""
    exp = client.get_experiment_by_name(experiment)
    if exp is None or exp.lifecycle_stage == "deleted":
        raise BadInput(f"MLflow experiment '{experiment}' does not exist in this store; pass --experiment NAME.")
    runs = schema.search_all(client, exp.experiment_id,
                             schema.runs_filter({schema.TAG_KIND: schema.KIND_TRAIN}, finished=True))
    before = len(runs)
    runs = [r for r in runs if r.info.run_id not in (skip or set())]
    if not runs:
        raise BadInput(f"MLflow experiment '{experiment}' has no FINISHED training run to export"
                       + (f" that is not in the earlier exports ({before} are)." if before else "."))
    runs.sort(key=lambda r: (r.info.start_time or 0, r.info.run_id))
    partial = path.with_name(path.name + ".partial")
    with gzip.open(partial, "wt", encoding="utf-8", compresslevel=9) as out:
        for i, run in enumerate(runs, start=1):
            with tempfile.TemporaryDirectory(prefix="vlmrl-export-") as tmp:
                out.write(json.dumps(_record(client, run, models, Path(tmp)), separators=(",", ":")) + "\n")
            if progress is not None:
                progress(i, len(runs))
    partial.replace(path)
    return TransferSummary(len(runs), before - len(runs))


def format_problem(tag: object) -> str | None:
    """Why a record whose ``format`` field is ``tag`` cannot be read here, or None.

    Example:
        >>> format_problem(FORMAT) is None, format_problem("vlmrl-runs/7")
        (True, 'written by a newer vlmrl (format 7; this one reads up to 1): upgrade vlmrl')
        >>> format_problem("mlflow-export")
        'not a vlmrl run export (vlmrl-runs/1)'
    """
    if tag == FORMAT:
        return None
    name, _, version = str(tag).partition("/")
    if name == FORMAT_NAME and version.isdigit() and int(version) > FORMAT_VERSION:
        return f"written by a newer vlmrl (format {int(version)}; this one reads up to {FORMAT_VERSION}): upgrade vlmrl"
    return f"not a vlmrl run export ({FORMAT})"


def read_records(path: Path) -> Iterator[dict[str, Any]]:
    """The records of an export file, each checked for its format; ``BadInput`` for anything else."""
    try:
        with gzip.open(path, "rt", encoding="utf-8") as lines:
            for n, line in enumerate(lines, start=1):
                record = json.loads(line)
                problem = format_problem(record.get("format") if isinstance(record, dict) else None)
                if problem:
                    raise BadInput(f"{path}, line {n}: {problem}.")
                yield record
    except (OSError, EOFError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise BadInput(f"cannot read the run export {path}: {exc}.") from None


def _present(client: Any, experiment_id: str) -> tuple[set[tuple[str, str, str]], set[str]]:
    runs = schema.search_all(client, experiment_id,
                             schema.runs_filter({schema.TAG_KIND: schema.KIND_TRAIN}, finished=True))
    keys = {(r.data.tags.get(schema.TAG_ARM, ""), r.data.tags.get(schema.TAG_SEED, ""),
             r.data.tags.get(schema.TAG_CONFIG_HASH, "")) for r in runs}
    sources = {r.data.tags[TAG_IMPORTED_FROM] for r in runs if TAG_IMPORTED_FROM in r.data.tags}
    return keys, sources


def _create(client: Any, experiment_id: str, record: dict[str, Any]) -> None:
    from mlflow.entities import Metric

    tags = {k: v for k, v in record["tags"].items() if k not in _DROPPED_TAGS}
    tags[TAG_IMPORTED_FROM] = record["source_run_id"]
    run = client.create_run(experiment_id, start_time=record["start_time"], tags=tags,
                            run_name=record.get("run_name"))
    run_id = run.info.run_id
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
            files = []
            for name, text in record.get("artifacts", {}).items():
                (Path(tmp) / name).write_text(text, encoding="utf-8")
                files.append(Path(tmp) / name)
            for name, blob in record.get("binary", {}).items():
                (Path(tmp) / name).write_bytes(base64.b64decode(blob))
                files.append(Path(tmp) / name)
            store.log_artifacts(client, run_id, files)


def import_runs(client: Any, path: Path, experiment: str,
                progress: Callable[[int, int], None] | None = None) -> TransferSummary:
    """Create the runs of the export ``path`` in ``experiment`` (created if missing); runs already
    there are skipped. ``progress(done, total)`` after each record."""
    records = list(read_records(path))
    experiment_id = store.ensure_experiment(client, experiment)
    keys, sources = _present(client, experiment_id)
    written = skipped = 0
    for i, record in enumerate(records, start=1):
        tags = record["tags"]
        key = (tags.get(schema.TAG_ARM, ""), tags.get(schema.TAG_SEED, ""), tags.get(schema.TAG_CONFIG_HASH, ""))
        if key in keys or record["source_run_id"] in sources:
            skipped += 1
        else:
            _create(client, experiment_id, record)
            keys.add(key)
            written += 1
        if progress is not None:
            progress(i, len(records))
    return TransferSummary(written, skipped)
