"""The study manifest's record of earlier invocations (a resumed study)."""

from __future__ import annotations

from vlmrl_cli.study.outputs import earlier_invocations


def _manifest(commit: str, trained: int, history: list[dict[str, object]] | None = None) -> dict[str, object]:
    out: dict[str, object] = {"experiment": "vlmrl-study", "tracking_uri": "sqlite:///s.db", "git_commit": commit,
                              "runs_trained_now": trained, "wall_s": 1.0, "regimes": ["dropped"]}
    if history is not None:
        out["earlier_invocations"] = history
    return out


def test_history_chains_oldest_first_and_keeps_only_the_invocation_fields() -> None:
    first = earlier_invocations(_manifest("a", 170), "vlmrl-study", "sqlite:///s.db")
    assert first == [{"git_commit": "a", "runs_trained_now": 170, "wall_s": 1.0}]
    second = earlier_invocations(_manifest("b", 0, first), "vlmrl-study", "sqlite:///s.db")
    assert [h["git_commit"] for h in second] == ["a", "b"]


def test_a_manifest_of_another_store_or_experiment_is_not_carried() -> None:
    assert earlier_invocations(_manifest("a", 3), "vlmrl-study", "sqlite:///other.db") == []
    assert earlier_invocations(_manifest("a", 3), "other", "sqlite:///s.db") == []


def test_anything_but_a_manifest_gives_no_history() -> None:
    previous: object
    for previous in (None, [], "text", 3):
        assert earlier_invocations(previous, "vlmrl-study", "sqlite:///s.db") == []
