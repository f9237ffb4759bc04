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
ROS 2 parameter sources: params YAML files, ``-p`` overrides, and what a node may be given.

A ROS 2 params file maps node-name patterns ('/**', '/*', 'umbrella_node', '/a1/umbrella_node')
to ``ros__parameters``.  rcl parses it with its own typing (a plain 72.0e9 is a double, a
quoted "-0.5" a string) and refuses a key given twice; these readers apply the same rules
first, so that a bad file gets a one-line error naming the file instead of an rcl traceback,
and the offline tools read the same files the nodes take.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import functools
import math
import re

from ..bag.paths import read_text_input
from ..core.registry import check_known_names, NODE_PARAMETERS_LISTED, unknown_names


def _flatten(values: dict, prefix: str = '') -> dict:
    """Nested mappings are dotted parameter names in ROS 2 (`a: {b: 1}` is `a.b`)."""
    out = {}
    for key, value in values.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            out.update(_flatten(value, name + '.'))
        else:
            out[name] = value
    return out


#: a plain (unquoted) scalar rcl's params parser reads as a double: strtod's forms, which
#: include 72.0e9 (YAML 1.1, and so PyYAML, wants a sign in the exponent: a string to it)
_ROS_DOUBLE = re.compile(r'(?:[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|[-+]?\.(inf|Inf|INF)'
                         r'|\.(nan|NaN|NAN))$')      # the whole value (PyYAML: match only)


def load_yaml_as_ros(text: str):
    """
    Load YAML typed as rcl types a params file; a mapping with a key twice is an error.

    A plain scalar in one of strtod's forms is a double (72.0e9 too), a quoted one a string
    ("-0.5"), as rclpy gives them to a node; YAML takes a repeated key's last value
    silently, rcl refuses the file.  yaml.YAMLError if it cannot be read.
    """
    import yaml

    return yaml.load(text, Loader=_ros_typed_loader())   # noqa: S506 - a SafeLoader


@functools.cache
def _ros_typed_loader():
    """Return the loader class of load_yaml_as_ros (made once: yaml imported on first use)."""
    import yaml

    # libyaml's parser where PyYAML has it (the pure-Python scanner took ~8 of every 10 s of a
    # large file); the typing below is the resolver's and the constructor's, the same on both
    class RosTyped(getattr(yaml, 'CSafeLoader', yaml.SafeLoader)):

        def construct_mapping(self, node, deep=False):
            seen = set()
            for key_node, _ in node.value:
                key = self.construct_object(key_node, deep=deep)
                if key in seen:
                    raise yaml.MarkedYAMLError(
                        problem=f'key {key!r} given twice', problem_mark=key_node.start_mark)
                seen.add(key)
            return super().construct_mapping(node, deep)

    RosTyped.add_implicit_resolver('tag:yaml.org,2002:float', _ROS_DOUBLE,
                                   list('-+0123456789.'))
    return RosTyped


def read_params_file(path: str) -> dict[str, dict]:
    """
    Read the sections of a ROS 2 params YAML.

    {section (node name pattern): ros__parameters with dotted names} of a ROS 2 params
    YAML, or ValueError naming the file and the reason.  The same checks rcl makes, done
    first so that a bad file gets a one-line error instead of an rcl traceback.
    """
    import yaml  # local import: only the file path needs it

    text = read_text_input(path, 'params file')
    known = _parsed.get(path)
    if known is not None and known[0] == text:       # the same text: parsed once
        return {key: dict(values) for key, values in known[1].items()}
    try:
        doc = load_yaml_as_ros(text)
    except yaml.YAMLError as exc:
        reason = ' '.join(str(exc).split())
        raise ValueError(f'params file {path}: not valid YAML ({reason})') from None
    if not isinstance(doc, dict) or not doc:
        raise ValueError(f'params file {path}: expected a mapping of node names to '
                         '{ros__parameters: {...}}')
    sections = {}
    for key, section in doc.items():
        values = section.get('ros__parameters') if isinstance(section, dict) else None
        if not isinstance(values, dict):
            raise ValueError(f'params file {path}: section {key!r} has no ros__parameters '
                             'mapping')
        extra = sorted(set(section) - {'ros__parameters'})
        if extra:
            raise ValueError(f'params file {path}: section {key!r}: only ros__parameters is '
                             f"allowed, found {', '.join(map(str, extra))}")
        sections[str(key)] = _flatten(values)
        empty = sorted(name for name, value in sections[str(key)].items() if value is None)
        if empty:
            raise ValueError(f'params file {path}: section {key!r}: no value for '
                             f"{', '.join(empty)}")
    _parsed[path] = (text, sections)
    return {key: dict(values) for key, values in sections.items()}


