"""The command line with WGS84: path_geodetic, one-line errors, and a plain plan that loads
none of the geodesy, raster or MAVLink packages (the README's example command: test/export).
"""

import json
from pathlib import Path
import subprocess
import sys

import yaml

from threat_planner.cli.main import main

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / 'examples' / 'geo'
HEAVY = ('pymap3d', 'rasterio', 'pyproj', 'mavsdk', 'pymavlink', 'geojson')


def test_local_scenario_with_a_datum_gets_path_geodetic(tmp_path):
    doc = yaml.safe_load((REPO / 'test' / 'data' / 'weak20_0.yaml').read_text())
    doc['datum'] = [-33.8688, 151.2093, 40.0]
    (tmp_path / 's.yaml').write_text(yaml.safe_dump(doc))
    assert main(['plan', str(tmp_path / 's.yaml'), '--json', str(tmp_path / 'o.json')]) == 0
    summary = json.loads((tmp_path / 'o.json').read_text())
    geo = summary['path_geodetic']
    assert len(geo) == len(summary['path']) and summary['datum'] == doc['datum']
    assert abs(geo[0][0] + 33.8688) < 0.01 and abs(geo[0][1] - 151.2093) < 0.01
    # without a datum there is no geodetic path
    assert main(['plan', str(REPO / 'test' / 'data' / 'weak20_0.yaml'), '--json',
                 str(tmp_path / 'p.json')]) == 0
    assert 'path_geodetic' not in json.loads((tmp_path / 'p.json').read_text())


def test_geodetic_errors_exit_2_with_one_line(tmp_path, capsys):
    doc = yaml.safe_load((EXAMPLE / 'valley.yaml').read_text())
    doc['terrain']['dem'] = str(EXAMPLE / 'valley_dem.tif')
    cases = {'start': ({'start': [47.3712, 208.5, 520.0]},
                       'start: longitude 208.5 outside [-180, 180]'),
             'nodatum': ({'datum': None}, 'coordinates: geodetic needs a "datum'),
             'wide': ({'bounds': {'min': [47.37, 8.53, 430.0], 'max': [49.5, 8.56, 9000.0]}},
                      'bounds: the box spans'),
             'dem': ({'bounds': {'min': [47.37, 8.53, 430.0], 'max': [47.40, 8.56, 900.0]}},
                     "does not cover the box's north side")}
    for name, (change, message) in cases.items():
        (tmp_path / f'{name}.yaml').write_text(yaml.safe_dump({**doc, **change}))
        assert main(['plan', str(tmp_path / f'{name}.yaml')]) == 2, name
        err = capsys.readouterr().err
        assert err.count('\n') == 1 and message in err, err


def test_a_plain_plan_loads_no_geodesy_raster_or_mavlink():
    probe = ('import sys, json\n'
             'from threat_planner.cli.main import main\n'
             f'code = main(["plan", {str(REPO / "test" / "data" / "weak20_0.yaml")!r}])\n'
             f'print(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))\n'
             'sys.exit(code)\n')
    p = subprocess.run([sys.executable, '-c', probe], cwd=REPO, capture_output=True,
                       text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().splitlines()[-1] == '[]'
