"""The README's command for examples/geo, run once for the export tests."""

import contextlib
import io
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from threat_planner.cli.main import main

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / 'examples' / 'geo'


def readme_command() -> list[str]:
    """Return the README's one command for the example (its exports go to examples/geo)."""
    text = (REPO / 'README.md').read_text()
    line = next(ln for ln in text.splitlines() if 'examples/geo/valley.yaml' in ln
                and ln.lstrip().startswith('threat-planner plan'))
    return line.split()[1:]


@pytest.fixture(scope='session')
def example_run(tmp_path_factory):
    """Run the README command with its files in a temporary folder, and --json beside them.

    Returns files (by suffix), the --json summary, the exported points in [lat, lon, h]
    and the command's output.
    """
    out = tmp_path_factory.mktemp('example')
    args = readme_command()
    files = {}
    for flag in ('--qgc', '--waypoints', '--geojson'):
        assert flag in args, f'the README command lacks {flag}'
        i = args.index(flag) + 1
        assert Path(args[i]).parent == Path('examples/geo'), args[i]
        files[Path(args[i]).suffix[1:]] = args[i] = str(out / Path(args[i]).name)
    args[args.index('examples/geo/valley.yaml')] = str(EXAMPLE / 'valley.yaml')
    files['json'] = str(out / 'valley.json')
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(args + ['--json', files['json']]) == 0
    summary = json.loads(Path(files['json']).read_text())
    return SimpleNamespace(files={k: Path(v) for k, v in files.items()}, summary=summary,
                           geo=np.array(summary['exported']['path_geodetic']),
                           printed=printed.getvalue())
