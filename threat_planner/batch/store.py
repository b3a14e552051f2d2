"""The results folder: rows committed chunk by chunk, merged into ``results.parquet``.

Each finished chunk's rows become one part file ``parts/<id>.parquet``, written under a
temporary name and renamed into place, so a part is either whole or absent: a run killed
at any moment loses at most the chunks in flight. :meth:`Store.merge` gathers
``results.parquet`` and the parts, keeps each (task, sample) once, orders the rows as the
study's task list (whatever order they finished in), writes the table the same way and
then removes the parts it holds. ``study.json`` keeps the study the folder belongs to.
"""

from __future__ import annotations

import fcntl
import json
import os
from pathlib import Path
import uuid

from threat_planner.batch.study import Study
from threat_planner.batch.tasks import Task
from threat_planner.core.inputs.settings import PLANNER_SETTINGS
from threat_planner.errors import InputError

__all__ = ['RESULTS', 'Store', 'columns']

RESULTS = 'results.parquet'
PARTS = 'parts'
STUDY = 'study.json'
LOCK = '.lock'


def _pa():
    import pyarrow
    import pyarrow.parquet
    return pyarrow


def columns(study: Study) -> list[tuple[str, object]]:
    """Return the table's columns as (name, pyarrow type), in order."""
    pa = _pa()
    kinds = {float: pa.float64(), int: pa.int64(), bool: pa.bool_(), str: pa.string()}
    return ([('task', pa.string()), ('scenario', pa.string()), ('w', pa.float64()),
             ('method', pa.string())]
            + [(name, kinds[PLANNER_SETTINGS[name].kind]) for name, _ in study.settings]
            + [('plan', pa.string()), ('sample', pa.int64()), ('J', pa.float64()),
               ('J_L', pa.float64()), ('J_R', pa.float64()), ('J_planned', pa.float64()),
               ('feasible', pa.bool_()), ('total_ms', pa.float64()), ('error', pa.string()),
               ('path', pa.list_(pa.list_(pa.float64(), 3)))])


class Store:
    """The results folder of one study.

    Parameters
    ----------
    out : Path
        The folder (made if missing).
    study : Study
        Its study; a folder holding another study's results is refused.

    """

    def __init__(self, out: str | Path, study: Study) -> None:
        pa = _pa()
        self.out = Path(out)
        self.parts = self.out / PARTS
        self.schema = pa.schema(columns(study))
        fingerprint = study.fingerprint()
        try:
            self.parts.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f'--out: cannot make {self.out} ({exc.strerror})') from None
        # Held until this process ends (a kill releases it): one run writes at a time. A
        # POSIX record lock belongs to this process alone, not to forked workers.
        self._lock = open(self.out / LOCK, 'w')
        try:
            fcntl.lockf(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._lock.close()
            raise InputError(f'--out: another batch run is writing to {self.out}') from None
        marker = self.out / STUDY
        if marker.exists():
            try:
                held = json.loads(marker.read_text())
            except (OSError, ValueError):
                self.close()
                raise InputError(f'--out: {marker} is unreadable; use another folder'
                                 ) from None
            if held != fingerprint:
                field = next((k for k in fingerprint if held.get(k) != fingerprint[k]), '?')
                self.close()
                raise InputError(f'--out: {self.out} holds the results of another study '
                                 f'(its {field} differs); use another folder')
        else:
            _atomic(marker, lambda tmp: tmp.write_text(json.dumps(fingerprint, indent=1)))
        for stale in [*self.parts.glob('.*.tmp'), *self.out.glob('.*.tmp')]:
            stale.unlink(missing_ok=True)   # a write cut off by a kill

    def close(self) -> None:
        """Let another run use the folder."""
        self._lock.close()

    def done(self) -> set[str]:
        """Return the keys of the tasks whose rows are committed."""
        keys: set[str] = set()
        for f in self._sources():
            keys.update(_read(f, ['task']).column('task').to_pylist())
        return keys

    def commit(self, rows: list[dict]) -> Path:
        """Write one finished chunk's rows as a part file (whole or not at all)."""
        pa = _pa()
        table = pa.Table.from_pylist(rows, schema=self.schema)
        target = self.parts / f'{uuid.uuid4().hex}.parquet'
        _atomic(target, lambda tmp: pa.parquet.write_table(table, tmp))
        return target

    def merge(self, tasks: list[Task]):
        """Write ``results.parquet``: the study's rows, once each, in task order.

        Returns the table (a ``pyarrow.Table``).
        """
        pa = _pa()
        import numpy as np
        sources = self._sources()
        tables = [_read(f) for f in sources]
        table = pa.concat_tables([t.select(self.schema.names).cast(self.schema)
                                  for t in tables]) if tables else self.schema.empty_table()
        order = {t.key: t.index for t in tasks}
        index = np.array([order.get(k, -1) for k in table.column('task').to_pylist()])
        sample = np.array([-1 if s is None else s for s in table.column('sample').to_pylist()])
        keep = np.flatnonzero(index >= 0)
        keep = keep[np.lexsort((sample[keep], index[keep]))]
        if len(keep):
            pair = index[keep] * (sample.max() + 2) + sample[keep] + 1
            keep = keep[np.concatenate([[True], pair[1:] != pair[:-1]])]
        table = table.take(pa.array(keep, pa.int64()))
        _atomic(self.out / RESULTS, lambda tmp: pa.parquet.write_table(table, tmp))
        for f in sources:
            if f.parent == self.parts:
                f.unlink(missing_ok=True)
        return table

    def _sources(self) -> list[Path]:
        results = self.out / RESULTS
        return ([results] if results.exists() else []) + sorted(self.parts.glob('*.parquet'))


def _read(path: Path, cols: list[str] | None = None):
    return _pa().parquet.read_table(path, columns=cols)


def _atomic(target: Path, write) -> None:
    """Write through a temporary file beside ``target`` and rename it into place."""
    tmp = target.with_name(f'.{target.name}.{os.getpid()}.tmp')
    write(tmp)
    os.replace(tmp, target)
