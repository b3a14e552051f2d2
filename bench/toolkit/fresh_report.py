"""Ratios, the gate of issue 42 and the Markdown report of ``python -m bench fresh``.

Every function here takes the suite's case rows (plain dicts, as the suite's JSON holds
them), so the gate can be checked on rows made by hand. A row has ``id``, ``family``,
``n``, ``w``, ``limits`` ('on' or 'off'), ``head`` and ``base`` (``J`` and ``feasible``
from the independent grading, ``own_J``, ``own_feasible``, ``ms``, maybe ``error``), and
``in_box`` and ``limited`` (a yardstick's ``J``, or None where none was computed).
"""

from __future__ import annotations

import math
import statistics
from typing import Iterable, Sequence

from bench.toolkit.report import md_table

#: The gate of issue 42, item 2.
MIN_CASES = 300
BASE_MAX = 1.001
LIMITED_MEDIAN, LIMITED_WORST = 1.001, 1.01
IN_BOX_MEDIAN, IN_BOX_WORST = 1.001, 1.005
#: Own J and the independent J of the same path may differ by rounding, no more.
OWN_J_RTOL = 1e-9


def ratio(row: dict, against: str) -> float | None:
    """Return HEAD's J over the baseline's (``'base'``) or a yardstick's J.

    ``against`` is ``'base'``, ``'in_box'`` or ``'limited'``. None where there is nothing
    to compare with: no yardstick, or a baseline plan that failed the independent check.
    A HEAD plan that failed it counts as inf against a yardstick (a path that breaks the
    rules is no match for one that keeps them).
    """
    head = row['head']
    if against == 'base':
        base = row['base']
        if not base['feasible'] or not math.isfinite(base['J']) or base['J'] <= 0:
            return None
        return head['J'] / base['J']
    yard = row.get(against)
    if not yard or not math.isfinite(yard['J']) or yard['J'] <= 0:
        return None
    return head['J'] / yard['J'] if head['feasible'] else math.inf


def _values(rows: Iterable[dict], against: str) -> list[tuple[float, dict]]:
    return [(r, row) for row in rows if (r := ratio(row, against)) is not None]


def _pass(ok: bool) -> str:
    return 'PASS' if ok else 'FAIL'


def _yard_line(rows: Sequence[dict], against: str, title: str, median_max: float,
               worst_max: float) -> tuple[bool, str]:
    vals = _values(rows, against)
    if not vals:
        return False, f'{title}: no cases: FAIL'
    ratios = [r for r, _ in vals]
    worst, at = max(vals, key=lambda v: v[0])
    med = statistics.median(ratios)
    below = sum(r < 1.0 for r in ratios)
    ok = med <= median_max and worst <= worst_max
    return ok, (f'{title}: {len(vals)} cases, median {med:.5f} (<= {median_max}), worst '
                f'{worst:.4f} (<= {worst_max}) at {at["id"]}; {below} below 1 (the '
                f'yardstick above HEAD there: allowed): {_pass(ok)}')


def gate(rows: Sequence[dict], min_cases: int = MIN_CASES) -> list[tuple[bool, str]]:
    """Return the gate's lines, ``(passed, text)`` each, in the order issue 42 gives them.

    Parameters
    ----------
    rows : sequence of dict
        Every case of the run.
    min_cases : int
        The fewest cases the gate accepts.
    """
    out = [(len(rows) >= min_cases,
            f'cases: {len(rows)} fresh cases (>= {min_cases}): '
            f'{_pass(len(rows) >= min_cases)}')]
    vals = _values(rows, 'base')
    above = [(r, row) for r, row in vals if r > BASE_MAX]
    infeasible = [row for row in rows if not row['head']['feasible']]
    errors = sum('error' in row['head'] for row in rows)
    ok = not above and not infeasible and bool(vals)
    worst = (f'worst {max(vals, key=lambda v: v[0])[0]:.4f} at '
             f'{max(vals, key=lambda v: v[0])[1]["id"]}' if vals else 'none compared')
    unmatched = len(rows) - len(vals)
    out.append((ok, f'baseline: {len(above)} of {len(vals)} cases above {BASE_MAX} of the '
                    f"baseline's J ({worst}; {unmatched} not compared, the baseline's plan "
                    f'failed the independent check); HEAD infeasible by the independent '
                    f'check: {len(infeasible)} of {len(rows)} ({errors} plans failed): '
                    f'{_pass(ok)}'))
    on = [row for row in rows if row['limits'] == 'on']
    off = [row for row in rows if row['limits'] == 'off']
    out.append(_yard_line(on, 'limited', 'limited yardstick (limits on)', LIMITED_MEDIAN,
                          LIMITED_WORST))
    out.append(_yard_line(off, 'in_box', 'in-box yardstick (limits off)', IN_BOX_MEDIAN,
                          IN_BOX_WORST))
    return out


