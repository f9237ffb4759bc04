# Copyright 2026 umbrella_sim developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
The sleeve force as a function of time: one zero-order-hold rule for every path.

``ForceSchedule`` holds F_H on the physics grid t_k = k h.  The rule, used by the offline
simulator (``umbrella_sim simulate``, with or without ``--mcap``), the live node and
``umbrella_replay --resimulate``:

    a value given for time t acts from step k = ceil((t - 1 ns) / h), i.e. from the first
    physics step that starts at or after t (a time within 1 ns of a grid point, the
    resolution of a recording's time stamps, counts as on it); when several values fall
    on the same step, the last one given wins.

The live node takes a command received between two publications at the start of the next
publication period (its sim time then, on the grid) and records that instant
(``sleeve_force/applied``), so the recorded history, through the same rule, reproduces the
run exactly.
"""
from __future__ import annotations

import bisect
import math
from typing import Any, Callable, Iterable

from .params import UmbrellaParams
from .registry import SPECS

#: a time within this of a grid point counts as on it (s): the ns resolution of recordings
TIME_RESOLUTION = 1e-9


class ForceSchedule:
    """F_H per physics step (see the module docstring for the rule)."""

    def __init__(self, step: float, initial: float = 0.0,
                 changes: Iterable[tuple[float, float]] = (),
                 check: Callable[[float], float] | None = None):
        """
        Build the schedule of F_H on the grid of ``step`` seconds.

        initial: F_H from t = 0 until the first change; changes: (t, F) pairs in
        non-decreasing time; check: validates one force value and returns it as a float
        (``solver.command_force`` with the model's bounds), raising ValueError.
        """
        if not (math.isfinite(step) and step > 0.0):
            raise ValueError(f'physics step {step}: must be a finite number > 0')
        self.step = float(step)
        self._check = check or float
        self.initial = self._check(initial)
        self._k: list[int] = []           # step index from which ...
        self._f: list[float] = []         # ... this force acts
        for t, f in changes or ():
            self.add(t, f)

    def step_index(self, t: float) -> int:
        """Return the first step that starts at or after t (within 1 ns)."""
        if not (math.isfinite(t) and t >= 0.0):
            raise ValueError(f'force schedule time {t}: must be finite and >= 0')
        return max(0, math.ceil((t - TIME_RESOLUTION) / self.step))

    def add(self, t: float, force: float) -> int:
        """Schedule F_H = force from time t on (times non-decreasing); return its step."""
        f = self._check(force)
        k = self.step_index(t)
        if self._k and k < self._k[-1]:
            raise ValueError(f'force schedule time {t} s goes backwards (the previous value '
                             f'acts from t = {self._k[-1] * self.step:.9g} s)')
        if self._k and k == self._k[-1]:
            self._f[-1] = f
        else:
            self._k.append(k)
            self._f.append(f)
        return k

    def force_at(self, k: int) -> float:
        """F_H during step k (from t_k to t_k+1)."""
        i = bisect.bisect_right(self._k, k) - 1
        return self.initial if i < 0 else self._f[i]

    def next_change(self, k: int) -> int | None:
        """Return the first step after k at which a scheduled value starts acting (or None)."""
        i = bisect.bisect_right(self._k, k)
        return self._k[i] if i < len(self._k) else None

    def changes(self) -> list[tuple[float, float]]:
        """Return [(time the value acts from, value)], on the grid."""
        return [(k * self.step, f) for k, f in zip(self._k, self._f)]


def validate_force(force: float, limit: float | None = None, minimum: float = 0.0,
                   link: str = 'the link') -> float:
    """
    Return F_H as a float, or raise ValueError naming the rule it breaks.

    F_H must be finite, >= minimum (the model's ``sleeve_force_min``: 0 for the thesis's
    push-only sleeve, < 0 for a drive that can hold the sleeve back) and, given the model's
    UmbrellaParams.sleeve_force_limit, at most that (N), the load of ``link`` (the umbrella's
    weakest: UmbrellaRibsParams.weakest_link).  Every command is checked with
    ``command_force`` below, which takes the bounds from the model.
    """
    try:
        f = float(force)
    except (TypeError, ValueError):
        raise ValueError(f'sleeve force {force!r}: not a number') from None
    # the same range as the sleeve_force parameter: one rule (registry.REGISTRY)
    SPECS['sleeve_force'].check(f, what='sleeve force F_H')
    if f < minimum:
        raise ValueError(f'sleeve force F_H={f}: must be >= {minimum:g} (sleeve_force_min; '
                         'below 0 only for a drive that can hold the sleeve back)')
    if limit is not None and f > limit:
        raise ValueError(f'sleeve force {f:g} N: above {limit:.6g} N, the axial load {link} '
                         'can carry (Euler buckling / squash load)')
    return f


def command_force(force: float, params: UmbrellaParams) -> float:
    """Return a force command as a float if the model accepts it, else raise ValueError."""
    return validate_force(force, params.sleeve_force_limit, params.sleeve_force_min,
                          getattr(params, 'weakest_link', 'the link'))


def check_profile_row(t: float, force: float, previous: float | None,
                      params: UmbrellaParams) -> tuple[float, float]:
    """
    Return a force profile's row (t, F) as floats, or raise ValueError saying what is wrong.

    The rule of every (t, F) profile (a CSV's ``--force-profile``, a test's
    ``play_force_profile``): t finite, >= 0 and after the row before (``previous``, None for
    the first; one force per instant), F a command the model accepts (command_force).
    """
    try:
        t = float(t)
    except (TypeError, ValueError):
        raise ValueError(f'time {t!r}: not a number') from None
    if not math.isfinite(t) or t < 0.0:
        raise ValueError(f'time {t} must be finite and >= 0')
    if previous is not None and t < previous:
        raise ValueError(f'time {t} goes backwards (the row before has {previous})')
    if previous is not None and t == previous:     # which one acts? one force per instant
        raise ValueError(f'time {t} given twice (the row before has it too): one force per '
                         'instant')
    return t, command_force(force, params)


def checked_profile(rows: Iterable[Any], params: UmbrellaParams,
                    row_name: Callable[[int], str]) -> list[tuple[float, float]]:
    """
    Return a (t, F) profile's rows as floats, or raise ValueError naming its first bad row.

    The one place a whole profile is judged, whoever read it: each row by check_profile_row
    against the model (params: the planar record, or the umbrella of N ribs, whose bound is
    its weakest link's), its refusal prefixed with ``row_name(i)`` of the row (i from 0):
    where the row came from, a CSV's 'force profile f.csv:12' (its line) or a list's
    'force profile row 3 (0.1, 80.0)'.  An empty profile is returned empty: a caller
    refuses it in its own words (the file's, the list's).
    """
    out: list[tuple[float, float]] = []
    for i, row in enumerate(rows):
        try:
            t, force = row
        except (TypeError, ValueError):
            raise ValueError(f'{row_name(i)}: expected a pair (t, F)') from None
        try:
            out.append(check_profile_row(t, force, out[-1][0] if out else None, params))
        except ValueError as exc:
            raise ValueError(f'{row_name(i)}: {exc}') from None
    return out
