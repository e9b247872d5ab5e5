"""The one table renderer: no cell text breaks a Markdown or LaTeX table."""

from __future__ import annotations

import re

import pandas as pd
from hypothesis import given
from hypothesis import strategies as st

from vlmrl_cli.core import tables

cells = st.text()  # any text: pipes, newlines, control characters, LaTeX specials, unicode
grids = st.integers(1, 4).flatmap(lambda n: st.tuples(st.lists(cells, min_size=n, max_size=n, unique=True),
                                                      st.lists(st.lists(cells, min_size=n, max_size=n), max_size=4)))
UNESCAPED_PIPE = re.compile(r"(?<!\\)\|")
UNESCAPED_AMP = re.compile(r"(?<!\\)&")
LATEX_SPECIALS = set("\\&%$#_{}~^|")
_ESCAPE_TOKENS = re.compile("|".join(re.escape(v) for v in sorted(tables.LATEX_ESCAPES.values(), key=len,
                                                                    reverse=True)))


@given(grids)
def test_markdown_keeps_one_line_and_the_same_cell_count_per_row(grid: tuple[list[str], list[list[str]]]) -> None:
    header, rows = grid
    md = tables.markdown(pd.DataFrame(rows, columns=header))
    lines = md.split("\n")
    assert len(lines) == len(rows) + 2
    assert lines[1] == "| " + " | ".join(["---"] * len(header)) + " |"
    for line in lines:
        assert line.startswith("| ") and line.endswith(" |") and line.isprintable()
        assert len(UNESCAPED_PIPE.findall(line)) == len(header) + 1


@given(cells)
def test_a_markdown_cell_keeps_its_visible_text(text: str) -> None:
    cell = tables.markdown_cell(text)
    assert cell.replace("\\|", "|") == tables.printable(text)


@given(grids, cells)
def test_latex_escapes_every_special_character(grid: tuple[list[str], list[list[str]]], caption: str) -> None:
    header, rows = grid
    tex = tables.latex(pd.DataFrame(rows, columns=header), caption)
    lines = tex.split("\n")
    assert len(lines) == len(rows) + 11 and all(line.isprintable() for line in lines)
    body = lines[6:7] + lines[8:8 + len(rows)]  # the header row and the data rows
    for line in body:
        assert line.endswith(r" \\")
        cells_ = UNESCAPED_AMP.split(line.removesuffix(r" \\"))
        assert len(cells_) == len(header)
        for c in cells_:
            assert not set(_ESCAPE_TOKENS.sub("", c)) & LATEX_SPECIALS, c


@given(cells)
def test_latex_escape_leaves_no_bare_special(text: str) -> None:
    escaped = tables.latex_escape(text)
    assert not set(_ESCAPE_TOKENS.sub("", escaped)) & LATEX_SPECIALS
    assert "\n" not in escaped


def test_latex_layout_options() -> None:
    df = pd.DataFrame({"a": ["1"], "b": ["2"]})
    tex = tables.latex(df, "C", label="tab:x", colspec="ll", setup=(r"\centering\scriptsize",), rules=tables.HLINES)
    assert tex.split("\n")[:6] == [r"\begin{table}[t]", r"\centering\scriptsize", r"\caption{C}", r"\label{tab:x}",
                                   r"\begin{tabular}{ll}", r"\hline"]
    assert tex.count(r"\hline") == 3 and r"\toprule" not in tex


def test_one_escape_map_for_both_old_writers() -> None:
    assert tables.latex_escape("~120 — 5^2 | x") == r"$\sim$120 -- 5\textasciicircum{}2 $|$ x"
