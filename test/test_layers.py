"""The layers hold: the planning core and the command line's ``plan`` load no ROS."""

import json
from pathlib import Path
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Loaded by importing each of these, nothing from rclpy or a message package may be.
ROS_FREE = [
    'threat_planner',
    'threat_planner.core',
    'threat_planner.core.planner',
    'threat_planner.core.inputs.scenario',
    'threat_planner.core.geo.dem',
    'threat_planner.core.flight.commit',
    'threat_planner.flight.fly',
    'threat_planner.flight.follow',
    'threat_planner.flight.playback',
    'threat_planner.export.thin',
    'threat_planner.export.qgc',
    'threat_planner.cli',
    'threat_planner.cli.main',
    'threat_planner.batch.runner',
    'threat_planner.batch.worker',
]

PROBE = r"""
import importlib, json, sys
importlib.import_module(sys.argv[1])
ros = sorted(m for m in sys.modules
             if m.split('.')[0] in ('rclpy', 'rosidl_parser', 'rosidl_runtime_py')
             or m.split('.')[0].endswith('_msgs') or m.split('.')[0].endswith('_interfaces'))
print(json.dumps(ros))
"""


@pytest.mark.parametrize('module', ROS_FREE)
def test_core_imports_no_ros(module):
    p = subprocess.run([sys.executable, '-c', PROBE, module], cwd=ROOT, capture_output=True,
                       text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == '[]', f'{module} loads {p.stdout.strip()}'


def test_cli_plan_loads_no_ros(tmp_path):
    """Planning a scenario from the command line (no --record) never touches rclpy."""
    probe = (
        'import sys, json\n'
        'from threat_planner.cli import main\n'
        f'code = main(["plan", {str(ROOT / "test" / "data" / "weak20_0.yaml")!r}, '
        f'"--json", {str(tmp_path / "out.json")!r}])\n'
        'ros = [m for m in sys.modules if m.split(".")[0] == "rclpy" '
        'or m.split(".")[0].endswith("_msgs")]\n'
        'print(json.dumps(ros)); sys.exit(code)\n')
    p = subprocess.run([sys.executable, '-c', probe], cwd=ROOT, capture_output=True,
                       text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().splitlines()[-1] == '[]'
    assert (tmp_path / 'out.json').exists()


def test_the_probe_sees_ros_when_it_is_loaded():
    """The check above can fail: importing the node package does load rclpy."""
    p = subprocess.run([sys.executable, '-c', PROBE, 'threat_planner.ros.node'], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert 'rclpy' in p.stdout


HEAVY_PROBE = r"""
import importlib, json, sys
importlib.import_module(sys.argv[1])
print(json.dumps(sorted({m.split('.')[0] for m in sys.modules} & {
    'numpy', 'scipy', 'numba', 'rclpy', 'mcap', 'yaml', 'nav_msgs'})))
"""


@pytest.mark.parametrize('module, heavy', [
    ('threat_planner', []),                    # core's names load on first use
    ('threat_planner.ros.entry', []),          # what a spawned plan process runs first
    ('threat_planner.ros.worker', []),
    ('threat_planner.bag.cdr', []),            # a plan process's serialiser: no mcap
    # The node's own process plans nothing (its child and its GetPlan thread load the
    # planner): no scipy.spatial, a third of a second, before it reports ready.
    ('threat_planner.ros.node', ['nav_msgs', 'numpy', 'rclpy', 'yaml']),
    ('threat_planner.core', ['numpy', 'yaml']),
])
def test_the_executables_start_their_plan_process_before_the_heavy_imports(module, heavy):
    """`planner_node` spawns its plan process from :mod:`threat_planner.ros.entry`, whose
    imports (and a spawned child's re-run of the script) must stay free of numpy, scipy and
    rclpy; the node's case shows that the probe sees them."""
    p = subprocess.run([sys.executable, '-c', HEAVY_PROBE, module], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout) == heavy, p.stdout


def test_the_lazy_package_names_are_the_core_s_and_the_bag_s():
    import threat_planner
    from threat_planner import bag, core
    assert all(getattr(threat_planner, n) is getattr(core, n) for n in threat_planner.__all__
               if n in core.__all__) and 'plan' in dir(threat_planner)
    from threat_planner.bag import writer
    assert bag.McapRecorder is writer.McapRecorder and set(bag.__all__) <= set(dir(bag))
    with pytest.raises(AttributeError, match='no attribute .nope.'):
        bag.nope  # noqa: B018


def test_no_module_is_over_450_lines():
    """Every Python file git tracks: the package, test, bench, examples, launch, setup.py."""
    p = subprocess.run(['git', 'ls-files', '-z', '--', '*.py'], cwd=ROOT, capture_output=True,
                       check=True)
    files = [ROOT / name for name in p.stdout.decode().split('\0') if name]
    assert ROOT / 'setup.py' in files and ROOT / 'test' / 'test_layers.py' in files
    sizes = {str(f.relative_to(ROOT)): len(f.read_text().splitlines())
             for f in files if f.is_file()}
    assert {f: n for f, n in sizes.items() if n > 450} == {}


# ---- the import graph: no circle, and no arrow back up a layer ------------------------

#: Layers, lowest first: a module may import its own layer's and lower layers' modules.
LAYERS = ('core', 'export', 'batch', 'bag', 'ros', 'cli')
#: Inside core, lowest first; one rank may hold several folders that must not import
#: one another ('' is the core package's own modules: planner, result).
CORE_RANKS = (('_numba_cache', '_scipy_first', '_vector'), ('_aot',), ('world',), ('geo',),
              ('inputs', 'cost'), ('network', 'optimise'), ('methods',), ('detection',), ('',))


def import_graph(package: Path) -> dict[str, set[str]]:
    """Return module -> the project's modules it imports (anywhere in its body).

    ``from pkg import name`` counts as importing ``pkg.name`` where that is a module and
    ``pkg`` otherwise; a module's own parent packages (run by Python first) do not count.
    """
    import ast
    base = package.parent
    mods = {}
    for f in package.rglob('*.py'):
        parts = f.relative_to(base).with_suffix('').parts
        mods['.'.join(parts[:-1] if parts[-1] == '__init__' else parts)] = f
    graph = {}
    for name, f in mods.items():
        out = set()
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                targets = [node.module + '.' + a.name if node.module + '.' + a.name in mods
                           else node.module for a in node.names]
            else:
                continue
            for t in targets:
                while t not in mods and '.' in t:
                    t = t.rsplit('.', 1)[0]
                if t in mods and t != name and not name.startswith(t + '.'):
                    out.add(t)
        graph[name] = out
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Return the strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def place(module: str) -> tuple[int, int, str] | None:
    """(layer, rank in core, folder) of a module; None for the package root and errors."""
    parts = module.split('.')[1:]
    if not parts or parts[0] not in LAYERS:
        return None
    if parts[0] != 'core':
        return LAYERS.index(parts[0]), 0, parts[0]
    folder = parts[1] if len(parts) > 1 and any(parts[1] in r for r in CORE_RANKS) else ''
    return 0, next(i for i, r in enumerate(CORE_RANKS) if folder in r), folder


def upward_arrows(graph: dict[str, set[str]]) -> list[str]:
    """Every import from a lower layer or rank to a higher or sideways one."""
    bad = []
    for a, targets in graph.items():
        pa = place(a)
        for b in targets:
            pb = place(b)
            if pa is None or pb is None or pa[2] == pb[2] and pa[0] == pb[0]:
                continue
            if pb[:2] >= pa[:2]:
                bad.append(f'{a} -> {b}')
    return sorted(bad)


GRAPH = import_graph(ROOT / 'threat_planner')


def test_no_import_circle():
    assert circles(GRAPH) == []


def test_no_import_runs_back_up_a_layer():
    assert upward_arrows(GRAPH) == []


def test_the_graph_checks_can_fail():
    """A planted circle and a planted upward arrow are both seen."""
    g = {k: set(v) for k, v in GRAPH.items()}
    g['threat_planner.core.world.threats'].add('threat_planner.core.planner')
    assert any('threat_planner.core.world.threats' in c for c in circles(g))
    assert 'threat_planner.core.world.threats -> threat_planner.core.planner' in \
        upward_arrows(g)
    assert upward_arrows({'threat_planner.bag.writer': {'threat_planner.ros.node'},
                          'threat_planner.core.cost.kernels':
                          {'threat_planner.core.inputs.config'}}) == [
        'threat_planner.bag.writer -> threat_planner.ros.node',
        'threat_planner.core.cost.kernels -> threat_planner.core.inputs.config']
    # the walk reads imports inside functions too (cli.main loads ROS only when asked)
    assert 'threat_planner.ros.recording.record' in GRAPH['threat_planner.cli.main']