def _stat(rows: Sequence[dict], against: str) -> tuple[str, str]:
    ratios = [r for r, _ in _values(rows, against)]
    if not ratios:
        return '-', '-'
    return f'{statistics.median(ratios):.4f}', f'{max(ratios):.4f}'


def _ms(rows: Sequence[dict], who: str) -> float:
    ms = [row[who]['ms'] for row in rows if math.isfinite(row[who].get('ms', math.nan))]
    return statistics.median(ms) if ms else math.nan


def _row(label: Sequence[object], rows: Sequence[dict]) -> list[object]:
    base_ms, head_ms = _ms(rows, 'base'), _ms(rows, 'head')
    bad = (f"{sum(not r['head']['feasible'] for r in rows)}/"
           f"{sum(not r['base']['feasible'] for r in rows)}")
    return [*label, len(rows), *_stat(rows, 'base'), *_stat(rows, 'in_box'),
            *_stat(rows, 'limited'), bad, f'{base_ms:.0f}', f'{head_ms:.0f}',
            f'{head_ms / base_ms:.2f}' if base_ms > 0 else '-']


_HEAD = ['cases', 'HEAD/base median', 'worst', 'HEAD/in-box median', 'worst',
         'HEAD/limited median', 'worst', 'infeasible HEAD/base', 'base ms', 'HEAD ms',
         'HEAD/base time']


def tables(rows: Sequence[dict]) -> list[str]:
    """Return the per size and family table, then the per size and limits one."""
    sizes = sorted({r['n'] for r in rows})
    families = list(dict.fromkeys(r['family'] for r in rows))
    by_family = []
    for n in sizes:
        for fam in families:
            sel = [r for r in rows if r['n'] == n and r['family'] == fam]
            if sel:
                by_family.append(_row([n, fam], sel))
        by_family.append(_row([n, '**all**'], [r for r in rows if r['n'] == n]))
    by_limits = [_row([n, lim], sel) for n in sizes for lim in ('on', 'off')
                 if (sel := [r for r in rows if r['n'] == n and r['limits'] == lim])]
    by_limits.append(_row(['all', 'both'], rows))
    align = 'll' + 'r' * len(_HEAD)
    return (md_table(['n', 'family', *_HEAD], by_family, align) + ['']
            + md_table(['n', 'limits', *_HEAD], by_limits, align))


def badness(row: dict) -> float:
    """How far a case is from passing: its largest ratio, inf where HEAD is infeasible."""
    if not row['head']['feasible']:
        return math.inf
    return max((r for a in ('base', 'in_box', 'limited') if (r := ratio(row, a)) is not None),
               default=0.0)


def worst_cases(rows: Sequence[dict], seed: int, count: int = 10) -> list[str]:
    """Return a table of the ``count`` worst cases, each with its replay command."""
    def cell(r: float | None) -> str:
        return '-' if r is None else f'{r:.4f}'
    worst = sorted(rows, key=badness, reverse=True)[:count]
    body = [[f"`{row['id']}`", f"{row['base']['J']:.2f}", f"{row['head']['J']:.2f}",
             cell(ratio(row, 'base')), cell(ratio(row, 'in_box')), cell(ratio(row, 'limited')),
             f"{row['base']['feasible']}/{row['head']['feasible']}",
             f"{row['base'].get('own_J', math.nan):.2f}/{row['head'].get('own_J', math.nan):.2f}",
             f"{row['base']['ms']:.0f}/{row['head']['ms']:.0f}",
             f"`python -m bench fresh --seed {seed} --only {row['id']}`"] for row in worst]
    return md_table(['case', 'base J', 'HEAD J', 'HEAD/base', 'HEAD/in-box', 'HEAD/limited',
                     'feasible base/HEAD', 'own J base/HEAD', 'ms base/HEAD', 'replay'],
                    body, 'lrrrrrlrrl')


def self_grading(rows: Sequence[dict]) -> list[str]:
    """Return lines on where a checkout's own J or feasible flag differs from the grading."""
    out = []
    for who, label in (('head', 'HEAD'), ('base', 'baseline')):
        flags = [r['id'] for r in rows if 'own_feasible' in r[who]
                 and r[who]['own_feasible'] != r[who]['feasible']]
        js = [r['id'] for r in rows if 'own_J' in r[who] and math.isfinite(r[who]['J'])
              and abs(r[who]['own_J'] - r[who]['J']) > OWN_J_RTOL * abs(r[who]['J'])]
        errors = [r['id'] for r in rows if 'error' in r[who]]
        out.append(f'* {label}: own feasible flag differs from the independent check on '
                   f'{len(flags)} cases{": " + ", ".join(flags[:8]) if flags else ""}; own J '
                   f'differs from the recomputed J by more than {OWN_J_RTOL:g} relative on '
                   f'{len(js)}{": " + ", ".join(js[:8]) if js else ""}; failed plans: '
                   f'{len(errors)}{": " + ", ".join(errors[:8]) if errors else ""}')
    return out
