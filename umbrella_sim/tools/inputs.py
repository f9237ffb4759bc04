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
What an offline run is given: its parameters (params file, options, --set) and force profile.

``umbrella_sim simulate`` and ``umbrella_sim sweep`` take the same ROS 2 params files as the
nodes (a ``/**`` file shared with umbrella_node and deploy_controller included), resolve them
with the same types and rules, and read a force profile as a CSV of (t, F) rows.  Every
refusal names the file, the line or the option, and why.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
import functools
import io
import os
import re
import sys

from ..bag.paths import read_text_input
from ..core.forcing import checked_profile
from ..core.params import check_values, UmbrellaParams
from ..core.registry import (check_known_names, check_types, CONTROLLER_PARAMETERS,
                             NODE_ONLY_PARAMS, NODE_PARAMETERS, SPECS)
from ..core.umbrella3d.params3d import (check_umbrella_types, names_a_rib,
                                        refuse_empty_rib_lists,
                                        RIB_LIST_PREFIX, umbrella_model,
                                        umbrella_parameter_names, umbrella_values)
from ..ros.params_file import check_parameter_sources, load_params_file
from ..ros.share import package_path


def default_params_file() -> str | None:
    """Return the package's config/umbrella.yaml (the source checkout's, or installed)."""
    return package_path('config', 'umbrella.yaml')


def _number(text: str) -> float:
    """Return a CSV field as a number: Python's float forms but for digit separators (1_0)."""
    if '_' in text:
        raise ValueError(text)
    return float(text)


def _is_number(text: str) -> bool:
    try:
        _number(text)
    except ValueError:
        return False
    return True


#: a unit a header names: in brackets, 't (s)', 'F [N]', or as a suffix, 't_ms', 'F_kN'
_UNIT = re.compile(r'[(\[]\s*([^)\]]*?)\s*[)\]]|_(ms|us|µs|min|kn|mn|lbf|lb)$', re.I)


def _header_problem(names: list[str]) -> str | None:
    """
    Say what a header's names tell against the columns t (s), F (N), or None.

    The columns are read by position; a header is free text, but one naming force first and
    time second, or another unit than s and N (t (ms), F (kN)), describes numbers that
    position would misread.
    """
    low = [name.lower() for name in names]
    if ((low[0].startswith('f') or 'force' in low[0])
            and (low[1].startswith('t') or 'time' in low[1])):
        return 'the columns are time then force (t,F), not force then time'
    for name, unit, what in zip(names, ('s', 'N'), ('time', 'force')):
        found = _UNIT.search(name)
        given = found and (found.group(1) if found.group(1) is not None else found.group(2))
        if given and given.lower() != unit.lower():
            return (f'{what} in {given}: the columns are time in s and force in N (SI); '
                    f'convert the column, or name it in {unit}')
    return None


@dataclass(frozen=True)
class ForceProfileFile:
    """
    A force profile CSV as read: its (t, F) rows and the line each came from.

    ``checked(model)`` judges the rows against a model (forcing.checked_profile: times
    finite, >= 0 and increasing, each F a command the model accepts, up to the bound of the
    umbrella's weakest link), a refusal naming the file and the line of the bad row.  A
    sweep reads its SPEC's profile once and checks it against each case's model.
    """

    path: str
    rows: tuple             # ((t, F), ...) as numbers, unchecked
    lines: tuple            # the line number of each row

    def checked(self, params=None) -> list[tuple[float, float]]:
        """Return the rows as (t, F) floats if the model takes them (default: planar defaults)."""
        return checked_profile(self.rows, params or UmbrellaParams(),
                               lambda i: f'force profile {self.path}:{self.lines[i]}')


def parse_force_profile(path: str) -> ForceProfileFile:
    """
    Read a CSV of (t, F) rows, an optional header line; what is not such a row is refused.

    Blank lines and lines starting with # are skipped; the first other line may be a header
    (neither of its two fields a number; one naming force then time, F,t, or another unit
    than s and N, t (ms), is refused), and a file of no rows.  ValueError naming the file
    and the line.  The rows are not judged against a model: ForceProfileFile.checked does.
    """
    rows, lines = [], []
    text = read_text_input(path, 'force profile').removeprefix('\ufeff')   # (Excel's BOM)
    try:
        parsed = list(csv.reader(io.StringIO(text, newline='')))
    except csv.Error as exc:
        raise ValueError(f'force profile {path}: not CSV ({exc})') from None
    first = True
    for lineno, row in enumerate(parsed, start=1):
        if not row or row[0].strip().startswith('#'):
            continue
        if len(row) < 2 or any(field.strip() for field in row[2:]):
            raise ValueError(f'force profile {path}:{lineno}: expected two columns t,F, '
                             f'got {row}')
        header, first = first and not any(map(_is_number, row[:2])), False
        if header:
            problem = _header_problem([field.strip() for field in row[:2]])
            if problem:
                raise ValueError(f'force profile {path}:{lineno}: header {row[:2]}: {problem}')
            continue
        try:
            rows.append((_number(row[0]), _number(row[1])))
        except ValueError:
            raise ValueError(f'force profile {path}:{lineno}: not numbers: {row[:2]}') from None
        lines.append(lineno)
    if not rows:
        raise ValueError(f'force profile {path}: no (t, F) rows')
    return ForceProfileFile(path, tuple(rows), tuple(lines))


def read_force_profile(path: str, params=None) -> list[tuple[float, float]]:
    """
    Read a force profile CSV (parse_force_profile) and check it against the run's model.

    params: the model the profile drives (UmbrellaParams, or the umbrella of N ribs,
    UmbrellaRibsParams: its weakest link's bound); default the planar defaults.  Every
    refusal names the file and the line of the row (ForceProfileFile.checked).
    """
    return parse_force_profile(path).checked(params)


#: node parameters that ``--set`` may give offline: they shape the --mcap recording
RECORDING_PARAMS = ('publish_rate', 'marker_magnification')


#: an offline run of more physics steps than this needs the user's consent (--long-run): at
#: ~10 us a step (the default model) 10^8 steps take ~20 min, and --csv writes a row each
LONG_RUN_STEPS = 1e8


def check_run_length(duration: float, step: float, consent: bool, option: str,
                     what: str = '--duration') -> None:
    """
    Refuse a run of more than LONG_RUN_STEPS physics steps unless the user consented.

    ValueError naming the duration (what), its steps and how to consent (option): ``--duration
    1e9`` was taken and ran for years, writing as it went.
    """
    steps = duration / step
    if steps > LONG_RUN_STEPS and not consent:
        raise ValueError(f'{what} {duration:g}: {steps:.3g} physics steps of {step:g} s, '
                         f'more than {LONG_RUN_STEPS:.0e} (hours of computing or more); '
                         f'give {option} to run it anyway')


#: models whose lock is always plastic (a rigid mechanism stopped at a point)
RIGID_MODELS = ('rigid', 'rigid-fe')


def resolve_params(overrides: dict, params_file: str | None = None,
                   from_file: dict | None = None) -> UmbrellaParams:
    """
    Return an offline run's parameters, validated (a ValueError names the parameter).

    The params file (default config/umbrella.yaml, its node-only keys skipped), then the
    overrides; from_file: that file's parameters, if the caller has read them.  The planar
    record only: the umbrella's values (UMBRELLA_NAMES) are the caller's to take.
    """
    values: dict = {}
    params_file = params_file or default_params_file()
    if params_file:
        if from_file is None:
            from_file = load_params_file(params_file)
        params_file_warnings(params_file)       # a name unknown in a section naming the node
        # (a '/**' section's other names are another node's, as the node takes them)
        from_file = {k: v for k, v in from_file.items() if k in _KNOWN_IN_FILES}
        try:        # its own values first: an error names the file
            check_values({k: v for k, v in from_file.items()
                          if k in SPECS and k not in overrides})
        except ValueError as exc:
            raise ValueError(f'params file {params_file}: {exc}') from None
        values.update(from_file)
    # a file shared with the nodes: theirs; the umbrella's: build_params's
    values = {k: v for k, v in values.items() if k not in _NOT_PLANAR_NAMES}
    values.update({k: v for k, v in overrides.items() if k not in UMBRELLA_NAMES})
    return UmbrellaParams.from_mapping(values).validated()


#: deploy_controller's parameters, which a '/**' params file shared with it may hold
SHARED_NAMES = tuple(CONTROLLER_PARAMETERS)
#: the umbrella of N ribs' parameters (umbrella3d_parameters.md): its own, rib.<name> lists
UMBRELLA_NAMES = umbrella_parameter_names()
#: an offline run's parameter names: the planar model's and the umbrella's
_OFFLINE_NAMES = frozenset(SPECS) | UMBRELLA_NAMES
#: a params file's names that are not the planar record's (the nodes' and the umbrella's)
_NOT_PLANAR_NAMES = frozenset(NODE_ONLY_PARAMS) | frozenset(SHARED_NAMES) | UMBRELLA_NAMES
_KNOWN_IN_FILES = frozenset(SPECS) | _NOT_PLANAR_NAMES


def check_offline_names(names, source: str) -> None:
    """
    Refuse a name that is no offline run's parameter, with the name meant (ValueError).

    simulate's --set and a sweep's cases alike: the umbrella's names are known too, so a
    misspelt rib.<name> or rib<k>.<name> is suggested its right spelling.
    """
    if not _OFFLINE_NAMES.issuperset(names):        # (a sweep checks every case's)
        check_known_names(names, _OFFLINE_NAMES, source)


def params_file_warnings(params_file: str) -> list[str]:
    """
    Check a params file's names as umbrella_node does; return the warnings to print.

    An unknown name in a section naming umbrella_node is a ValueError (did you mean); in a
    '/**' section it is another node's: a warning naming it, unless it is a per-rib name
    (params3d.names_a_rib: the node's alone, a ValueError there too).  A file checked before
    and not changed since (its size and modification time) is not checked again: a sweep
    resolves every case's parameters on the same file.
    """
    try:
        stat = os.stat(params_file)
    except OSError:         # (check_parameter_sources names the file it cannot read)
        return list(_file_warnings.__wrapped__(params_file, None))
    return list(_file_warnings(params_file, (stat.st_size, stat.st_mtime_ns)))


@functools.lru_cache(maxsize=16)
def _file_warnings(params_file: str, version) -> tuple:
    """Return params_file_warnings of a file at its version (size, modification time)."""
    return tuple(check_parameter_sources('/umbrella_node', [params_file], (), _KNOWN_IN_FILES,
                                         shared=SHARED_NAMES, own=names_a_rib).warnings)


#: simulate's options that give a parameter: (argparse dest, parameter)
CLI_FLAGS = (('model', 'model'), ('elements_per_segment', 'elements_per_segment'),
             ('v0', 'v0'), ('force', 'sleeve_force'), ('lock', 'lock'),
             ('time_step', 'time_step'), ('publish_rate', 'publish_rate'))


def _given_once(given: dict, name: str, how: str) -> None:
    """Record that the command line gives parameter name (how); refuse a second time."""
    if name in given:
        raise ValueError(f'{how}: {name} is already given by {given[name]} (give each '
                         'parameter once)')
    given[name] = how


def umbrella_value(name: str, value):
    """Return an umbrella parameter's value from --set text: a rib.<name> list as YAML."""
    if name.startswith(RIB_LIST_PREFIX) and isinstance(value, str):
        import yaml

        text = value
        try:
            value = yaml.safe_load(value)
        except yaml.YAMLError:
            value = None
        if isinstance(value, list):     # (YAML 1.1 reads 1e-4 as text: a number all the same)
            value = [_number_text(v) for v in value]
        if not isinstance(value, list) or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            raise ValueError(f'--set {name}: a list of numbers, one per rib, comma-separated '
                             f'([0.0, 0.1, 0.0]); got {text!r}')
        refuse_empty_rib_lists({name: value})      # ([]: no rib's value, as on the node)
    return value


def _number_text(value):
    """Return a list element: a str that is a number (1e-4) as that float, else itself."""
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            pass
    return value


def build_params(args) -> UmbrellaParams:
    """
    Return the planar record of the options, --set and the params file (validated).

    The umbrella's values (UMBRELLA_NAMES) go to args.umbrella (params3d.umbrella_values:
    {} for the planar model), the run's model to args.model (params3d.umbrella_model: the
    planar record, or the umbrella of N ribs).
    """
    values: dict = {}
    umbrella: dict = {}
    given: dict = {}            # parameter -> the option that gave it, to refuse a second
    lock_given = None
    flags = {name: getattr(args, flag) for flag, name in CLI_FLAGS
             if getattr(args, flag) is not None}
    for flag, name in CLI_FLAGS:
        if name in flags:
            _given_once(given, name, f"--{flag.replace('_', '-')} {flags[name]}")
    for item in args.set or []:
        if '=' not in item:
            raise ValueError(f'--set {item!r}: expected name=value')
        name, value = (x.strip() for x in item.split('=', 1))
        _given_once(given, name, f'--set {name}={value}')
        if name in RECORDING_PARAMS:
            if not args.mcap:
                raise ValueError(f"--set {name}={value}: a parameter of umbrella_node's "
                                 'publication; offline it only shapes a --mcap recording '
                                 '(the summary comes from every physics step whatever the '
                                 'rate): add --mcap BAG_DIR')
            setattr(args, name, NODE_PARAMETERS[name].coerce(value))
            NODE_PARAMETERS[name].check(getattr(args, name))
            continue
        if name in UMBRELLA_NAMES:
            umbrella[name] = umbrella_value(name, value)
            continue
        if name in NODE_PARAMETERS:
            raise ValueError(f'--set {name}: a parameter of the live umbrella_node only, with '
                             'no meaning offline (see --duration, --mcap, --publish-rate)')
        check_offline_names([name], '--set')
        values[name] = value
        if name == 'lock':
            lock_given = f'--set lock={value}'
    values.update({name: value for name, value in flags.items() if name in SPECS})
    if args.lock is not None:
        lock_given = f'--lock {args.lock}'
    params_file = args.params or default_params_file()
    from_file = load_params_file(params_file) if params_file else {}
    params = resolve_params(values, params_file, from_file)
    for text in params_file_warnings(params_file) if params_file else ():
        print(f'umbrella_sim: warning: {text}', file=sys.stderr)
    node_duration = from_file.get('duration') if args.params else None
    if node_duration and getattr(args, 'duration', None) not in (None, node_duration):
        print(f'umbrella_sim: warning: params file {params_file}: duration {node_duration} is '
              "umbrella_node's (where it exits); offline the run takes --duration "
              f'({args.duration:g} s)', file=sys.stderr)
    check_lock_given(params, lock_given)
    refuse_empty_rib_lists(from_file, f'params file {params_file}: ')
    try:        # typed as the node reads the file: "5" is a string, [0, 0.1] refused
        check_umbrella_types({name: from_file[name] for name in UMBRELLA_NAMES & set(from_file)
                              if name not in umbrella})
    except ValueError as exc:
        raise ValueError(f'params file {params_file}: {exc}') from None
    for name in UMBRELLA_NAMES & set(from_file):
        umbrella.setdefault(name, from_file[name])
    try:        # (the core's rules; a value the file gave is named with the file)
        args.umbrella = umbrella_values(umbrella)
        args.model = umbrella_model(params, args.umbrella)
    except ValueError as exc:
        culprit = re.match(r'parameter ([\w.]+)[=:]', str(exc))
        if culprit and culprit.group(1) in (set(from_file) - set(given)) & UMBRELLA_NAMES:
            raise ValueError(f'params file {params_file}: {exc}') from None
        raise
    # what shapes a --mcap recording: --publish-rate / --set, else the params file's (a file
    # shared with the node), else the node's default
    for name in RECORDING_PARAMS:
        spec = NODE_PARAMETERS[name]
        if getattr(args, name) is None and name in from_file:
            try:
                check_types({name: from_file[name]})    # typed as the node reads the file
                setattr(args, name, spec.coerce(from_file[name]))
                spec.check(getattr(args, name))
            except ValueError as exc:
                raise ValueError(f'params file {params_file}: {exc}') from None
        elif getattr(args, name) is None:
            setattr(args, name, spec.default)
    return params


def check_lock_given(params: UmbrellaParams, given: str | None) -> None:
    """
    Refuse a lock asked for explicitly (given: how) that the model cannot take.

    A rigid model always stops plastically; a lock from a params file shared with flexible
    runs only gets the validity warning (outputs.lock_warning).
    """
    if given and params.model in RIGID_MODELS and params.lock == 'energy':
        raise ValueError(f'{given}: does not apply to model {params.model}, whose lock '
                         'is always plastic (a rigid mechanism stopped at a point keeps no '
                         'kinetic energy to redistribute); use lock plastic or a flexible '
                         'model')
