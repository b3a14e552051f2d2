"""Write the six airspace scenarios of issue 12 into test/data/ (deterministic).

Run: ``python -m bench make_airspace_scenarios``. The terrain of the ridge scenarios is
written once as ``test/data/air_ridges_dem.npy`` and referenced with ``file:``.
"""

from __future__ import annotations

import argparse

import numpy as np
import yaml

from bench.toolkit.repo import DATA


def ridges(n: int = 41, size: float = 1000.0) -> np.ndarray:
    """Two ridges across the route with a saddle in each, rows along y [m]."""
    x = np.linspace(0, size, n)
    xx, yy = np.meshgrid(x, x)
    gap1 = 1 - 0.6 * np.exp(-((yy - 300) / 90) ** 2)
    gap2 = 1 - 0.6 * np.exp(-((yy - 750) / 90) ** 2)
    r1 = 160 * np.exp(-((xx + 0.3 * yy - 450) / 60) ** 2) * gap1
    r2 = 190 * np.exp(-((xx - 0.2 * yy - 620) / 70) ** 2) * gap2
    return np.round(20 + r1 + r2 + 10 * np.sin(xx / 130) * np.cos(yy / 170), 2)


def bilinear(h: np.ndarray, res: float, x: float, y: float) -> float:
    """Height at (x, y) of a grid with origin (0, 0)."""
    gx, gy = x / res, y / res
    i, j = min(int(gx), h.shape[1] - 2), min(int(gy), h.shape[0] - 2)
    fx, fy = gx - i, gy - j
    return float((1 - fy) * ((1 - fx) * h[j, i] + fx * h[j, i + 1])
                 + fy * ((1 - fx) * h[j + 1, i] + fx * h[j + 1, i + 1]))


def small(name: str, description: str, **extra) -> dict:
    """Return a 100 m box from (0, 0, 20) to (100, 100, 80) with five radars."""
    threats = [{'position': [30.0, 40.0, 50.0], 'intensity': 2.0e4},
               {'position': [60.0, 55.0, 45.0], 'intensity': 3.0e4},
               {'position': [70.0, 20.0, 60.0], 'intensity': 1.5e4},
               {'position': [25.0, 80.0, 40.0], 'intensity': 2.5e4},
               {'position': [85.0, 75.0, 55.0], 'intensity': 2.0e4}]
    out = {'name': name, 'frame_id': 'map', 'description': description,
           'bounds': {'min': [0.0, 0.0, 0.0], 'max': [100.0, 100.0, 100.0]},
           'start': [0.0, 0.0, 20.0], 'goal': [100.0, 100.0, 80.0], 'threats': threats}
    out.update(extra)
    return out


def main(argv: list[str] | None = None) -> None:
    """Write the scenarios (no options: `argv` must be empty)."""
    argparse.ArgumentParser(description=__doc__.split('\n')[0]).parse_args(argv)
    docs = []
    sph = small('air_spheres_0', 'spheres and lethal radii across the straight line',
                no_fly_zones=[{'type': 'sphere', 'center': [50.0, 50.0, 50.0], 'radius': 12.0},
                              {'type': 'sphere', 'center': [20.0, 22.0, 30.0], 'radius': 8.0}])
    sph['threats'][1]['lethal_radius'] = 10.0
    sph['threats'][0]['lethal_radius'] = 6.0
    docs.append(sph)
    docs.append(small('air_geofence_0', 'a non-convex geofence prism across the route',
                      no_fly_zones=[{'type': 'prism', 'z_min': 0.0, 'z_max': 100.0,
                                     'polygon': [[35.0, 20.0], [75.0, 45.0], [70.0, 80.0],
                                                 [55.0, 55.0], [30.0, 60.0]]}]))
    docs.append(small('air_airport_0', 'an airport cylinder and a box across the route',
                      no_fly_zones=[{'type': 'cylinder', 'center': [50.0, 50.0],
                                     'radius': 18.0, 'z_min': 0.0, 'z_max': 90.0},
                                    {'type': 'box', 'min': [75.0, 60.0, 0.0],
                                     'max': [95.0, 70.0, 100.0]}]))
    h = ridges()
    np.save(DATA / 'air_ridges_dem.npy', h)
    res = 25.0
    radars = [(520.0, 300.0, 5e8), (780.0, 560.0, 8e8), (300.0, 700.0, 5e8),
              (880.0, 250.0, 6e8)]
    threats = [{'position': [x, y, round(bilinear(h, res, x, y) + 3.0, 2)], 'intensity': f}
               for x, y, f in radars]
    for masking in (True, False):
        name = f'air_ridges_{"mask" if masking else "nomask"}_0'
        docs.append({
            'name': name, 'frame_id': 'map',
            'description': f'1 km terrain with two ridges, ground radars, masking {masking}',
            'bounds': {'min': [0.0, 0.0, 0.0], 'max': [1000.0, 1000.0, 450.0]},
            'start': [20.0, 50.0, round(bilinear(h, res, 20, 50) + 60.0, 2)],
            'goal': [980.0, 950.0, round(bilinear(h, res, 980, 950) + 60.0, 2)],
            'threats': threats,
            'terrain': {'origin': [0.0, 0.0], 'resolution': res,
                        'file': 'air_ridges_dem.npy', 'clearance': 25.0,
                        'masking': masking}})
    x = np.linspace(0, 100, 11)
    xx, yy = np.meshgrid(x, x)
    hm = np.round(5 + 25 * np.exp(-((xx - 45) ** 2 + (yy - 40) ** 2) / 300), 2)
    mixed = small('air_mixed_0', 'terrain with masking, a cylinder, a prism and lethal radii',
                  no_fly_zones=[{'type': 'cylinder', 'center': [70.0, 65.0], 'radius': 10.0,
                                 'z_min': 0.0, 'z_max': 100.0},
                                {'type': 'prism', 'z_min': 0.0, 'z_max': 70.0,
                                 'polygon': [[20.0, 45.0], [40.0, 50.0], [35.0, 70.0]]}],
                  terrain={'origin': [0.0, 0.0], 'resolution': 10.0,
                           'heights': hm.tolist(), 'clearance': 5.0, 'masking': True})
    mixed['threats'][1]['lethal_radius'] = 8.0
    mixed['threats'][2]['position'] = [70.0, 20.0, 12.0]
    docs.append(mixed)
    for doc in docs:
        (DATA / f'{doc["name"]}.yaml').write_text(yaml.safe_dump(doc, sort_keys=False,
                                                                 default_flow_style=None))
