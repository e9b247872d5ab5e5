"""The claim rule: who trains a job when several sweeps (or retries) create runs for it."""

from __future__ import annotations

import os
import subprocess
import sys

from hypothesis import given
from hypothesis import strategies as st

from vlmrl_cli.sweep import leases
from vlmrl_cli.sweep.leases import Liveness, RunRecord, decide, is_stale

HOST = "node-a"


def _live(now: float = 1000.0, dead: frozenset[int] = frozenset()) -> Liveness:
    return Liveness(now=now, stale_after_s=300.0, host=HOST, pid_alive=lambda pid: pid not in dead)


def _run(run_id: str, start_ms: int, status: str = "RUNNING", heartbeat: float | None = 990.0,
         owner: str | None = f"{HOST}:1", parent: str | None = "sweep-1") -> RunRecord:
    return RunRecord(run_id, status, start_ms, heartbeat, owner, parent)


def test_a_fresh_heartbeat_of_a_living_process_is_live() -> None:
    assert not is_stale(_run("a", 0), _live())


def test_an_old_heartbeat_is_stale_even_on_another_host() -> None:
    assert is_stale(_run("a", 0, heartbeat=600.0, owner="node-b:1"), _live())
    assert not is_stale(_run("a", 0, heartbeat=701.0, owner="node-b:1"), _live())


def test_a_dead_owner_on_this_host_is_stale_at_once() -> None:
    assert is_stale(_run("a", 0, owner=f"{HOST}:42"), _live(dead=frozenset({42})))
    # the same pid on another host says nothing about that host
    assert not is_stale(_run("a", 0, owner="node-b:42"), _live(dead=frozenset({42})))


def test_a_run_without_heartbeat_predates_heartbeats_and_is_stale() -> None:
    assert is_stale(_run("a", 0, heartbeat=None), _live())


def test_the_earliest_live_run_wins_and_the_later_one_loses() -> None:
    first, second = _run("b", 100, parent="s1"), _run("a", 200, parent="s2")
    assert decide(first, [first, second], _live()).won
    lost = decide(second, [first, second], _live())
    assert not lost.won and "claimed by live run b" in lost.reason


def test_a_tie_in_start_time_is_broken_by_run_id() -> None:
    a, b = _run("a", 100, parent="s1"), _run("b", 100, parent="s2")
    assert decide(a, [a, b], _live()).won
    assert not decide(b, [a, b], _live()).won


def test_a_finished_run_beats_every_claimant() -> None:
    done, own = _run("z", 0, status="FINISHED"), _run("a", 500)
    decision = decide(own, [done, own], _live())
    assert not decision.won and "already FINISHED" in decision.reason


def test_stale_runs_are_superseded_not_obeyed() -> None:
    dead = _run("old", 0, heartbeat=10.0, owner="node-b:7", parent="s0")
    own = _run("new", 500)
    decision = decide(own, [dead, own], _live())
    assert decision.won and decision.superseded == ("old",)


def test_a_retry_supersedes_the_attempt_its_own_sweep_dispatched_before() -> None:
    """Ray retries a task only after its worker died: the earlier attempt of the same sweep is
    dead even when its heartbeat, written on another machine, still looks fresh."""
    attempt1 = _run("try1", 100, owner="node-b:9", parent="s1")
    attempt2 = _run("try2", 900, owner="node-c:3", parent="s1")
    decision = decide(attempt2, [attempt1, attempt2], _live())
    assert decision.won and decision.superseded == ("try1",)


def test_failed_and_killed_runs_do_not_compete() -> None:
    own = _run("b", 500)
    others = [_run("a", 0, status="FAILED"), _run("c", 1, status="KILLED")]
    assert decide(own, [*others, own], _live()) == leases.Decision(True, "")


records = st.builds(
    RunRecord,
    run_id=st.text("abcdef", min_size=1, max_size=4),
    status=st.sampled_from(["RUNNING", "FINISHED", "FAILED"]),
    start_ms=st.integers(0, 10),
    heartbeat=st.one_of(st.none(), st.floats(500.0, 1000.0)),
    owner=st.sampled_from([None, f"{HOST}:1", f"{HOST}:2", "node-b:1"]),
    parent=st.sampled_from([None, "s1", "s2"]),
)


@given(st.lists(records, min_size=1, max_size=6, unique_by=lambda r: r.run_id))
def test_at_most_one_claimant_wins_whatever_the_runs(runs: list[RunRecord]) -> None:
    """Every RUNNING run applies the rule to the same rows; at most one of them trains, and none
    trains while a FINISHED run exists. (Retries of one sweep are excluded: one dispatch has one
    live attempt at a time, which Ray guarantees, not the store.)"""
    by_parent: dict[str | None, RunRecord] = {}
    for r in runs:
        by_parent.setdefault(r.parent, r)
    rows = [r for r in runs if r.parent is None or by_parent[r.parent] is r]
    live = _live(dead=frozenset({2}))
    claimants = [r for r in rows if r.status == "RUNNING" and not is_stale(r, live)]
    winners = [r for r in claimants if decide(r, rows, live).won]
    assert len(winners) <= 1
    if any(r.status == "FINISHED" for r in rows):
        assert winners == []


def test_pid_alive_sees_a_dead_and_a_reaped_process() -> None:
    assert leases.pid_alive(os.getpid())
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    assert not leases.pid_alive(child.pid)


def test_pid_alive_calls_an_unreaped_child_dead() -> None:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    try:
        for _ in range(200):  # until the child has exited (a zombie until we wait for it)
            if not leases.pid_alive(child.pid):
                break
            import time

            time.sleep(0.05)
        assert not leases.pid_alive(child.pid)
    finally:
        child.wait()
