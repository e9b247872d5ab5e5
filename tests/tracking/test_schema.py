"""The tracking contract: key spellings, run filters and the one paginated search."""

from __future__ import annotations

from typing import Any

from vlmrl_cli.tracking import schema


class _Page(list):  # MLflow's PagedList: a list with the next page's token
    def __init__(self, items: list[int], token: str | None) -> None:
        super().__init__(items)
        self.token = token


class _Client:
    """Answers ``search_runs`` with ``n`` runs in pages of ``max_results``, recording each call."""

    def __init__(self, n: int) -> None:
        self.runs = list(range(n))
        self.calls: list[dict[str, Any]] = []

    def search_runs(self, experiment_ids: list[str], filter_string: str, max_results: int,
                    page_token: str | None) -> _Page:
        self.calls.append({"ids": experiment_ids, "filter": filter_string, "max": max_results, "token": page_token})
        start = int(page_token or 0)
        end = start + max_results
        return _Page(self.runs[start:end], str(end) if end < len(self.runs) else None)


def test_search_all_follows_every_page() -> None:
    client = _Client(7)
    assert schema.search_all(client, "3", "f", page_size=3) == list(range(7))
    assert [c["token"] for c in client.calls] == [None, "3", "6"]
    assert all(c["ids"] == ["3"] and c["filter"] == "f" and c["max"] == 3 for c in client.calls)


def test_search_all_of_nothing_is_one_call() -> None:
    client = _Client(0)
    assert schema.search_all(client, "1", "f") == [] and len(client.calls) == 1
    assert client.calls[0]["max"] == schema.PAGE_SIZE


def test_runs_filter_joins_tags_and_status() -> None:
    assert schema.runs_filter({schema.TAG_KIND: "calibration", schema.TAG_CONFIG_HASH: "abc"}) == (
        "tags.`vlmrl.kind` = 'calibration' and tags.`vlmrl.config_hash` = 'abc'")
    assert schema.runs_filter({schema.TAG_REPORT_KEY: "k"}, finished=True) == (
        "tags.`vlmrl.report.key` = 'k' and attributes.status = 'FINISHED'")


def test_vlmrl_tags_share_the_prefix_and_keys_are_distinct() -> None:
    tags = {k: v for k, v in vars(schema).items() if k.startswith("TAG_") and k != "TAG_PREFIX"}
    assert all(v.startswith(schema.TAG_PREFIX) for v in tags.values())
    metrics = [v for k, v in vars(schema).items() if k.startswith("METRIC_")]
    assert len(set(tags.values())) == len(tags) and len(set(metrics)) == len(metrics)
