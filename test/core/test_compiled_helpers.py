"""The compiled Dijkstra and resampling agree with scipy and numpy on random inputs."""

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from threat_planner.core.network.graph_kernels import Graph
from threat_planner.core.optimise.smoothing import resample


def _random_graph(rng, n, e):
    edges = set()
    while len(edges) < e:
        a, b = rng.integers(0, n, 2)
        if a != b:
            edges.add((min(a, b), max(a, b)))
    return np.array(sorted(edges))


@pytest.mark.parametrize('seed', range(20))
def test_graph_distances_match_scipy_dijkstra(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 120))
    edges = _random_graph(rng, n, int(rng.integers(1, min(4 * n, n * (n - 1) // 2) + 1)))
    weights = rng.uniform(0.0, 10.0, len(edges))
    weights[::7] = 0.0                      # zero weights still count as edges
    graph = Graph(n, edges)
    for source in rng.integers(0, n, 3):
        dist, pred = graph.shortest(weights, int(source))
        ref = csr_matrix((np.maximum(weights, 1e-12),
                          (edges[:, 0], edges[:, 1])), shape=(n, n))
        want = dijkstra(ref, directed=False, indices=int(source))
        np.testing.assert_allclose(dist, want, rtol=1e-12, atol=1e-9)
        # Every predecessor chain is a path of exactly that total weight.
        w = {tuple(e): max(x, 1e-12) for e, x in zip(edges, weights)}
        for v in np.flatnonzero(np.isfinite(dist)):
            total, u = 0.0, int(v)
            while u != source:
                p = int(pred[u])
                total += w[(min(p, u), max(p, u))]
                u = p
            assert total == pytest.approx(dist[v], rel=1e-12, abs=1e-9)
        assert np.all(pred[~np.isfinite(dist)] == -1)


@pytest.mark.parametrize('seed', range(20))
def test_a_search_stopped_at_its_target_has_the_full_search_route(seed):
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(2, 300))
    edges = _random_graph(rng, n, int(rng.integers(1, min(4 * n, n * (n - 1) // 2) + 1)))
    # Ties too: equal weights make equal-length routes, which must break the same way.
    weights = (rng.choice([0.5, 1.0, 2.0], len(edges)) if seed % 2
               else rng.uniform(0, 1, len(edges)))
    graph = Graph(n, edges)
    source, target = (int(v) for v in rng.integers(0, n, 2))
    full_dist, full_pred = graph.shortest(weights, source)
    dist, pred = graph.shortest(weights, source, target)
    assert dist[target] == full_dist[target]
    u = target
    while np.isfinite(full_dist[target]) and u != source:
        assert pred[u] == full_pred[u]
        u = int(pred[u])
    # Stopped early, the other entries bound the least distances from above.
    assert np.all(dist >= full_dist)


def test_graph_weights_change_in_place_between_searches():
    edges = np.array([[0, 1], [1, 2], [0, 2]])
    graph = Graph(3, edges)
    dist, pred = graph.shortest(np.array([1.0, 1.0, 5.0]), 0)
    assert dist[2] == 2.0 and pred[2] == 1
    dist, pred = graph.shortest(np.array([1.0, 1.0, 1.5]), 0)
    assert dist[2] == 1.5 and pred[2] == 0


def _reference_resample(points, n):
    """The numpy version the compiled one replaced (np.interp along the arc length)."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] == 0:
        return np.concatenate([np.repeat(points[:1], n, axis=0), points[-1:]])
    q = np.linspace(0.0, s[-1], n + 1)
    out = np.stack([np.interp(q, s, points[:, k]) for k in range(3)], axis=1)
    out[0], out[-1] = points[0], points[-1]
    return out


def test_resample_matches_interpolation_along_the_arc_length():
    rng = np.random.default_rng(3)
    for trial in range(500):
        pts = rng.normal(0.0, 10.0, (int(rng.integers(2, 30)), 3))
        if trial % 3 == 0:                  # a zero-length segment
            k = int(rng.integers(0, len(pts) - 1))
            pts[k + 1] = pts[k]
        if trial % 11 == 0:                 # every vertex at one place
            pts[:] = pts[0]
        n = int(rng.integers(1, 50))
        got = resample(pts, n)
        np.testing.assert_allclose(got, _reference_resample(pts, n), atol=1e-9)
        assert np.array_equal(got[0], pts[0]) and np.array_equal(got[-1], pts[-1])
        steps = np.linalg.norm(np.diff(got, axis=0), axis=1)
        assert np.all(steps <= np.linalg.norm(np.diff(pts, axis=0), axis=1).sum() / n + 1e-9)


def test_the_kernel_cache_is_named_by_every_compiled_module():
    """A module compiled with cache=True outside the hash could load a stale callee."""
    from pathlib import Path

    from threat_planner.core import _numba_cache
    from threat_planner.core.cost import kernels

    core = Path(_numba_cache.__file__).parent
    compiled = {p.relative_to(core).as_posix() for p in core.rglob('*.py')
                if '@njit(cache=True' in p.read_text()}
    assert compiled and compiled <= set(_numba_cache.SOURCES)
    # every kernel's cache lives in the folder of this hash, under its place in the package
    kernel = kernels._kernel
    if not hasattr(kernel, '_cache'):  # the AOT kernel: its JIT twin has the cache
        from threat_planner.core import _aot
        kernel = _aot.jit()['threat_planner.core.cost.kernels._kernel']
    where = Path(kernel._cache._cache_path)
    assert where == _numba_cache.cache_dir() / 'cost'
    assert _numba_cache.cache_dir().name == _numba_cache.sources_digest() != ''


@pytest.mark.parametrize('first, env, sees', [('', '', False), ('import coverage', '', True),
                                              ('', '1', True)])
def test_numba_imports_coverage_only_for_a_running_measurement(first, env, sees):
    import os
    import subprocess
    import sys
    pytest.importorskip('coverage')
    code = (f'{first}\nimport sys, threat_planner.core\n'
            'import numba.misc.coverage_support as c\n'
            'print(c.coverage_available, "coverage" in sys.modules)\n'
            'import coverage\nprint(coverage.Coverage is not None)\n')
    environment = {k: v for k, v in os.environ.items() if k != 'NUMBA_JIT_COVERAGE'}
    environment['THREAT_PLANNER_AOT'] = '0'  # the JIT path's import (the AOT path has none)
    if env:
        environment['NUMBA_JIT_COVERAGE'] = env
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         env=environment, timeout=120, check=True).stdout.split()
    assert out == [str(sees), str(sees), 'True']
