"""The airspace at the ROS edge: zone markers and height maps, the node's state, recording.

Messages go through rclpy's own CDR serialisation where a round trip is claimed, so what is
checked is what a subscriber receives.
"""

import math

from builtin_interfaces.msg import Time
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.highlevel import AnyReader
from sensor_msgs.msg import Image
from visualization_msgs.msg import Marker, MarkerArray
import yaml

from node_harness import pose, REPO
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.planner import plan
from threat_planner.core.world.airspace import Airspace, make_zone, zone_to_mapping
from threat_planner.core.world.terrain import Terrain
from threat_planner.errors import InputError
from threat_planner.ros.conversions import (image_from_terrain, terrain_from_image,
                                            zones_from_markers, zones_to_markers)
from threat_planner.ros.inputs import accept, InputState
from threat_planner.ros.outputs import plan_markers
from threat_planner.ros.parameters import PARAMETER_DEFAULTS
from threat_planner.ros.recording.bagfile import load_bag
from threat_planner.ros.recording.record import record_plan
from threat_planner.ros.recording.replay import replay_bag

STAMP = Time(sec=5, nanosec=7)
coord = st.floats(-500, 500, allow_nan=False).map(lambda v: round(v, 3))
size = st.floats(0.5, 200, allow_nan=False).map(lambda v: round(v, 3))


def via_cdr(msg):
    return deserialize_message(serialize_message(msg), type(msg))


@st.composite
def zones(draw):
    kind = draw(st.sampled_from(['sphere', 'cylinder', 'box', 'prism']))
    label = f'no_fly_zones[{draw(st.integers(0, 99))}]'
    if kind == 'sphere':
        return make_zone(kind, label, center=[draw(coord) for _ in range(3)],
                         radius=draw(size))
    z0 = draw(coord)
    z1 = z0 + draw(size)
    if kind == 'cylinder':
        return make_zone(kind, label, center=[draw(coord), draw(coord)], radius=draw(size),
                         z_min=z0, z_max=z1)
    if kind == 'box':
        lo = [draw(coord) for _ in range(3)]
        return make_zone(kind, label, min=lo, max=[v + draw(size) for v in lo])
    # A star-shaped polygon around a centre is simple: increasing angles, positive radii.
    n = draw(st.integers(3, 8))
    cx, cy = draw(coord), draw(coord)
    radii = [draw(size) for _ in range(n)]
    poly = [[round(cx + r * math.cos(2 * math.pi * k / n), 3),
             round(cy + r * math.sin(2 * math.pi * k / n), 3)] for k, r in enumerate(radii)]
    return make_zone(kind, label, polygon=poly, z_min=z0, z_max=z1)


def unique_labels(zs):
    seen, out = set(), []
    for z in zs:
        if z.label not in seen:
            seen.add(z.label)
            out.append(z)
    return out


@settings(max_examples=60, deadline=None)
@given(st.lists(zones(), max_size=6).map(unique_labels))
def test_zones_round_trip_through_markers(zs):
    back = zones_from_markers(via_cdr(zones_to_markers(zs, 'map', STAMP)), 'map')
    assert [z.label for z in back] == [z.label for z in zs]
    for a, b in zip(zs, back):
        ma, mb = zone_to_mapping(a), zone_to_mapping(b)
        assert ma['type'] == mb['type']
        for key in ma:
            if key != 'type':
                np.testing.assert_allclose(mb[key], ma[key], rtol=0, atol=1e-9)
        # Same set: the signed distances agree at random points.
        p = np.random.default_rng(0).uniform(-600, 700, (50, 3))
        np.testing.assert_allclose(b.sdf(p), a.sdf(p), atol=1e-8)


def test_deleteall_clears_the_markers_before_it():
    zs = [make_zone('sphere', 'no_fly_zones[0]', center=[1, 2, 3], radius=4)]
    msg = zones_to_markers(zs, 'map', STAMP)
    msg.markers.append(Marker(action=Marker.DELETEALL))
    assert zones_from_markers(msg, 'map') == ()
    assert zones_from_markers(MarkerArray(), 'map') == ()


def _marker(kind, **fields):
    m = Marker(ns='nfz', id=1, type=kind, action=Marker.ADD)
    m.header.frame_id = 'map'
    m.pose.orientation.w = 1.0
    m.scale.x = m.scale.y = m.scale.z = 10.0
    for name, value in fields.items():
        obj = m
        *path, last = name.split('.')
        for part in path:
            obj = getattr(obj, part)
        setattr(obj, last, value)
    return m


