"""Retrain recorded runs from their ``config.json`` and compare their learning curves bit for bit
(`vlmrl verify`): a rebuilt config that hashes differently is refused."""

from __future__ import annotations

import json
import random
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.core.numeric_pin import pin_record
from vlmrl_cli.core.provenance import cpu_paths
from vlmrl_cli.tracking import schema
from vlmrl_cli.training.config import TrainJob

if TYPE_CHECKING:
    from vlmrl_cli.tasks.base import TaskLookup

#: The tags that say which numeric path a run computed on (printed beside each verdict), and their short names.
PATH_TAGS = {schema.TAG_PIN: "pin", schema.TAG_PIN_ENV: "env", f"{schema.TAG_CPU_PREFIX}numpy_simd": "numpy",
             f"{schema.TAG_CPU_PREFIX}torch": "torch", f"{schema.TAG_CPU_PREFIX}model": "cpu"}


@dataclass(frozen=True)
class RecordedRun:
    """What verifying a finished training run needs: its config, tags and native returns."""

    run_id: str
    name: str
    config: dict[str, Any]
    tags: dict[str, str]
    native_returns: list[float]
    wall_s: float | None = None

    @property
    def seed(self) -> int:
        return int(self.config.get("seed", self.tags.get(schema.TAG_SEED, -1)))

    @property
    def arm(self) -> str:
        return str(self.config.get("arm", {}).get("name", self.tags.get(schema.TAG_ARM, "?")))


@dataclass(frozen=True)
class Outcome:
    """One run's verdict: ``identical``, or the first episode (0-based) where the curves part."""

    run: RecordedRun
    returns: list[float]
    wall_s: float

    @property
    def first_difference(self) -> int | None:
        return first_difference(self.run.native_returns, self.returns)

    @property
    def identical(self) -> bool:
        return self.first_difference is None

    def verdict(self) -> str:
        k = self.first_difference
        if k is None:
            return f"identical ({len(self.returns)} episodes)"
        recorded, here = self.run.native_returns, self.returns
        both = f"recorded {recorded[k]!r}, here {here[k]!r}" if k < min(len(recorded), len(here)) else (
            f"recorded {len(recorded)} episodes, here {len(here)}")
        return f"differs from episode {k} ({both})"

    def lines(self, here_tags: dict[str, str]) -> list[str]:
        """The verdict and the recorded numeric path; this process's too where they differ."""
        run = self.run
        lines = [f"{run.run_id[:12]}  {run.name}: {self.verdict()} in {self.wall_s:.0f} s",
                 f"    recorded: {describe_paths(run.tags)}"]
        if not self.identical or run.tags.get(schema.TAG_PIN) != here_tags[schema.TAG_PIN]:
            lines.append(f"    here:     {describe_paths(here_tags)}")
        return lines


def first_difference(recorded: Sequence[float], here: Sequence[float]) -> int | None:
    """The first index where two learning curves differ (a missing episode counts), or None.

    Example:
        >>> first_difference([1.0, 2.0], [1.0, 2.0]), first_difference([1.0, 2.0], [1.0, 3.0])
        (None, 1)
        >>> first_difference([1.0, 2.0], [1.0])
        1
    """
    for i, (a, b) in enumerate(zip(recorded, here, strict=False)):
        if a != b:
            return i
    return None if len(recorded) == len(here) else min(len(recorded), len(here))


def _from_export(record: dict[str, Any]) -> RecordedRun | None:
    text = record.get("artifacts", {}).get("config.json")
    history = record.get("histories", {}).get(schema.METRIC_NATIVE_RETURN)
    if text is None or history is None:
        return None
    # the export keeps each history sorted by (step, timestamp): the order the episodes ended in
    wall = record.get("latest", {}).get(schema.METRIC_WALL_S)
    return RecordedRun(run_id=str(record["source_run_id"]), name=str(record.get("run_name") or record["source_run_id"]),
                       config=json.loads(text), tags=dict(record.get("tags", {})),
                       native_returns=[float(v) for v in history["value"]],
                       wall_s=float(wall[2]) if wall is not None else None)


