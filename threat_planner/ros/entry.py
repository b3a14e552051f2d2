"""The executables ``planner_node`` and ``planner_lifecycle_node``: plan process first.

Each starts the node's first plan process (:func:`threat_planner.ros.worker.prestart`)
before it imports rclpy, numpy and scipy, so the child's imports run beside the node's on
the second core and the first picture finds the child ready sooner. Then rclpy comes up,
with its DDS participant, before the node's module is imported, so that discovery of the
running nodes goes on during those imports (:func:`threat_planner.ros.process.run_node`).
This module imports nothing heavy: a spawned child runs the executable's script again,
and pays only this.

``python -m threat_planner.ros.entry planner_node [--ros-args ...]`` runs the same as
``ros2 run threat_planner planner_node``.
"""

import importlib
import sys
from typing import Optional

__all__ = ['planner_lifecycle_node', 'planner_node']


def _run(node_module: str, node_class: str, args: Optional[list[str]]) -> int:
    from threat_planner.ros.worker import prestart
    prestart()
    # rclpy's context and participant come up before the node's own imports, so that DDS
    # discovery runs beside them (see run_node's early_discovery).
    from threat_planner.ros.interface import NODE_NAME
    from threat_planner.ros.process import run_node
    return run_node(lambda: getattr(importlib.import_module(node_module), node_class)(),
                    NODE_NAME, args, early_discovery=True)


def planner_node(args: Optional[list[str]] = None) -> int:
    """Run :class:`~threat_planner.ros.node.ThreatPlannerNode`; see its ``main``."""
    return _run('threat_planner.ros.node', 'ThreatPlannerNode', args)


def planner_lifecycle_node(args: Optional[list[str]] = None) -> int:
    """Run the managed node; its plan process waits, imported, for ``configure``."""
    return _run('threat_planner.ros.lifecycle', 'ThreatPlannerLifecycleNode', args)


_EXECUTABLES = {'planner_node': planner_node, 'planner_lifecycle_node': planner_lifecycle_node}

if __name__ == '__main__':
    if len(sys.argv) < 2 or sys.argv[1] not in _EXECUTABLES:
        print(f'usage: python -m threat_planner.ros.entry {{{",".join(_EXECUTABLES)}}} '
              '[--ros-args ...]', file=sys.stderr)
        raise SystemExit(2)
    name = sys.argv.pop(1)
    raise SystemExit(_EXECUTABLES[name]())