def _prism(points, **fields):
    from geometry_msgs.msg import Point
    m = _marker(Marker.LINE_STRIP, **fields)
    m.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in points]
    return m


@pytest.mark.parametrize('markers, reason', [
    ([_marker(Marker.SPHERE, **{'scale.x': -10.0, 'scale.y': -10.0, 'scale.z': -10.0})],
     r'nfz\[1\].radius: must be positive, got -5.0'),
    ([_marker(Marker.SPHERE, **{'scale.y': 5.0})], r'nfz\[1\]: a SPHERE needs scale.x'),
    ([_marker(Marker.CYLINDER, **{'scale.y': 5.0})], r'nfz\[1\]: a CYLINDER needs'),
    ([_marker(Marker.CUBE, **{'pose.orientation.z': 0.5})],
     r'nfz\[1\]: orientation must be the identity'),
    ([_marker(Marker.CUBE, **{'pose.position.x': math.nan})],
     r'nfz\[1\].min: expected 3 finite numbers'),
    ([_marker(Marker.ARROW)], r'nfz\[1\]: marker type 0 is not a zone'),
    ([_marker(Marker.SPHERE, **{'header.frame_id': 'odom'})],
     r"no_fly_zones nfz\[1\] frame_id 'odom' does not match expected frame 'map'"),
    ([_marker(Marker.SPHERE), _marker(Marker.CUBE)], r'nfz\[1\]: duplicate marker ns/id'),
    ([_marker(Marker.SPHERE, action=Marker.DELETE)], r'nfz\[1\]: action DELETE'),
    ([_prism([(0, 0, 0), (10, 10, 0), (10, 0, 0), (0, 10, 0)])],
     r'nfz\[1\].polygon: not a simple polygon'),
    ([_prism([(0, 0, 0), (10, 0, 0)])], r'nfz\[1\]: a LINE_STRIP prism needs at least 3'),
    ([_prism([(0, 0, 0), (10, 0, 0), (0, 10, 5)])], r'nfz\[1\]: .* every point at one z'),
    ([_prism([(0, 0, 0), (10, 0, 0), (0, 10, 0)], **{'scale.z': 0.0})],
     r'nfz\[1\].z_max: must exceed z_min'),
])
def test_bad_zone_markers_are_refused_naming_the_zone(markers, reason):
    with pytest.raises(InputError, match=reason):
        zones_from_markers(MarkerArray(markers=markers), 'map')


def test_terrain_image_round_trip_and_layout():
    heights = np.arange(12, dtype=np.float32).reshape(3, 4) * 1.5   # rows along y
    t = Terrain.from_arrays([10, 20], 5.0, heights, 2.0, True)
    msg = via_cdr(image_from_terrain(t, 'map', STAMP))
    back = terrain_from_image(msg, 'map', np.array([10.0, 20.0]), 5.0, 2.0, True)
    np.testing.assert_array_equal(back.heights, heights)
    # Column c is x = x0 + c * resolution, row r is y = y0 + r * resolution.
    assert back.height(np.array([[10 + 3 * 5.0, 20 + 1 * 5.0]]))[0] == heights[1, 3]
    assert (back.clearance, back.masking) == (2.0, True)


def test_terrain_image_big_endian_with_row_padding():
    heights = np.array([[1.0, 2.0], [3.0, 4.0]], dtype='>f4')
    padded = np.zeros((2, 3), dtype='>f4')
    padded[:, :2] = heights
    msg = Image(height=2, width=2, encoding='32FC1', is_bigendian=1, step=12,
                data=padded.tobytes())
    msg.header.frame_id = 'map'
    t = terrain_from_image(msg, 'map', np.zeros(2), 1.0, 0.0, False)
    np.testing.assert_array_equal(t.heights, heights.astype(float))
    empty = Image()
    empty.header.frame_id = 'map'
    assert terrain_from_image(empty, 'map', np.zeros(2), 1.0, 0.0, False) is None


@pytest.mark.parametrize('change, reason', [
    ({'encoding': 'mono8'}, "terrain encoding must be 32FC1, got 'mono8'"),
    ({'step': 7}, 'terrain step must be a multiple of 4'),
    ({'data': b'\0' * 12}, 'terrain data has 12 bytes, expected step'),
    ({'data': np.array([1, np.nan, 2, 3], '<f4').tobytes()}, 'terrain.heights'),
])
def test_bad_terrain_images_are_refused(change, reason):
    msg = Image(height=2, width=2, encoding='32FC1', step=8,
                data=np.zeros(4, '<f4').tobytes())
    msg.header.frame_id = 'map'
    for name, value in change.items():
        setattr(msg, name, value)
    with pytest.raises(InputError, match=reason):
        terrain_from_image(msg, 'map', np.zeros(2), 1.0, 0.0, False)


