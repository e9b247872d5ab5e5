"""tests/conftest.py's order of files for pytest-xdist: the files with the most slow tests first."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, cast

import pytest

from tests.conftest import heaviest_files_first


@dataclass
class _Item:
    nodeid: str
    marks: set[str] = field(default_factory=set)

    def get_closest_marker(self, name: str) -> Any:
        return name if name in self.marks else None


def test_files_with_more_slow_tests_go_first_and_keep_their_tests_together_in_order() -> None:
    items = [_Item("a.py::t1"), _Item("b.py::t1", {"slow"}), _Item("a.py::t2"), _Item("c.py::t1", {"slow"}),
             _Item("c.py::t2", {"slow"}), _Item("b.py::t2"), _Item("d.py::t1")]
    ordered = heaviest_files_first(cast(list[pytest.Item], items))
    assert [i.nodeid for i in cast(list[_Item], ordered)] == [
        "c.py::t1", "c.py::t2", "b.py::t1", "b.py::t2", "a.py::t1", "a.py::t2", "d.py::t1"]
