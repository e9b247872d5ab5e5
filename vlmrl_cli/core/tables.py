"""The one table renderer: GitHub Markdown and LaTeX from string cells, with one escape map, so a
cell holding ``|``, a newline or a LaTeX special never breaks its table (pandas' ``to_latex``
escapes less, and its ``to_markdown`` needs ``tabulate``)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import pandas as pd

#: Each character LaTeX would read as markup, and the few non-ASCII symbols our tables use,
#: spelled so that pdflatex prints them as text.
LATEX_ESCAPES: dict[str, str] = {
    "\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_",
    "{": r"\{", "}": r"\}", "~": r"$\sim$", "^": r"\textasciicircum{}", "|": r"$|$",
    "Δ": r"$\Delta$", "Φ": r"$\Phi$", "→": r"$\rightarrow$", "−": r"$-$", "—": "--",
}
BOOKTABS = (r"\toprule", r"\midrule", r"\bottomrule")
HLINES = (r"\hline", r"\hline", r"\hline")


def printable(text: str) -> str:
    """``text`` on one line: whitespace runs folded to one space, unprintables spelled as escapes."""
    flat = " ".join(text.split())
    return "".join(ch if ch.isprintable() else ch.encode("unicode_escape").decode("ascii") for ch in flat)


def markdown_cell(value: object) -> str:
    """One Markdown table cell: ``printable`` with ``|`` escaped."""
    return printable(str(value)).replace("|", "\\|")


def markdown_rows(header: Sequence[object], rows: Iterable[Sequence[object]]) -> list[str]:
    """The lines of a GitHub Markdown table: header, rule, one line per row.

    Example:
        >>> print("\\n".join(markdown_rows(["a", "b"], [[1, "x|y"]])))
        | a | b |
        | --- | --- |
        | 1 | x\\|y |
    """
    def line(cells: Iterable[object]) -> str:
        return "| " + " | ".join(markdown_cell(c) for c in cells) + " |"

    return [line(header), line("---" for _ in header), *(line(r) for r in rows)]


def markdown(df: pd.DataFrame) -> str:
    """``df`` as a GitHub Markdown table (its columns as the header, no index, no final newline)."""
    return "\n".join(markdown_rows(list(df.columns), df.itertuples(index=False)))


def latex_escape(text: str) -> str:
    """``printable`` text with every character of ``LATEX_ESCAPES`` replaced."""
    return "".join(LATEX_ESCAPES.get(ch, ch) for ch in printable(text))


def latex(
    df: pd.DataFrame,
    caption: str,
    *,
    label: str | None = None,
    colspec: str | None = None,
    setup: Sequence[str] = (r"\centering", r"\small"),
    rules: tuple[str, str, str] = BOOKTABS,
) -> str:
    """``df`` as a ``table`` float holding a ``tabular``, every cell and the caption escaped;
    ``colspec`` defaults to ``l`` then ``r``s, ``rules`` (top, header, bottom) to ``BOOKTABS``.
    """
    top, mid, bottom = rules
    spec = colspec if colspec is not None else "l" + "r" * (len(df.columns) - 1)
    lines = [r"\begin{table}[t]", *setup, f"\\caption{{{latex_escape(caption)}}}"]
    if label is not None:
        lines.append(f"\\label{{{label}}}")
    lines += [f"\\begin{{tabular}}{{{spec}}}", top, " & ".join(latex_escape(str(c)) for c in df.columns) + r" \\", mid]
    lines += [" & ".join(latex_escape(str(v)) for v in row) + r" \\" for row in df.itertuples(index=False)]
    lines += [bottom, r"\end{tabular}", r"\end{table}"]
    return "\n".join(lines)
