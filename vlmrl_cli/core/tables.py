"""The one table renderer: GitHub Markdown and LaTeX from string cells, with one escape map.

Every table vlmrl writes (Table 1, Table 2, the claims, attribution, hacking, calibration and
study tables, the report's run list) goes through here, so a cell that holds a ``|``, a newline,
a control character or a LaTeX special never breaks its table. Written by hand: pandas'
``to_markdown`` needs ``tabulate``, and its ``to_latex`` escapes less than we need.
"""

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
    """Text made safe to show on one line: whitespace runs (newlines included) folded to one
    space, control and other unprintable characters (a random model's garbage) spelled as
    escapes such as ``\\x08``.

    Example:
        >>> printable("BOTTOM\\n\\x08ok")
        'BOTTOM \\\\x08ok'
    """
    flat = " ".join(text.split())
    return "".join(ch if ch.isprintable() else ch.encode("unicode_escape").decode("ascii") for ch in flat)


def markdown_cell(value: object) -> str:
    """One Markdown table cell: ``printable`` with ``|`` escaped.

    Example:
        >>> markdown_cell("a|b\\nc")
        'a\\\\|b c'
    """
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
    """``printable`` text with every character of ``LATEX_ESCAPES`` replaced.

    Example:
        >>> latex_escape("ΔΦ = 0.0 (LEFT_SLOPE)")
        '$\\\\Delta$$\\\\Phi$ = 0.0 (LEFT\\\\_SLOPE)'
    """
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
    """``df`` as a ``table`` float holding a ``tabular`` (no final newline); every cell and the
    caption escaped with ``latex_escape``.

    ``colspec``: the tabular's column spec (default: the first column left-aligned, the others
    right-aligned); ``setup``: the lines before the caption; ``rules``: the top, header and bottom
    rules (``BOOKTABS`` needs ``\\usepackage{booktabs}``; ``HLINES`` needs nothing).

    Example:
        >>> print(latex(pd.DataFrame({"arm": ["a_1"], "steps": ["50%"]}), "Steps & more"))
        \\begin{table}[t]
        \\centering
        \\small
        \\caption{Steps \\& more}
        \\begin{tabular}{lr}
        \\toprule
        arm & steps \\\\
        \\midrule
        a\\_1 & 50\\% \\\\
        \\bottomrule
        \\end{tabular}
        \\end{table}
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
