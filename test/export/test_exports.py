"""Exports read back by the readers autopilots and maps use, not by parsers of our own.

The README's command plans the example (examples/geo: geodetic, DEM terrain, all four zone
kinds) once and exports 16 waypoints; its ``.waypoints`` is read by pymavlink's
MAVWPLoader and by MAVSDK, its ``.plan`` by MAVSDK's import_qgroundcontrol_mission
(MAVSDK's native library, fed one heartbeat from a pymavlink-encoded autopilot: no
network), its GeoJSON by the geojson package; each matches the exported points of
``--json`` point for point, and those are ``path_geodetic``'s rows that were kept.
"""

import json
from pathlib import Path

import geojson
import numpy as np
import pytest

from threat_planner.cli.main import main
from threat_planner.core.inputs.scenario import load_scenario

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / 'examples' / 'geo' / 'valley.yaml'


@pytest.fixture
def exported(example_run):
    return example_run.files, example_run.summary, example_run.geo


def mavsdk_mission_raw():
    """MAVSDK's MissionRaw plugin on a system discovered from one injected heartbeat."""
    import mavsdk
    from mavsdk.plugins.mission_raw import MissionRaw
    from pymavlink.dialects.v20 import common as mavlink

    class Sink:
        def write(self, data):
            pass

    lib = mavsdk.Mavsdk(mavsdk.Configuration.create_with_component_type(
        mavsdk.ComponentType.GROUND_STATION))
    assert lib.add_any_connection('raw://') == mavsdk.ConnectionResult.SUCCESS
    lib.subscribe_raw_bytes_to_be_sent(lambda data: None)   # nowhere to send: nothing
    autopilot = mavlink.MAVLink(Sink(), srcSystem=1, srcComponent=1)
    beat = autopilot.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4,
                                      0, 0, mavlink.MAV_STATE_STANDBY).pack(autopilot)
    for _ in range(50):
        lib.pass_received_raw_bytes(bytes(beat))
        system = lib.first_autopilot(0.1)
        if system is not None:
            return lib, MissionRaw(system)
    pytest.skip('MAVSDK found no system from an injected heartbeat')


def test_path_geodetic_is_the_path_converted(exported):
    _, summary, geo = exported
    s = load_scenario(EXAMPLE)
    assert summary['datum'] == s.datum.as_list()
    full = np.array(summary['path_geodetic'])
    np.testing.assert_allclose(s.datum.to_enu(full), summary['path'], atol=1e-6)
    np.testing.assert_allclose(full[0], [47.3712, 8.5318, 520.0], atol=1e-9)
    np.testing.assert_array_equal(geo, full[summary['exported']['kept']])
    assert len(geo) == 16


def test_the_committed_exports_come_from_the_readme_command(example_run):
    folder = EXAMPLE.parent
    for name in ('valley.plan', 'valley.waypoints', 'valley.geojson'):
        assert name in example_run.printed
        committed, fresh = (folder / name).read_text(), example_run.files[name[7:]].read_text()
        assert committed.splitlines()[0] == fresh.splitlines()[0]
    plan = json.loads(example_run.files['plan'].read_text())
    committed = json.loads((folder / 'valley.plan').read_text())
    assert len(plan['mission']['items']) == len(committed['mission']['items']) == 17
    assert plan['geoFence'] == committed['geoFence']      # zones do not depend on the plan


def test_waypoints_read_back_with_pymavlink(exported):
    from pymavlink import mavwp
    files, _, geo = exported
    loader = mavwp.MAVWPLoader()
    assert loader.load(str(files['waypoints'])) == len(geo) + 2
    home = loader.wp(0)
    assert (home.frame, home.command) == (0, 16)
    np.testing.assert_allclose([home.x, home.y, home.z], geo[0], atol=1e-4)
    speed = loader.wp(1)   # the plan's speed over the ground, before the first waypoint
    assert (speed.frame, speed.command, speed.param1, speed.param3) == (2, 178, 1, -1)
    assert speed.param2 == exported[1]['speed_mps'] == 20.0
    for i, p in enumerate(geo):
        wp = loader.wp(i + 2)
        assert (wp.seq, wp.frame, wp.command, wp.autocontinue) == (i + 2, 3, 16, 1)
        assert abs(wp.x - p[0]) < 1e-9 and abs(wp.y - p[1]) < 1e-9   # 9 decimals
        assert abs(wp.z - (p[2] - geo[0][2])) < 1e-4


