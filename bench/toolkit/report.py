"""Markdown tables and the result files of the suites."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Iterable, Sequence

from bench.toolkit.repo import RESULTS


def md_table(head: Sequence[str], rows: Iterable[Sequence[object]], align: str = ''
             ) -> list[str]:
    """Return the lines of a Markdown table.

    Parameters
    ----------
    head : sequence of str
        Column titles.
    rows : iterable of sequences
        Cells, already formatted (``str()`` is applied).
    align : str
        One letter a column, ``'l'`` or ``'r'`` (right-aligned, ``---:``); left if short.
    """
    rule = ['---:' if align[i:i + 1] == 'r' else '---' for i in range(len(head))]
    return (['| ' + ' | '.join(head) + ' |', '|' + '|'.join(rule) + '|']
            + ['| ' + ' | '.join(map(str, row)) + ' |' for row in rows])


def publish(lines: Sequence[str], out: Path) -> str:
    """Write the lines (one newline each) to `out`, print them and return the text."""
    text = '\n'.join(lines) + '\n'
    out.write_text(text)
    print(text, end='')
    return text


def append_section(out: Path, heading: str, table: Sequence[str]) -> None:
    """Append ``## heading`` and a table to the Markdown file `out`."""
    with open(out, 'a') as f:
        f.write('\n'.join([f'\n## {heading}\n', *table]) + '\n')


def write_results(stem: str, data: dict, markdown: str) -> None:
    """Write ``bench/results/<stem>.json`` and ``<stem>.md``."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f'{stem}.json').write_text(json.dumps(data, indent=2, sort_keys=True) + '\n')
    (RESULTS / f'{stem}.md').write_text(markdown.rstrip() + '\n')