#: the last text read from each params file and its sections: a process checks its files
#: before rclpy.init and again as its node starts, and parsing a large file is what costs
_parsed: dict[str, tuple[str, dict]] = {}


def section_matches(pattern: str, node_fqn: str) -> bool:
    """
    Tell whether a params-file section applies to a node.

    Whether a params-file section name applies to the node of fully qualified name
    node_fqn (ROS 2 rules: '/**' any namespace depth, '*' one token, no leading slash means
    relative to the root).
    """
    tokens = pattern.strip('/').split('/')
    regex = ''.join('(/[^/]+)*' if t == '**' else '/[^/]+' if t == '*' else '/' + re.escape(t)
                    for t in tokens)
    return re.fullmatch(regex, node_fqn) is not None


def load_params_file(path: str, node_name: str = 'umbrella_node') -> dict:
    """
    Return the parameters of a params YAML for node_name.

    The ``ros__parameters`` of a ROS 2 params YAML that apply to node_name in the root
    namespace (sections '/**', '/*', node_name, ...); a file with no such section is an
    error.
    """
    sections = read_params_file(path)
    merged: dict = {}
    for key, values in sections.items():
        if section_matches(key, '/' + node_name):
            merged.update(values)
    if not any(section_matches(key, '/' + node_name) for key in sections):
        raise ValueError(f'params file {path}: no section for node /{node_name} (sections: '
                         f"{', '.join(sections)}); use '/**' or '{node_name}'")
    return merged


#: the prefix of rclpy's QoS override parameters, and the parameters every rclpy node has
QOS_OVERRIDES = 'qos_overrides.'


USE_SIM_TIME = 'use_sim_time'


ROS_OWN_PARAMETERS = frozenset({USE_SIM_TIME, 'start_type_description_service'})


def params_files_in(ros_args: list[str]) -> list[str]:
    """
    Return the ``--params-file`` arguments of a command line, each read and checked.

    ValueError naming the file and the problem (rcl's own parse errors are tracebacks).
    """
    files = [ros_args[i + 1] for i, a in enumerate(ros_args[:-1]) if a == '--params-file']
    for path in files:
        read_params_file(path)
    return files


def param_rules_in(ros_args: list[str]) -> dict[str, str]:
    """
    Return the ``-p name:=value`` rules of a command line: name -> value text, the last one.

    Only those inside a ``--ros-args`` section (up to ``--``), as rcl reads them; a rule
    with a node's name before the parameter's (``node:name:=value``) is left out.
    """
    rules, inside = {}, False
    for i, arg in enumerate(ros_args):
        if arg in ('--ros-args', '--'):
            inside = arg == '--ros-args'
        elif inside and arg in ('-p', '--param') and i + 1 < len(ros_args):
            name, assign, value = ros_args[i + 1].partition(':=')
            if assign and ':' not in name:
                rules[name] = value
    return rules


def _kind(value) -> str:
    """Return a parameter value's ROS type, in words (bool, integer, double, string, list)."""
    for kind, types in (('bool', bool), ('integer', int), ('double', float), ('string', str)):
        if isinstance(value, types):
            return kind
    return 'list'


def _a(kind: str) -> str:
    """Return 'a kind' or 'an kind' (an integer)."""
    return f"{'an' if kind[0] in 'aeiou' else 'a'} {kind}"


def _as_rcl_typed(value, kept):
    """
    Return a rule's value as rcl types it where YAML and rcl differ: a number's text.

    rcl reads 'NaN', 'nan', 'inf' (strtod's words) as doubles where YAML has strings (its
    NaN is '.nan'); a list element alike.
    """
    if isinstance(value, str) and isinstance(kept, float):
        try:
            return float(value)
        except ValueError:
            return value
    if isinstance(value, list) and isinstance(kept, (list, tuple)) and len(value) == len(kept):
        return [_as_rcl_typed(v, k) for v, k in zip(value, kept)]
    return value


def _same_value(given, kept) -> bool:
    """Tell whether a rule's value is the one a node was given (numbers by value, NaN too)."""
    if kept is None:        # (rcl gives an empty list no type: not set)
        return given == [] or given is None
    kinds = {_kind(given), _kind(kept)}
    if 'list' in kinds:
        return (kinds == {'list'} and len(given) == len(kept)
                and all(map(_same_value, given, kept)))
    if kinds <= {'integer', 'double'}:
        return given == kept or (given != given and kept != kept)
    return len(kinds) == 1 and given == kept


