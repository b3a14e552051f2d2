"""The QoS a topic was offered with, as rosbag2 records it in MCAP channel metadata."""

import dataclasses

import yaml

from threat_planner.errors import RecordingError

__all__ = ['INPUT_QOS', 'LATCHED_QOS', 'TopicQos', 'as_topic_qos']

# rmw's RMW_DURATION_INFINITE; rosbag2 records it for the unset deadline/lifespan/lease.
_INFINITE = {'sec': 9223372036, 'nsec': 854775807}


@dataclasses.dataclass(frozen=True)
class TopicQos:
    """The QoS a topic was offered with, as rosbag2 records it.

    Parameters
    ----------
    reliability : str
        ``'reliable'``, ``'best_effort'`` or ``'system_default'``.
    durability : str
        ``'volatile'``, ``'transient_local'`` or ``'system_default'``.
    history : str
        ``'keep_last'``, ``'keep_all'`` or ``'system_default'``.
    depth : int
        History depth (ignored by readers for ``keep_all``).

    """

    reliability: str = 'reliable'
    durability: str = 'volatile'
    history: str = 'keep_last'
    depth: int = 10

    def __post_init__(self):
        """Reject values rmw would not understand, naming the bad one."""
        allowed = {
            'reliability': ('reliable', 'best_effort', 'system_default'),
            'durability': ('volatile', 'transient_local', 'system_default'),
            'history': ('keep_last', 'keep_all', 'system_default'),
        }
        for name, values in allowed.items():
            if getattr(self, name) not in values:
                raise RecordingError(
                    f'QoS {name} {getattr(self, name)!r} is not one of {", ".join(values)}')
        if isinstance(self.depth, bool) or not isinstance(self.depth, int) or self.depth < 0:
            raise RecordingError(f'QoS depth {self.depth!r} is not a non-negative integer')

    @classmethod
    def from_rclpy(cls, profile) -> 'TopicQos':
        """Convert an ``rclpy.qos.QoSProfile`` (duck-typed, so rclpy is not imported).

        Parameters
        ----------
        profile : rclpy.qos.QoSProfile
            Profile whose policies are enums named like ``RELIABLE``.

        Returns
        -------
        TopicQos
            The same policies as plain values.

        """
        return cls(reliability=profile.reliability.name.lower(),
                   durability=profile.durability.name.lower(),
                   history=profile.history.name.lower(),
                   depth=int(profile.depth))

    def as_dict(self) -> dict:
        """Return the profile as one entry of rosbag2's v9 ``offered_qos_profiles`` list.

        Returns
        -------
        dict
            Keys in rosbag2's order, with string enums and infinite durations.

        """
        return {
            'history': self.history,
            'depth': self.depth,
            'reliability': self.reliability,
            'durability': self.durability,
            'deadline': dict(_INFINITE),
            'lifespan': dict(_INFINITE),
            'liveliness': 'automatic',
            'liveliness_lease_duration': dict(_INFINITE),
            'avoid_ros_namespace_conventions': False,
        }

    def to_yaml(self) -> str:
        """Return the YAML string rosbag2 stores in the MCAP channel metadata.

        Returns
        -------
        str
            A one-element YAML sequence.

        """
        return yaml.safe_dump([self.as_dict()], sort_keys=False, default_flow_style=False)


#: Outputs the planner latches: late subscribers still get the last plan.
LATCHED_QOS = TopicQos(reliability='reliable', durability='transient_local',
                       history='keep_last', depth=1)
#: Inputs and other streams: reliable, volatile.
INPUT_QOS = TopicQos(reliability='reliable', durability='volatile',
                     history='keep_last', depth=10)


def as_topic_qos(qos) -> TopicQos:
    """Return `qos` as a TopicQos: a TopicQos, an rclpy QoSProfile, or None (INPUT_QOS)."""
    if qos is None:
        return INPUT_QOS
    if isinstance(qos, TopicQos):
        return qos
    if all(hasattr(qos, a) for a in ('reliability', 'durability', 'history', 'depth')):
        return TopicQos.from_rclpy(qos)
    raise RecordingError(f'qos {qos!r} is neither a TopicQos nor an rclpy QoSProfile')