# ------------------------------------------------------------------ node state


def state(**params):
    return InputState.from_parameters({**PARAMETER_DEFAULTS, **params})


def zone_msg(*zs):
    return zones_to_markers(list(zs), 'map', STAMP)


def test_a_zone_around_the_start_is_refused_and_the_state_kept():
    s = state()   # start [0, 0, 50]
    with pytest.raises(InputError, match=r'start: \[0.0, 0.0, 50.0\] is inside '
                                         r'no_fly_zones\[0\] \(sphere, 5 m deep\)'):
        accept(s, 'no_fly_zones', zone_msg(make_zone('sphere', 'no_fly_zones[0]',
                                                     center=[0, 0, 50], radius=5)))
    s2 = accept(s, 'no_fly_zones', zone_msg(make_zone('box', 'no_fly_zones[0]',
                                                      min=[40, 40, 0], max=[60, 60, 80])))
    assert len(s2.airspace.zones) == 1
    with pytest.raises(InputError, match=r'goal: \[50.0, 50.0, 50.0\] is inside '
                                         r'no_fly_zones\[0\] \(box'):
        accept(s2, 'goal_pose', pose([50, 50, 50]))
    with pytest.raises(InputError, match=r'start: .* is inside no_fly_zones\[0\]'):
        accept(s2, 'parameters', {'start': [45.0, 45.0, 10.0]})


def airspace_file(tmp_path, data, name='air.yaml'):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return str(path)


def test_the_file_loads_and_the_topics_replace_its_parts(tmp_path):
    file = airspace_file(tmp_path, {
        'no_fly_zones': [{'type': 'cylinder', 'center': [50, 50], 'radius': 10,
                          'z_min': 0, 'z_max': 100}],
        'terrain': {'origin': [0, 0], 'resolution': 50, 'heights': [[0, 0, 0]] * 3,
                    'clearance': 5, 'masking': False}})
    s = state(airspace_file=file)
    assert [z.label for z in s.zones] == ['no_fly_zones[0]']
    assert s.terrain.clearance == 5 and not s.terrain_from_topic
    # The zones topic replaces the file's zones; the file's terrain stays.
    s = accept(s, 'no_fly_zones', zone_msg(make_zone('sphere', 'nfz[3]', center=[20, 80, 50],
                                                     radius=5)))
    assert [z.label for z in s.zones] == ['nfz[3]'] and s.terrain.clearance == 5
    # A terrain image replaces the file's terrain, on the grid of the terrain_* parameters.
    img = image_from_terrain(Terrain.from_arrays([0, 0], 1, np.full((2, 2), 3.0)), 'map',
                             STAMP)
    s = accept(s, 'terrain', img)
    assert s.terrain_from_topic and s.terrain.resolution == 10.0 and s.terrain.clearance == 0
    s = accept(s, 'parameters', {'terrain_resolution': 60.0, 'terrain_clearance': 2.0,
                                 'terrain_masking': True})
    assert (s.terrain.resolution, s.terrain.clearance, s.terrain.masking) == (60.0, 2.0, True)
    # Setting the file again takes both parts from it; '' removes both.
    s = accept(s, 'parameters', {'airspace_file': file})
    assert [z.label for z in s.zones] == ['no_fly_zones[0]'] and s.terrain.clearance == 5
    assert accept(s, 'parameters', {'airspace_file': ''}).airspace is None
    # A new frame drops what the topics sent in the old one, and keeps the file's.
    s = accept(s, 'no_fly_zones', zone_msg(make_zone('sphere', 'nfz[3]', center=[20, 80, 50],
                                                     radius=5)))
    s = accept(s, 'terrain', img)
    s = accept(s, 'parameters', {'frame_id': 'odom'})
    assert [z.label for z in s.zones] == ['no_fly_zones[0]'] and s.terrain.clearance == 5
    assert not s.terrain_from_topic