def test_plan_reads_back_with_mavsdk_point_for_point(exported):
    files, _, geo = exported
    lib, mission = mavsdk_mission_raw()
    data = mission.import_qgroundcontrol_mission(str(files['plan']))
    items = data.mission_items
    assert len(items) == len(geo) + 1
    speed, items = items[0], items[1:]
    assert (speed.seq, speed.frame, speed.command) == (0, 2, 178)
    assert (speed.param1, speed.param2, speed.param3) == (1, 20.0, -1)
    for i, (it, p) in enumerate(zip(items, geo)):
        assert (it.seq, it.frame, it.command) == (i + 1, 3, 16)
        # MAVLink's int32 1e-7 deg (1.1 cm) and float32 altitude
        assert abs(it.x - p[0] * 1e7) <= 0.5 + 1e-6 and abs(it.y - p[1] * 1e7) <= 0.5 + 1e-6
        assert abs(it.z - (p[2] - geo[0][2])) < 1e-3
    s = load_scenario(EXAMPLE)
    kinds = [z.kind for z in s.airspace.zones]
    fence = data.geofence_items
    circles = [f for f in fence if f.command == 5004]   # MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION
    vertices = [f for f in fence if f.command == 5002]  # ..._POLYGON_VERTEX_EXCLUSION
    assert len(circles) == kinds.count('sphere') + kinds.count('cylinder') == 2
    radii = sorted(f.param1 for f in circles)
    round_zones = [z for z in s.airspace.zones if z.kind in ('sphere', 'cylinder')]
    assert radii == sorted(z.radius for z in round_zones)
    # a box's 4 corners and the prism's 4 vertices, each vertex naming its polygon's size
    assert len(vertices) == 8 and {f.param1 for f in vertices} == {4.0}
    lib.destroy()


def test_waypoints_read_back_with_mavsdk_too(exported):
    files, _, geo = exported
    lib, mission = mavsdk_mission_raw()
    items = mission.import_mission_planner_mission(str(files['waypoints'])).mission_items
    # item 0 is home, at its absolute height (MAV_FRAME_GLOBAL)
    assert len(items) == len(geo) + 2
    assert items[0].frame == 0 and abs(items[0].z - geo[0][2]) < 1e-3
    assert (items[1].command, items[1].param2) == (178, 20.0)
    for it, p in zip(items[2:], geo):
        assert it.frame == 3 and abs(it.z - (p[2] - geo[0][2])) < 1e-3
        assert abs(it.x - p[0] * 1e7) <= 0.5 + 1e-6 and abs(it.y - p[1] * 1e7) <= 0.5 + 1e-6
    lib.destroy()


def ring_area(ring):
    x, y = np.asarray(ring)[:, 0], np.asarray(ring)[:, 1]
    return 0.5 * np.sum(x[:-1] * y[1:] - x[1:] * y[:-1])


def test_geojson_validates_and_its_line_is_path_geodetic(exported):
    files, summary, geo = exported
    doc = geojson.loads(files['geojson'].read_text())
    assert doc.is_valid, doc.errors()
    assert isinstance(doc, geojson.FeatureCollection)
    for f in doc['features']:
        assert f.is_valid and f['geometry'].is_valid, f.errors()
        assert {'name', 'kind'} <= set(f['properties'])
    # geojson rounds what it reads to 6 decimals (11 cm): the exact numbers from the JSON
    raw = json.loads(files['geojson'].read_text())
    line = [f for f in raw['features'] if f['geometry']['type'] == 'LineString']
    assert len(line) == 1
    np.testing.assert_array_equal(np.array(line[0]['geometry']['coordinates']),
                                  geo[:, [1, 0, 2]])              # GeoJSON is lon, lat, h
    assert line[0]['properties']['J'] == summary['exported']['cost']['J']   # what is flown
    threats = [f for f in doc['features'] if f['properties']['kind'] == 'threat']
    s = load_scenario(EXAMPLE)
    assert [t['properties']['intensity'] for t in threats] == s.threats.intensities.tolist()
    zones = [f for f in doc['features'] if f['geometry']['type'] == 'Polygon']
    assert [z['properties']['name'] for z in zones] == [z.label for z in s.airspace.zones]
    for z in zones:
        ring = z['geometry']['coordinates'][0]
        assert ring[0] == ring[-1] and ring_area(ring) > 0     # closed, counter-clockwise


def test_export_without_a_datum_is_refused_in_one_line(tmp_path, capsys):
    code = main(['plan', str(REPO / 'test' / 'data' / 'weak20_0.yaml'), '--waypoints',
                 str(tmp_path / 'x.waypoints')])
    err = capsys.readouterr().err
    assert code == 2 and err.count('\n') == 1
    assert '--waypoints: the scenario has no datum' in err
    assert not (tmp_path / 'x.waypoints').exists()
