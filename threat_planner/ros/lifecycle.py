"""``planner_lifecycle_node``: the planner as a managed (lifecycle) node, Nav2's way.

The same node as ``planner_node`` (:class:`~threat_planner.ros.node.ThreatPlannerNode`,
whose set-up steps it reuses) with its work split over the lifecycle transitions:

* unconfigured: parameters declared only (changes are taken, checked on configure);
* ``configure``: parameters validated into the state, worker started, recording opened,
  publishers created (lifecycle publishers, still off); a bad parameter fails the
  transition with the reason logged;
* ``activate``: publishers on, subscriptions and the ``plan_path`` service created;
  the latched threat picture arrives and planning starts;
* ``deactivate``: subscriptions and service destroyed, publishers off, inputs (parameter
  changes included) stored without planning; a plan that was running is not published;
* ``cleanup`` / ``shutdown``: worker stopped, recording closed, publishers destroyed.
"""

from __future__ import annotations

from typing import Optional

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from threat_planner.errors import ThreatPlannerError
from threat_planner.ros.interface import NODE_NAME
from threat_planner.ros.node import ThreatPlannerNode
from threat_planner.ros.plan_service import PlanService
from threat_planner.ros.process import run_node

__all__ = ['ThreatPlannerLifecycleNode', 'main']


class ThreatPlannerLifecycleNode(ThreatPlannerNode, LifecycleNode):
    """The managed planner node; see the module docstring.

    Parameters
    ----------
    **kwargs
        Passed to :class:`rclpy.lifecycle.LifecycleNode`.

    """

    def __init__(self, **kwargs) -> None:
        LifecycleNode.__init__(self, NODE_NAME, **kwargs)
        self._state = None
        self._staged = None
        self._active = False
        self._configured = False
        self._plan_service: Optional[PlanService] = None
        self._subs: dict = {}
        self._declare_parameters()

    # -- transitions -----------------------------------------------------------------

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Validate the parameters, start the worker, open the recording."""
        try:
            self._configure()
        except ThreatPlannerError as exc:
            self.get_logger().error(f'configure failed: {exc}')
            self._state = None
            return TransitionCallbackReturn.FAILURE
        self._create_outputs(self.create_lifecycle_publisher)
        self._configured = True
        self.get_logger().info('configured')
        return super().on_configure(state)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Turn the publishers on, create subscriptions and the plan service."""
        result = super().on_activate(state)
        self._active = True
        self._create_inputs()
        self._plan_service = PlanService(self, lambda: self._state)
        self._log_ready()
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop taking inputs and requests; turn the publishers off."""
        self._deactivate()
        self.get_logger().info('deactivated')
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Go back to unconfigured: stop the worker, close the recording, drop publishers."""
        self._release()
        self.get_logger().info('cleaned up')
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release everything from whichever state the node is in."""
        self._deactivate()
        self._release()
        return super().on_shutdown(state)

    # -- hooks into the shared node logic --------------------------------------------

    def _request_plan(self, source, stamp, reason: str = '') -> None:
        if self._active:
            super()._request_plan(source, stamp, reason)

    def _publish(self, name: str, msg) -> None:
        if self._active:
            super()._publish(name, msg)

    def close(self) -> None:
        """Release everything (process exit); idempotent."""
        self._deactivate()
        self._release()

    def _deactivate(self) -> None:
        self._active = False
        for sub in self._subs.values() if self._configured else ():
            self.destroy_subscription(sub)
        if self._configured:
            self._subs = {}
        if self._plan_service is not None:
            self._plan_service.close()
            self._plan_service = None

    def _release(self) -> None:
        if not self._configured:
            return
        self._configured = False
        ThreatPlannerNode.close(self)
        for pub in self._pubs.values():
            self.destroy_lifecycle_publisher(pub)
        self._pubs = {}
        self.destroy_guard_condition(self._guard)
        self._state = None


def main(args: Optional[list[str]] = None) -> int:
    """Run the managed node (unconfigured until told) until SIGINT or SIGTERM.

    Parameters
    ----------
    args : list of str, optional
        Command line (``--ros-args ...``); ``sys.argv`` if None.

    Returns
    -------
    int
        0 after a clean shutdown.

    """
    return run_node(ThreatPlannerLifecycleNode, NODE_NAME, args)


if __name__ == '__main__':
    raise SystemExit(main())