@pytest.mark.parametrize('data, reason', [
    ({'no_fly_zones': [{'type': 'sphere', 'center': [1, 2, 3], 'radius': -5}]},
     r'no_fly_zones\[0\].radius: must be positive, got -5.0'),
    ({'zones': []}, "unknown key 'zones'"),
    ({'terrain': {'origin': [0, 0], 'resolution': 10, 'heights': [[0, None], [0, 0]]}},
     'terrain'),
    ({'no_fly_zones': [{'type': 'sphere', 'center': [0, 0, 50], 'radius': 5}]},
     r'start: \[0.0, 0.0, 50.0\] is inside'),
])
def test_a_bad_airspace_file_is_refused_in_one_line(tmp_path, data, reason):
    file = airspace_file(tmp_path, data)
    for attempt in (lambda: state(airspace_file=file),
                    lambda: accept(state(), 'parameters', {'airspace_file': file})):
        with pytest.raises(InputError, match=reason) as err:
            attempt()
        assert '\n' not in str(err.value)
    with pytest.raises(InputError, match='airspace_file: cannot read'):
        state(airspace_file=str(tmp_path / 'missing.yaml'))


def test_network_markers_draw_the_zones_and_the_terrain():
    sc = load_scenario(REPO / 'test' / 'data' / 'air_mixed_0.yaml')
    cfg = PlannerConfig(routes=1, surface_seeds=False)
    r = plan(sc.threats, sc.start, sc.goal, sc.box, cfg, airspace=sc.airspace)
    ma = via_cdr(plan_markers(r, sc.threats, sc.box, 'map', STAMP, sc.airspace))
    zones = [m for m in ma.markers if m.ns == 'zones']
    assert [m.text for m in zones] == [z.label for z in sc.airspace.zones]
    assert [m.type for m in zones] == [
        {'sphere': Marker.SPHERE, 'cylinder': Marker.CYLINDER, 'box': Marker.CUBE,
         'prism': Marker.LINE_LIST}[z.kind] for z in sc.airspace.zones]
    terrain, = [m for m in ma.markers if m.ns == 'terrain']
    assert terrain.type == Marker.TRIANGLE_LIST and len(terrain.points) % 3 == 0
    pts = np.array([[p.x, p.y, p.z] for p in terrain.points])
    # Every vertex is a grid point on the surface.
    np.testing.assert_allclose(sc.airspace.terrain.height(pts[:, :2]), pts[:, 2], atol=1e-12)


def test_a_recorded_airspace_plan_replays_and_needs_its_airspace(tmp_path):
    sc = load_scenario(REPO / 'test' / 'data' / 'air_mixed_0.yaml')
    cfg = PlannerConfig()   # a recording holds node parameters only
    result, path = record_plan(sc, cfg, tmp_path / 'air.mcap')
    bag = load_bag(path)
    assert [i.kind for i in bag.inputs] == ['start', 'goal_pose', 'no_fly_zones', 'terrain',
                                            'threats']
    assert bag.parameters['terrain_masking'] is True
    # The airspace inputs decode with rosbags too (the file's own definitions).
    with AnyReader([path]) as reader:
        got = {c.topic: reader.deserialize(raw, c.msgtype)
               for c, _, raw in reader.messages() if c.topic in ('/no_fly_zones', '/terrain')}
    assert len(got['/no_fly_zones'].markers) == 1 + len(sc.airspace.zones)
    heights = np.frombuffer(bytes(got['/terrain'].data), '<f4').reshape(
        sc.airspace.terrain.heights.shape)
    np.testing.assert_array_equal(heights, sc.airspace.terrain.heights.astype(np.float32))
    report = replay_bag(bag)
    assert report.ok, report
    assert report.rows[0].j_replayed == pytest.approx(result.cost.J, rel=1e-12)
    # The airspace decides the plan: without it the same inputs give another path, one
    # that breaks the airspace.
    free = plan(sc.threats, sc.start, sc.goal, sc.box, cfg)
    assert not np.allclose(free.path, result.path)
    assert Airspace(sc.airspace.zones, sc.airspace.terrain).violations(free.path)
    assert not Airspace(sc.airspace.zones, sc.airspace.terrain).violations(result.path)


@pytest.mark.parametrize('change, reason', [
    ({'terrain_origin': [1.0]}, r'terrain_origin: expected \[x, y\], got 1 values'),
    ({'terrain_origin': [0.0, math.inf]}, 'terrain_origin: not finite'),
    ({'terrain_resolution': 0.0}, 'terrain_resolution: must be finite and > 0'),
    ({'terrain_clearance': -1.0}, 'terrain_clearance: must be finite and >= 0'),
    ({'terrain_masking': 1}, 'terrain_masking: must be true or false'),
    ({'airspace_file': 3}, 'airspace_file: must be a string'),
])
def test_airspace_parameters_refuse_bad_values(change, reason):
    with pytest.raises(InputError, match=reason):
        state(**change)
