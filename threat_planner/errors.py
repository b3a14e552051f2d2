"""Exception types: one per failure family, each naming the bad field and value."""


class ThreatPlannerError(Exception):
    """Base of all errors the project raises on purpose."""


class InputError(ThreatPlannerError, ValueError):
    """Bad input data: a field or value that cannot be planned with (NaN, F <= 0, ...)."""


class ScenarioError(InputError):
    """A scenario file that is missing, unreadable or has a bad field."""


class PlanningError(ThreatPlannerError):
    """Valid input for which no plan is possible (for example, no route to the goal)."""


class RecordingError(ThreatPlannerError):
    """An MCAP recording that cannot be written or read (truncated, unknown schema, ...)."""