def check_param_rules(rules: dict, overrides: dict, params_files=()) -> dict:
    """
    Refuse a ``-p`` value rcl dropped: ValueError naming the parameter and the value.

    Where a params file gives a parameter and a ``-p`` rule gives it a value of another type
    (a string or a list for a double: ``-p v0:=abc``), rcl keeps the file's value without a
    word, and the node would run on it.  rules: param_rules_in's; overrides: the node's
    (rclpy's _parameter_overrides, before any is coerced); params_files: the command line's,
    named in the refusal.  A rule whose value, typed as rcl types it (load_yaml_as_ros,
    _as_rcl_typed), is not the one the node was given is refused, but for a whole double
    where the file gives an integer (``-p elements_per_segment:=4.0``), which the node takes
    as that integer, as it does without a file: returned, name -> the integer, for the node
    to take in place of the file's.
    """
    import yaml

    taken = {}
    for name, text in rules.items():
        given = overrides.get(name)
        try:
            value = load_yaml_as_ros(text)
        except yaml.YAMLError:      # (rcl refused the arguments: init_ros said so)
            continue
        if given is None:
            continue
        kept = given.value
        value = _as_rcl_typed(value, kept)
        if _same_value(value, kept):
            continue
        if (_kind(kept) == 'integer' and _kind(value) == 'double' and math.isfinite(value)
                and value == int(value)):
            taken[name] = int(value)
            continue
        files = ''.join(f'params file {path} or ' for path in params_files)
        raise ValueError(
            f"parameter {name}={text!r} (-p): not taken: rcl keeps {name}'s value {kept!r} "
            f'({_a(_kind(kept))}, from {files}an earlier -p) without a word where -p gives one '
            f'of another type ({_a(_kind(value))}); give {name} {_a(_kind(kept))}')
    return taken


def names_the_node(pattern: str) -> bool:
    """
    Tell whether a params-file section addresses a node by its name.

    'umbrella_node', '/a1/umbrella_node', '/**/umbrella_node' do; a wildcard ('/**', '/*',
    '/a1/*') does not.
    """
    return pattern.strip('/').split('/')[-1] not in ('*', '**')


def shared_section_warning(path: str, section: str, node_fqn: str, problems) -> str:
    """Return the warning for names a wildcard section gives that a node does not know."""
    what = 'parameters' if len(problems) > 1 else 'a parameter'
    return (f"params file {path}: section {section!r} gives {', '.join(problems)}, not "
            f"{what} of {node_fqn}: ignored here (another node's, in a file shared by every "
            'node?)')


@dataclass
class ParameterSources:
    """What check_parameter_sources found: the qos_overrides.* names, and the warnings."""

    #: given by -p or in a section naming the node: one no topic has is an error
    qos_overrides: set = field(default_factory=set)
    #: given in a wildcard section ('/**'): one no topic has is another node's (a warning)
    shared_qos_overrides: dict = field(default_factory=dict)   # name -> (file, section)
    #: a wildcard section's names the node does not know, each with a "did you mean"
    warnings: list = field(default_factory=list)
    #: -p values the node takes in place of a file's that rcl kept (check_param_rules)
    taken: dict = field(default_factory=dict)


def check_parameter_sources(node_fqn: str, params_files, given, known,
                            listed: str = NODE_PARAMETERS_LISTED,
                            shared=(), rules=None, own=None) -> ParameterSources:
    """
    Check the params files and parameter names a ROS node was started with.

    Every params file has a section for the node, and every parameter given for it by
    name (``-p``, ``given``, or a section that names the node, 'umbrella_node' or
    '/a1/umbrella_node') is one it knows (``known``, besides ROS_OWN_PARAMETERS): a typo
    is a ValueError naming it, never a silent default.  A wildcard section ('/**', '/*',
    ...) serves every node of a launch (robot_state_publisher's ``publish_frequency``
    there is not a mistake): a name the node does not know there is a warning naming it,
    with a "did you mean", and rclpy ignores it; the sibling umbrella_sim node's
    parameters (``shared``) are taken there silently.  rules: the command line's ``-p``
    rules (param_rules_in), each held against the value the node was given (``given``, the
    node's overrides by name: check_param_rules).  own(name): names no other node would
    give, checked as the node's in a wildcard section too (the umbrella's per-rib names,
    which the node reads from every section: a typo there was said to be ignored, then
    refused).  Returns the ``qos_overrides.*`` names given, for the node to check against
    the QoS its topics declare.
    """
    taken = check_param_rules(rules, given, params_files) if rules else {}
    known = set(known) | ROS_OWN_PARAMETERS
    found = ParameterSources(taken=taken)
    in_files = set()
    for path in params_files:
        sections = read_params_file(path)
        if not any(section_matches(key, node_fqn) for key in sections):
            raise ValueError(f'params file {path}: no section for node {node_fqn} '
                             f"(sections: {', '.join(sections)}); use '/**' or the "
                             "node's name")
        for key, values in sections.items():
            if not section_matches(key, node_fqn):
                continue
            names = {n for n in values if not n.startswith(QOS_OVERRIDES)}
            qos = {n for n in values if n.startswith(QOS_OVERRIDES)}
            if names_the_node(key):
                check_known_names(names, known, f'params file {path} (for {node_fqn})',
                                  listed)
                found.qos_overrides |= qos
            else:
                mine = {n for n in names if own is not None and own(n)}
                check_known_names(mine, known, f'params file {path} (section {key!r}, for '
                                  f'{node_fqn})', listed)
                problems = unknown_names(names - set(shared) - mine, known)
                if problems:
                    found.warnings.append(shared_section_warning(path, key, node_fqn,
                                                                 problems))
                found.shared_qos_overrides.update({n: (path, key) for n in qos})
            in_files |= set(values)
    names = [n for n in given if not n.startswith(QOS_OVERRIDES) and n not in in_files]
    check_known_names(names, known, f'-p for {node_fqn}', listed)
    found.qos_overrides |= {n for n in given if n.startswith(QOS_OVERRIDES)
                            and n not in in_files}
    return found


