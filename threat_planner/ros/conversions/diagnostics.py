"""The node's ``plan_info`` as diagnostic_msgs/DiagnosticArray."""

from typing import Mapping, Sequence

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
from std_msgs.msg import Header

from threat_planner.errors import InputError

#: Name of the DiagnosticStatus written by :func:`plan_info_msg`.
PLAN_STATUS_NAME = 'threat_planner: plan'

_LEVELS = {
    'OK': DiagnosticStatus.OK,
    'WARN': DiagnosticStatus.WARN,
    'ERROR': DiagnosticStatus.ERROR,
}


def _format_value(value: object) -> str:
    # bool before int (bool is an int); numpy scalars via Python types because
    # numpy 2 reprs them as 'np.float64(...)'.
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        # repr is the shortest string that float() maps back to the same double.
        return repr(float(value))
    return str(value)


def plan_info_msg(
    status: str,
    message: str,
    values: Mapping[str, object],
    stamp: Time,
    hardware_id: str = 'threat_planner',
) -> DiagnosticArray:
    """
    Report a planning result as a DiagnosticArray with one status.

    Parameters
    ----------
    status : {'OK', 'WARN', 'ERROR'}
        Outcome, mapped to the DiagnosticStatus level.
    message : str
        One-line summary.
    values : Mapping[str, object]
        Key/value details in order; floats are written with ``repr`` so that
        ``float(text)`` gives back the same value, ints as integers, others with ``str``.
    stamp : builtin_interfaces.msg.Time
        Header stamp.
    hardware_id : str, optional
        DiagnosticStatus hardware id.

    Returns
    -------
    diagnostic_msgs.msg.DiagnosticArray
        Array with one status named :data:`PLAN_STATUS_NAME`.

    Raises
    ------
    InputError
        If `status` is not one of 'OK', 'WARN', 'ERROR'.

    """
    if status not in _LEVELS:
        raise InputError(f"status must be 'OK', 'WARN' or 'ERROR', got {status!r}")
    diag = DiagnosticStatus(
        level=_LEVELS[status], name=PLAN_STATUS_NAME, message=message,
        hardware_id=hardware_id,
        values=[KeyValue(key=str(k), value=_format_value(v)) for k, v in values.items()])
    return DiagnosticArray(header=Header(stamp=stamp), status=[diag])


def plan_info_values(msg: DiagnosticArray) -> dict[str, str]:
    """
    Read back the key/values written by :func:`plan_info_msg`.

    Parameters
    ----------
    msg : diagnostic_msgs.msg.DiagnosticArray
        Array holding a status named :data:`PLAN_STATUS_NAME`.

    Returns
    -------
    dict[str, str]
        Keys and their string values, in message order.

    Raises
    ------
    InputError
        If no status of that name is present.

    """
    for diag in msg.status:
        if diag.name == PLAN_STATUS_NAME:
            return {kv.key: kv.value for kv in diag.values}
    names: Sequence[str] = [d.name for d in msg.status]
    raise InputError(f'DiagnosticArray has no status {PLAN_STATUS_NAME!r}; statuses are {names}')
