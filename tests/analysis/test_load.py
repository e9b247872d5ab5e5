"""Episodes load the same from a run's per-episode table as from its metric histories."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from vlmrl_cli.analysis.load import _episodes, check_one_task
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.sweep.worker import write_episodes_table
from vlmrl_cli.tracking import schema, store


def test_the_table_and_the_histories_give_identical_frames_and_a_missing_table_falls_back(tmp_path: Path) -> None:
    client = store.connect(f"sqlite:///{tmp_path}/m.db")
    run_id = client.create_run(store.ensure_experiment(client, "x")).info.run_id
    episodes = [{"timestep": float(t), schema.METRIC_NATIVE_RETURN: -200.0 + i / 3,
                 schema.METRIC_LENGTH: 200.0 - i, schema.METRIC_SUCCESS: float(i % 2),
                 schema.METRIC_SHAPED_RETURN: 0.1 * i - 7.0}
                for i, t in enumerate([200, 400, 400, 590, 800])]  # two episodes end at one step
    logger = store.BatchLogger(client, run_id)
    for e in episodes:
        logger.log({k: e[k] for k in schema.EPISODE_METRICS}, step=int(e["timestep"]))
    logger.flush()
    write_episodes_table(episodes, tmp_path / schema.EPISODES_TABLE)
    store.log_artifacts(client, run_id, [tmp_path / schema.EPISODES_TABLE])

    from_table = _episodes(client, run_id, schema.EPISODES_TABLE)
    from_histories = _episodes(client, run_id, None)
    pd.testing.assert_frame_equal(from_table, from_histories, check_exact=True)
    assert from_table["native_return"].tolist() == [e[schema.METRIC_NATIVE_RETURN] for e in episodes]
    # a tag naming a table the run does not hold (an imported run) falls back to the histories
    pd.testing.assert_frame_equal(_episodes(client, run_id, "missing.csv"), from_histories, check_exact=True)


class _Run:
    def __init__(self, task: str | None) -> None:
        self.data = type("D", (), {"tags": {} if task is None else {"vlmrl.task": task}})()


def test_a_report_never_mixes_tasks_and_old_runs_are_mountain_car() -> None:
    assert check_one_task([_Run(None), _Run("mountain-car")], "e") == "mountain-car"  # untagged runs predate tasks
    with pytest.raises(BadInput, match=r"mixes tasks \(acrobot, mountain-car\)"):
        check_one_task([_Run(None), _Run("acrobot")], "e")
    assert check_one_task([_Run("acrobot")], "e") == "acrobot"