def check_qos_override_sources(node_fqn: str, found: ParameterSources, declared,
                               listed: str = NODE_PARAMETERS_LISTED,
                               why: str = '') -> list[str]:
    """
    Check the qos_overrides.* names given against those a node declared.

    A name given by -p or in a section naming the node that it did not declare is a
    ValueError (``why`` may say why none is); one of a wildcard section is returned as
    a warning, as check_parameter_sources treats other parameters.
    """
    check_known_names(found.qos_overrides, declared,
                      f'qos_overrides for {node_fqn}{why}', listed)
    by_section: dict = {}
    for name, where in found.shared_qos_overrides.items():
        by_section.setdefault(where, []).append(name)
    return [shared_section_warning(path, key, node_fqn, problems)
            for (path, key), names in sorted(by_section.items())
            for problems in [unknown_names(names, declared)] if problems]


class QoSOverrideValueError(ValueError):
    """A qos_overrides.* value no QoS takes (check_qos_override_values)."""


#: the largest history depth a DDS writer or reader takes (a 32-bit integer)
MAX_QOS_DEPTH = 2**31 - 1


def check_qos_override_values(given: dict, command: str, topics) -> None:
    """
    Refuse a qos_overrides value for one of a node's topics that no QoS takes, naming it.

    given: the node's parameter overrides (name -> rclpy Parameter); command: the resolved
    name of its subscription, topics: those of its publishers.  rclpy's own errors for
    such a value name neither the parameter nor its topic ('invalid allocator' for a
    negative depth, 'Unexpected QoS override for policy `reliability`'); a value of the
    wrong type is left to rclpy's type check.  QoSOverrideValueError.
    """
    from rclpy import qos

    enums = {'history': qos.HistoryPolicy, 'reliability': qos.ReliabilityPolicy,
             'durability': qos.DurabilityPolicy}
    prefixes = [f'{QOS_OVERRIDES}{command}.subscription.',
                *(f'{QOS_OVERRIDES}{topic}.publisher.' for topic in topics)]
    for name, parameter in sorted(given.items()):
        if not any(name.startswith(prefix) for prefix in prefixes):
            continue
        policy, value = name.rpartition('.')[2], parameter.value
        if policy == 'depth' and isinstance(value, int) and not 0 <= value <= MAX_QOS_DEPTH:
            rule = 'must be >= 0' if value < 0 else f'must be <= {MAX_QOS_DEPTH}'
            raise QoSOverrideValueError(f'parameter {name}={value}: {rule}')
        allowed = [m.name.lower() for m in enums.get(policy, ()) if m.name != 'UNKNOWN']
        if allowed and isinstance(value, str) and value.lower() not in allowed:
            raise QoSOverrideValueError(f'parameter {name}={value!r}: must be one of '
                                        f"{', '.join(allowed)}")


def init_ros(argv: list[str]) -> list[str]:
    """
    Check a process's params files, then initialise rclpy with its arguments.

    Return the ``--params-file`` arguments (params_files_in), or ValueError naming what is
    wrong: a params file, or ROS arguments rcl refuses (its parse errors are tracebacks, so
    the files are checked first).  rclpy installs no signal handlers: the process's own stop
    signals (signals.py) stay in charge.
    """
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    files = params_files_in(argv)
    try:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:    # RCLError, UnknownROSArgsError...: the arguments are wrong
        reason = ' '.join(str(exc).split())
        if type(exc).__name__ == 'UnknownROSArgsError':
            reason = f'unknown ROS arguments {reason}'
        if 'Sequence should be of same type' in reason:     # ([0, 0.1]: an int and a double)
            reason += ('; a list of doubles needs every value written as a double, '
                       '[0.0, 0.1] not [0, 0.1]')
        raise ValueError(f'invalid ROS arguments: {reason} (see --help)') from None
    return files
