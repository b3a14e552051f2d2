"""The planner node's recording (parameter ``record``): inputs, outputs, parameter events.

A mixin of :class:`threat_planner.ros.node.ThreatPlannerNode` (split from it): a
recording that fails (disk full) stops and the node plans on (reliability, issue 14).
"""

from __future__ import annotations

from typing import Sequence, TYPE_CHECKING

from builtin_interfaces.msg import Time
from rcl_interfaces.msg import ParameterEvent
from rclpy.parameter import Parameter

from threat_planner.errors import RecordingError
from threat_planner.ros.conversions import plan_info_msg
from threat_planner.ros.interface import (INPUT_TOPICS, NODE_NAME, OUTPUT_TOPICS,
                                          PARAMETER_EVENT_TYPE, PARAMETER_EVENTS_QOS,
                                          PARAMETER_EVENTS_TOPIC)
from threat_planner.ros.parameters import PARAMETER_DEFAULTS
if TYPE_CHECKING:  # mcap loads when a recording opens, not at every start
    from threat_planner.bag import McapRecorder

__all__ = ['NodeRecording']


class NodeRecording:
    """The recording methods of the planner node (module docstring)."""

    def _open_recorder(self, target: str) -> McapRecorder:
        from threat_planner.bag import McapRecorder
        recorder = McapRecorder(target, prefix=NODE_NAME)
        try:
            # From the interface, not the endpoints: a managed node records from configure
            # on, before its subscriptions exist.
            for name, (type_name, qos) in {**INPUT_TOPICS, **OUTPUT_TOPICS}.items():
                recorder.add_topic(self.resolve_topic_name(name), type_name, qos)
            recorder.add_topic(PARAMETER_EVENTS_TOPIC, PARAMETER_EVENT_TYPE,
                               PARAMETER_EVENTS_QOS)
            # The full parameter set first, so the recording alone says how the node was set.
            event = self._parameter_event()
            event.new_parameters = [self.get_parameter(n).to_parameter_msg()
                                    for n in PARAMETER_DEFAULTS]
            recorder.write(PARAMETER_EVENTS_TOPIC, event, log_time_ns=self._now_ns())
        except RecordingError:
            recorder.close()
            raise
        self.get_logger().info(f'recording inputs and outputs to {recorder.path}')
        return recorder

    def _recording_failed(self, exc: RecordingError) -> None:
        recorder, self._recorder = self._recorder, None
        message = (f'recording stopped after {recorder.message_count} messages, planning '
                   f'continues: {exc}')
        self.get_logger().error(message)
        try:
            recorder.close()
        except RecordingError:
            pass  # the recorder failed already; close() only releases the file
        values = self._input_values(self._seq, 'recording', Time())
        values['recording_error'] = str(exc)
        self._publish('plan_info', plan_info_msg('WARN', message, values, Time()))

    def _close_recorder(self) -> None:
        recorder, self._recorder = self._recorder, None
        if recorder is None:
            return
        try:
            recorder.close()
            self.get_logger().info(
                f'closed recording {recorder.path} ({recorder.message_count} messages)')
        except RecordingError as exc:
            self.get_logger().error(f'recording: {exc}')

    def _parameter_event(self) -> ParameterEvent:
        return ParameterEvent(stamp=self.get_clock().now().to_msg(),
                              node=self.get_fully_qualified_name())

    def _record_parameter_event(self, params: Sequence[Parameter]) -> None:
        if self._recorder is None:
            return
        event = self._parameter_event()
        event.changed_parameters = [p.to_parameter_msg() for p in params]
        self._record(PARAMETER_EVENTS_TOPIC, event)

    def _record(self, topic: str, msg: object) -> None:
        if self._recorder is None:
            return
        try:
            self._recorder.write(topic, msg, log_time_ns=self._now_ns())
        except RecordingError as exc:
            # reliability (issue 14): disk full or similar: stop recording, keep planning.
            self._recording_failed(exc)

    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds
