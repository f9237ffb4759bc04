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
A sweep's SPEC (YAML): the cases it names, each checked before any runs.

SPEC keys (every parameter name is the one of ``config/umbrella.yaml`` / the node)::

    params: other.yaml         # optional ROS 2 params file, default config/umbrella.yaml
    base: {name: value}        # overrides applied to every case
    grid: {name: [v1, v2]}     # cartesian product, first axis outermost (and the plots' x axis)
    cases: [{name: value}]     # explicit cases, added after the grid's
    duration: 1.0              # simulated time per case (s), the cap when stop_after_lock is set
    stop_after_lock: 0.2       # end a case this long after its lock (s)
    force: 5.0                 # constant sleeve force F_H (N), = base sleeve_force
    force_profile: f.csv       # or a CSV of t,F rows (path relative to the SPEC)
    long_run: true             # consent to cases of more than 10^8 physics steps each

The whole SPEC is checked before any case runs (names, values, every case's parameters through
the same validation as the CLI); errors name the case and the parameter.  ``case_id`` hashes
a case's full parameter set, run options and the package version.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import hashlib
import itertools
import json
import math
import os
from typing import Any

import yaml

from .inputs import (check_lock_given, check_offline_names, check_run_length,
                     default_params_file, LONG_RUN_STEPS, parse_force_profile, resolve_params,
                     UMBRELLA_NAMES)
from .. import __version__
from ..bag.paths import read_text_input


SPEC_KEYS = ('params', 'base', 'grid', 'cases', 'duration', 'stop_after_lock', 'force',
             'force_profile', 'long_run')


DEFAULT_DURATION = 1.0      # s, as `umbrella_sim simulate`


class SpecError(ValueError):
    """The SPEC cannot be run; the message names the key, case and parameter."""


@dataclass
class Case:
    index: int                  # 1-based position in the SPEC (grid first, then cases)
    overrides: dict             # what the SPEC sets for this case (base + grid/case values)
    params: dict                # every parameter, validated (UmbrellaParams.as_dict())
    duration: float
    stop_after_lock: float | None
    force_profile: list | None  # [(t, F)] read from the CSV, or None
    force_profile_path: str | None
    case_id: str = ''

    def label(self, names) -> str:
        return ', '.join(f'{n}={self.overrides[n]}' for n in names if n in self.overrides)

    def task(self, mcap_dir: str | None) -> dict:
        """Return what a worker needs (plain data, pickles anywhere)."""
        return {'case_id': self.case_id, 'params': self.params, 'duration': self.duration,
                'stop_after_lock': self.stop_after_lock, 'force_profile': self.force_profile,
                'mcap_dir': mcap_dir}


@dataclass
class Sweep:
    path: str
    cases: list
    axes: list                  # grid parameter names, in SPEC order
    swept: list                 # every parameter name the grid or the cases set
    duplicates: list = field(default_factory=list)   # (index, index of the same case)
    text: str = ''              # the SPEC as read (copied to DIR/spec.yaml)


# ------------------------------------------------------------------ the SPEC
def _number(where: str, value: Any, low: float, low_open: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or (value <= low if low_open else value < low):
        raise SpecError(f'{where}: {value!r} must be a finite number '
                        f"{'>' if low_open else '>='} {low:g}")
    return float(value)


def case_id(params: dict, duration: float, stop_after_lock, force_profile) -> str:
    """Key of a case in the store: its full parameters, run options and package version."""
    doc = {'umbrella_sim': __version__, 'params': params, 'duration': duration,
           'stop_after_lock': stop_after_lock, 'force_profile': force_profile}
    blob = json.dumps(doc, sort_keys=True, separators=(',', ':'))
    return hashlib.sha256(blob.encode('utf-8')).hexdigest()[:16]


def case_key(run) -> dict:
    """
    Return the parameters a case is stored by: every value of its run, as it resolves.

    run: the planar record or UmbrellaRibsParams (case_models' third).  Its as_dict, less a
    rib's own value that every rib takes without it: an umbrella however it is spelled
    (rib1.hinge_coulomb: 0.5 or rib.hinge_coulomb: [0, 0.5, 0]; rib1.hinge_coulomb: 0 or
    nothing; hub_radius: 0 or nothing) is one case.
    """
    from ..core.umbrella3d.params3d import RIB_SPECS

    out = run.as_dict()
    planar = getattr(run, 'planar', None)
    for name, values in list(out.items()):
        if planar is None or not isinstance(values, list):
            continue
        alone = RIB_SPECS[name].default if name in RIB_SPECS else getattr(planar, name)
        if all(v == alone for v in values):
            out[name] = alone
            if name in RIB_SPECS:
                del out[name]
    return out


def case_models(params: dict) -> tuple:
    """
    Return (the planar record, the umbrella's values, the run's parameters) of a case.

    params: a case's (Case.params: the planar record's values and the umbrella's, by their
    node names); the run's: UmbrellaRibsParams with ribs >= 2, else the planar record.
    """
    from ..core.params import UmbrellaParams
    from ..core.registry import SPECS
    from ..core.umbrella3d.params3d import umbrella_model, umbrella_values

    planar = UmbrellaParams.from_mapping({k: v for k, v in params.items()
                                          if k in SPECS}).validated()
    umbrella = umbrella_values({k: v for k, v in params.items() if k in UMBRELLA_NAMES})
    return planar, umbrella, umbrella_model(planar, umbrella)


#: a spec of at least this many cases reports its checking (progress(done, total))
CHECK_PROGRESS_CASES = 10_000


def load_spec(path: str, progress=None) -> Sweep:
    """
    Read and check the whole SPEC; every case's parameters validated as the CLI does.

    progress(done, total): called every 1 % of the cases (at least 1000) while they are
    checked, when there are CHECK_PROGRESS_CASES or more (10^6 cases take minutes).
    """
    from ..core.registry import check_types
    from ..core.umbrella3d.params3d import (check_umbrella_types, refuse_empty_rib_lists,
                                            umbrella_model, umbrella_values)
    from ..core.step_rule import physics_step_of, smallest_step_of
    from ..ros.params_file import load_params_file, load_yaml_as_ros

    try:
        text = read_text_input(path, 'sweep spec')
        doc = load_yaml_as_ros(text)        # typed as a params file is
    except ValueError as exc:       # missing, not a regular file, unreadable, not text
        raise SpecError(str(exc)) from None
    except yaml.YAMLError as exc:
        raise SpecError(f'sweep spec {path}: not valid YAML ({exc})') from None
    if not isinstance(doc, dict):
        raise SpecError(f'sweep spec {path}: expected a mapping with base/grid/cases')
    unknown = sorted(set(doc) - set(SPEC_KEYS))
    if unknown:
        raise SpecError(f"sweep spec {path}: unknown key(s) {', '.join(map(str, unknown))}; "
                        f"known: {', '.join(SPEC_KEYS)}")
    here = os.path.dirname(os.path.abspath(path))

    def rel(p):
        return p if os.path.isabs(p) else os.path.join(here, p)

    params_file = doc.get('params')
    if params_file is not None and not isinstance(params_file, str):
        raise SpecError(f'sweep spec {path}: params: expected a file name')
    base = doc.get('base') or {}
    grid = doc.get('grid') or {}
    explicit = doc.get('cases') or []
    if not isinstance(base, dict):
        raise SpecError(f'sweep spec {path}: base: expected a mapping of parameter overrides')
    if not isinstance(grid, dict):
        raise SpecError(f'sweep spec {path}: grid: expected a mapping name -> list of values')
    for name, values in grid.items():
        if not isinstance(values, list) or not values:
            raise SpecError(f'sweep spec {path}: grid: {name}: '
                            'expected a non-empty list of values')
    if not isinstance(explicit, list) or not all(isinstance(c, dict) for c in explicit):
        raise SpecError(f'sweep spec {path}: cases: expected a list of mappings of overrides')
    if not grid and not explicit:
        raise SpecError(f'sweep spec {path}: no cases: give grid and/or cases')
    duration = _number(f'sweep spec {path}: duration', doc.get('duration', DEFAULT_DURATION),
                       0.0, True)
    long_run = doc.get('long_run', False)
    if not isinstance(long_run, bool):
        raise SpecError(f'sweep spec {path}: long_run: expected true or false')
    stop_after_lock = doc.get('stop_after_lock')
    if stop_after_lock is not None:
        stop_after_lock = _number(f'sweep spec {path}: stop_after_lock', stop_after_lock, 0.0,
                                  False)
    base = dict(base)
    if doc.get('force') is not None:
        if doc.get('force_profile') is not None:
            raise SpecError(f'sweep spec {path}: give force or force_profile, not both')
        # force is every case's sleeve_force: no part of the SPEC may set its own
        for where, c in (('base', base), ('grid', grid), *(('cases', c) for c in explicit)):
            if 'sleeve_force' in c:
                raise SpecError(f'sweep spec {path}: force and {where}: sleeve_force both set '
                                "(force is every case's sleeve_force; sweep sleeve_force "
                                'without it)')
        if isinstance(doc['force'], bool) or not isinstance(doc['force'], (int, float)):
            raise SpecError(f"sweep spec {path}: force: {doc['force']!r} is not a number")
        base['sleeve_force'] = doc['force']     # its range is checked with each case's model
    profile = profile_path = None
    if doc.get('force_profile') is not None:
        if not isinstance(doc['force_profile'], str):
            raise SpecError(f'sweep spec {path}: force_profile: expected a CSV file name')
        profile_path = rel(doc['force_profile'])
        try:        # its rows once; each case's model judges them (below)
            profile_file = parse_force_profile(profile_path)
        except ValueError as exc:
            raise SpecError(f'sweep spec {path}: force_profile: {exc}') from None
    if params_file is not None:
        params_file = rel(params_file)
    params_file = params_file or default_params_file()
    try:        # read once for every case (each read it anew: ~14 ms a case, 4 h for 10^6)
        from_file = load_params_file(params_file) if params_file else None
        check_umbrella_types(from_file or {})       # typed as the node reads the file
    except ValueError as exc:
        raise SpecError(f'sweep spec {path}: params: {exc}') from None

    axes = list(grid)
    overrides_list = [dict(base, **dict(zip(axes, combo)))
                      for combo in itertools.product(*grid.values())] if grid else []
    overrides_list += [dict(base, **c) for c in explicit]
    swept = list(axes)
    for c in explicit:
        swept += [n for n in c if n not in swept]
    sweep = Sweep(path=os.path.abspath(path), cases=[], axes=axes, swept=swept, text=text)
    seen: dict[str, int] = {}
    total = len(overrides_list)
    every = max(1000, total // 100) if progress and total >= CHECK_PROGRESS_CASES else 0
    for index, overrides in enumerate(overrides_list, start=1):
        if every and (index % every == 0 or index == total):
            progress(index, total)
        source = 'grid' if index <= len(overrides_list) - len(explicit) else 'cases'
        try:
            check_offline_names(overrides, 'parameters')      # (as simulate's --set)
            check_types(overrides)          # typed YAML, as a params file (the node's rule)
            check_umbrella_types(overrides, params_file=False)
            resolved = resolve_params(overrides, params_file, from_file)
            check_lock_given(resolved, f"lock={overrides['lock']}" if 'lock' in overrides
                             else None)
            if duration / smallest_step_of(resolved) > LONG_RUN_STEPS:   # (cheap first)
                check_run_length(duration, physics_step_of(resolved), long_run,
                                 'long_run: true', 'duration')
            # the umbrella of N ribs (ribs, hub..., rib.<name> lists), checked with its model
            given = {k: v for k, v in {**(from_file or {}), **overrides}.items()
                     if k in UMBRELLA_NAMES}
            refuse_empty_rib_lists(given)
            umbrella = umbrella_values(given)
            run = umbrella_model(resolved, umbrella)
            params = {**resolved.as_dict(), **umbrella}
        except ValueError as exc:
            shown = ', '.join(f'{k}={v!r}' for k, v in overrides.items()
                              if source == 'cases' or k not in base or base[k] != v)
            raise SpecError(f'sweep spec {path}: case {index} ({source}: {shown}): '
                            f'{exc}') from None
        if profile_path is not None:
            try:    # against the case's model (the umbrella: its weakest link), named by line
                profile = [list(row) for row in profile_file.checked(run)]
            except ValueError as exc:
                raise SpecError(f'sweep spec {path}: case {index}: {exc}') from None
        case = Case(index=index, overrides=overrides, params=params, duration=duration,
                    stop_after_lock=stop_after_lock, force_profile=profile,
                    force_profile_path=profile_path)
        case.case_id = case_id(case_key(run), duration, stop_after_lock, profile)
        if case.case_id in seen:
            sweep.duplicates.append((index, seen[case.case_id]))
            continue
        seen[case.case_id] = index
        sweep.cases.append(case)
    return sweep