def runs_of_export(path: Path) -> list[RecordedRun]:
    """The training runs of an export file that can be verified (config and returns recorded)."""
    from vlmrl_cli.tracking.transfer import read_records

    if not path.is_file():
        raise BadInput(f"there is no export file {path}; write one with `vlmrl export --out FILE`.")
    runs = [r for r in (_from_export(rec) for rec in read_records(path)) if r is not None]
    if not runs:
        raise BadInput(f"{path} holds no training run with a config.json and its episode returns to verify.")
    return runs


def runs_of_store(client: Any, experiment: str) -> list[RecordedRun]:
    """The FINISHED training runs of ``experiment`` in a tracking store, with their configs."""
    import tempfile

    from vlmrl_cli.tracking import store

    runs = []
    for run in schema.finished_train_runs(client, experiment):
        run_id = run.info.run_id
        with tempfile.TemporaryDirectory(prefix="vlmrl-verify-") as tmp:
            if "config.json" not in {a.path for a in client.list_artifacts(run_id)}:
                continue
            store.download_artifacts(client, run_id, ["config.json"], Path(tmp))
            config = json.loads((Path(tmp) / "config.json").read_text(encoding="utf-8"))
        points = sorted(client.get_metric_history(run_id, schema.METRIC_NATIVE_RETURN),
                        key=lambda p: (p.step, p.timestamp))
        runs.append(RecordedRun(run_id=run_id, name=run.info.run_name or run_id, config=config,
                                tags=dict(run.data.tags), native_returns=[float(p.value) for p in points],
                                wall_s=run.data.metrics.get(schema.METRIC_WALL_S)))
    if not runs:
        raise BadInput(f"MLflow experiment '{experiment}' has no FINISHED training run to verify.")
    return runs


def recorded_runs(source: Path | None, experiment: str, tracking_uri: str | None) -> tuple[list[RecordedRun], str]:
    """The runs of the export file ``source``, else of ``experiment`` in the store, and where they are."""
    if source is not None:
        return runs_of_export(source), str(source)
    from vlmrl_cli.core.names import experiment_problem, tracking_uri_problem
    from vlmrl_cli.tracking import access, store

    problem = experiment_problem(experiment) or tracking_uri_problem(tracking_uri)
    if problem:
        raise BadInput(problem + ".")
    access.check_store(tracking_uri, write=False, existing=True)  # before MLflow loads (a second)
    return runs_of_store(store.connect_existing(tracking_uri), experiment), f"experiment '{experiment}'"


def choose(runs: Sequence[RecordedRun], *, run_ids: Iterable[str] = (), seeds: Iterable[int] = (),
           arms: Iterable[str] = (), sample: int | None = None, sample_seed: int = 0,
           source: str = "the source") -> list[RecordedRun]:
    """The runs to verify: those named by id (a prefix of 8+ characters will do), else those of the
    given seeds and arms; then ``sample`` of them drawn with ``sample_seed``, in recorded order.

    Example:
        >>> rs = [RecordedRun(f"id{i}", f"r{i}", {"seed": i % 2, "arm": {"name": "a"}}, {}, []) for i in range(6)]
        >>> [r.run_id for r in choose(rs, seeds=[1])]
        ['id1', 'id3', 'id5']
        >>> [r.run_id for r in choose(rs, sample=2)] == [r.run_id for r in choose(rs, sample=2)]
        True
        >>> choose(rs, sample=9, source="runs.jsonl.gz")
        Traceback (most recent call last):
        ...
        vlmrl_cli.core.errors.BadInput: --sample 9 is more than the 6 run(s) runs.jsonl.gz holds; pass --sample 6 ...
    """
    ids, wanted_seeds, wanted_arms = list(run_ids), set(seeds), set(arms)
    if ids:
        picked = []
        for wanted in ids:
            hits = [r for r in runs if r.run_id == wanted or (len(wanted) >= 8 and r.run_id.startswith(wanted))]
            if len(hits) != 1:
                raise BadInput(f"--run-id {wanted}: {'no run' if not hits else f'{len(hits)} runs'} of the source "
                               "match it; copy an id from `vlmrl export`'s source or the MLflow UI.")
            picked.append(hits[0])
    else:
        picked = [r for r in runs if (not wanted_seeds or r.seed in wanted_seeds)
                  and (not wanted_arms or r.arm in wanted_arms)]
    if not picked:
        raise BadInput("no run of the source matches --seed/--arm; drop them to verify any run.")
    if sample is not None and sample > len(picked):
        among = "" if len(picked) == len(runs) else f", {len(picked)} of them of the runs asked for"
        raise BadInput(f"--sample {sample} is more than the {len(runs)} run(s) {source} holds{among}; pass --sample "
                       f"{len(picked)} or fewer, or leave it out to verify all {len(picked)}.")
    if sample is not None and sample < len(picked):
        keep = set(random.Random(sample_seed).sample(range(len(picked)), sample))
        picked = [r for i, r in enumerate(picked) if i in keep]
    return picked


