"""Shared parts of the property tests (test_properties*.py): settings and the call guard.

CHEAP and PLANS are the hypothesis settings; time_limit and _guarded run one library call
under CALL_TIMEOUT_S and accept only the project's own one-line errors.
"""

import contextlib
import os
import signal

from hypothesis import event, HealthCheck, Phase, settings, strategies as st
from hypothesis.control import currently_in_test_context
from hypothesis.extra.numpy import arrays

from threat_planner.errors import ThreatPlannerError

#: Wall-time limit of one library call [s]; generous for a busy 2-core CI machine.
CALL_TIMEOUT_S = 20

_FAST = dict(database=None, derandomize=True, deadline=None,
             suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
CHEAP = settings(max_examples=300, **_FAST)
#: Shrinking a failing plan() example can take minutes, so CI reports it unshrunk; set
#: THREAT_PLANNER_SHRINK=1 to get the minimal example.
_PLAN_PHASES = (tuple(Phase) if os.environ.get('THREAT_PLANNER_SHRINK')
                else (Phase.explicit, Phase.generate))
PLANS = settings(max_examples=60, phases=_PLAN_PHASES, **_FAST)


class CallTimeout(Exception):
    """A library call ran past CALL_TIMEOUT_S (deliberately not a ThreatPlannerError)."""


@contextlib.contextmanager
def time_limit(seconds=CALL_TIMEOUT_S):
    """Raise CallTimeout in the main thread if the block runs longer than ``seconds``."""
    def on_alarm(signum, frame):
        raise CallTimeout(f'call exceeded {seconds} s')

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def _check_message(exc):
    msg = str(exc)
    assert msg.strip(), f'{type(exc).__name__} with an empty message'
    assert '\n' not in msg, f'multi-line message: {msg!r}'


def _note(what):
    """Count an outcome for --hypothesis-show-statistics (inside a hypothesis test only)."""
    if currently_in_test_context():
        event(what)


def _guarded(fn, *args, **kwargs):
    """Call fn under the time limit; return its value, or None after a project error."""
    try:
        with time_limit():
            return fn(*args, **kwargs)
    except ThreatPlannerError as exc:
        _check_message(exc)
        _note(f'raised {type(exc).__name__}: {str(exc).split(":")[0]}')
        return None


# ---------------------------------------------------------------------------- strategies

#: Length scale of a scene; box sides are 1 to 10 times it, so from 1e-6 to 1e7.
scales = st.floats(-6.0, 6.0).map(lambda e: 10.0 ** e)
fractions = st.floats(0.0, 1.0)
unit_points = arrays(float, 3, elements=fractions)
