"""Small studies for the batch tests: scenario copies, a study file, and table comparisons."""

import os
from pathlib import Path
import shutil
import subprocess
import sys

import yaml

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / 'test' / 'data'
#: Columns that measure the run rather than the result.
TIMING = ('total_ms',)


def write_study(folder: Path, scenarios=('weak20_0', 'uniform20_0'), **fields) -> Path:
    """Copy the scenarios into ``folder/fields`` and write ``folder/study.yaml``."""
    (folder / 'fields').mkdir(parents=True, exist_ok=True)
    for name in scenarios:
        shutil.copy(DATA / f'{name}.yaml', folder / 'fields' / f'{name}.yaml')
    study = {'scenarios': ['fields/*.yaml'], **fields}
    path = folder / 'study.yaml'
    path.write_text(yaml.safe_dump(study))
    return path


def rows(table) -> list[dict]:
    """The table's rows without the timing columns, for comparing two runs."""
    return table.drop_columns(list(TIMING)).to_pylist()


def cli(*args, cwd=None, timeout=300):
    """Run ``threat-planner`` as a user does; the completed process."""
    return subprocess.run([sys.executable, '-m', 'threat_planner.cli', *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, cwd=cwd)


def descendants(pid: int) -> set[int]:
    """Return the ids of every living process below `pid` (read from /proc)."""
    parents = {}
    for entry in os.listdir('/proc'):
        if entry.isdigit():
            try:
                stat = Path(f'/proc/{entry}/stat').read_text()
            except OSError:
                continue
            parents[int(entry)] = int(stat.rsplit(')', 1)[1].split()[1])
    out, frontier = set(), {pid}
    while frontier:
        frontier = {p for p, pp in parents.items() if pp in frontier} - out
        out |= frontier
    return out