def job_of(config: Mapping[str, Any], tags: Mapping[str, str], tasks: TaskLookup, where: str) -> TrainJob:
    """The ``TrainJob`` a run's ``config.json`` describes (response cache off), its task resolved by
    ``tasks``; ``BadInput`` naming ``where`` when it cannot be rebuilt."""
    from vlmrl_cli.shaping.arms import ARMS
    from vlmrl_cli.shaping.config import ShapingConfig
    from vlmrl_cli.tasks.registry import recorded_task
    from vlmrl_cli.training.presets import PPOConfig
    from vlmrl_cli.training.validation import validate_as
    from vlmrl_cli.vlm.config import VLMConfig

    try:
        arm = ARMS[config["arm"]["name"]]
        task = recorded_task(config.get("task"))
        plugin = tasks(task)
        ppo = validate_as(PPOConfig, dict(config["ppo"]))
        shaping = (validate_as(ShapingConfig, dict(config["shaping"])) if "shaping" in config
                   else plugin.shaping_for(ShapingConfig()))
        vlm = (validate_as(VLMConfig, {**config["vlm"], "use_cache": False}) if "vlm" in config
               else VLMConfig(use_cache=False))
        return TrainJob(arm=arm, seed=int(config["seed"]), preset=str(config["preset"]), ppo=ppo, vlm=vlm,
                        shaping=shaping, regime=tags.get(schema.TAG_REGIME), task=task, plugin=plugin)
    except (KeyError, TypeError, ValueError, BadInput) as exc:
        raise BadInput(f"{where}: its config.json cannot be rebuilt here ({exc}).") from None


def rebuild_job(run: RecordedRun, tasks: TaskLookup) -> TrainJob:
    """The ``TrainJob`` that trained ``run``; ``BadInput`` when it rebuilds with another config hash."""
    job = job_of(run.config, run.tags, tasks, f"run {run.run_id} ({run.name})")
    recorded = run.config.get("config_hash") or run.tags.get(schema.TAG_CONFIG_HASH)
    if job.config_hash != recorded:
        raise BadInput(f"run {run.run_id} ({run.name}): rebuilt here its config hashes {job.config_hash}, "
                       f"not {recorded}: this version of vlmrl would train another experiment.")
    return job


def verify_run(run: RecordedRun, tasks: TaskLookup) -> Outcome:
    """Retrain ``run`` in this process and compare its native returns with the recorded ones."""
    import time

    from vlmrl_cli.training.trace import native_returns

    job = rebuild_job(run, tasks)
    start = time.perf_counter()
    returns = native_returns(job)
    return Outcome(run=run, returns=returns, wall_s=time.perf_counter() - start)


def here_paths() -> dict[str, str]:
    """This process's numeric path, keyed like ``PATH_TAGS``."""
    record, paths = pin_record(), cpu_paths()
    values = (record["pin"], record["pin.env"], paths["numpy_simd"], paths["torch"], record["cpu.model"])
    return dict(zip(PATH_TAGS, values, strict=True))


def describe_paths(tags: dict[str, str]) -> str:
    """A run's numeric path in one line (``unrecorded`` for tags an older run lacks)."""
    return "; ".join(f"{short} {tags.get(t, 'unrecorded')}" for t, short in PATH_TAGS.items())


def verify_many(runs: Sequence[RecordedRun], tasks: TaskLookup, workers: int = 1) -> Iterator[Outcome]:
    """Verify ``runs`` in ``workers`` spawned processes, yielding each outcome as it finishes."""
    if workers <= 1:
        yield from (verify_run(run, tasks) for run in runs)
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as pool:
        for fut in as_completed([pool.submit(verify_run, run, tasks) for run in runs]):
            yield fut.result()
