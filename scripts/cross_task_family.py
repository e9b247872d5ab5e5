"""The cross-task primary family (``vlmrl_cli.study.cross_task``) from the committed studies'
regime maps: each task's hybrid vs baseline and hybrid vs kinematic, Holm across the four tasks.
Writes ``results/compare/primary_family.md`` and ``.csv``; trains and reads no store.

    python scripts/cross_task_family.py
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from vlmrl_cli.study.cross_task import TASK_SCALED_STUDIES as STUDIES
from vlmrl_cli.study.cross_task import family_from_files, to_markdown


def main() -> None:
    df = family_from_files({t: Path(d) for t, d in STUDIES.items()})
    out = Path("results/compare")
    df.to_csv(out / "primary_family.csv", index=False)
    text = ("# The cross-task primary family (SIMULATED VLM)\n\n"
            "Drawn by `python scripts/cross_task_family.py` from each study's `regime_map.csv` (main regime): "
            + ", ".join(f"{t} `{d}`" for t, d in STUDIES.items()) + ".\n\n" + to_markdown(df) + "\n")
    (out / "primary_family.md").write_text(text, encoding="utf-8")
    print(text)


if __name__ == "__main__":
    pd.set_option("display.width", 200)
    main()
