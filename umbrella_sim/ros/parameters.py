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
ROS parameters from the registry: typed, ranged descriptors and the coercions rclpy lacks.

Every parameter of umbrella_node and deploy_controller is declared statically typed
(``dynamic_typing=False``) with its range and its rule in the descriptor, read-only when it is
fixed at start (core.registry.REGISTRY).  ``coerce_parameter`` takes an integer literal for a
double (``-p v0:=-1``) and a whole double for an integer, as the other interfaces do.

``set_refusal`` says why a runtime set is refused, naming the parameter, before rclpy's own
checks: rclpy applies the descriptors (read-only, type, range) before any on-set callback and
its reasons name no parameter for a wrong type ("Wrong parameter type, expected
'Type.DOUBLE' got 'Type.STRING'"), do not say why for a read-only one, and an undeclared name
raises ParameterNotDeclaredException with an empty list; a pre-set callback cannot refuse.
"""
from __future__ import annotations

from dataclasses import replace
import re

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType, SetParametersResult)
from rclpy.exceptions import ParameterNotDeclaredException

from ..core.registry import check_known_names, defaults, NOW, REGISTRY, RESET, START


# --------------------------------------------------------------------- parameters
_APPLIES = {RESET: 'a runtime set applies on ~/reset', NOW: 'a runtime set applies at once',
            START: 'read-only: fixed when the node starts'}


_ROS_TYPES = {float: ParameterType.PARAMETER_DOUBLE, int: ParameterType.PARAMETER_INTEGER,
              str: ParameterType.PARAMETER_STRING, bool: ParameterType.PARAMETER_BOOL}


def descriptor(name: str, spec=None) -> ParameterDescriptor:
    """Build the statically typed descriptor of a parameter from the registry (or spec)."""
    p = REGISTRY[name] if spec is None else spec
    constraints = [f'range {p.range_text()}' if p.low is not None or p.high is not None
                   else ('one of ' + p.range_text() if p.choices else '')]
    if p.rule:
        constraints.append(p.rule.replace('`', ''))
    constraints.append(_APPLIES[p.applies])
    if name == 'sleeve_force':
        constraints.append('command the running force on the sleeve_force topic')
    d = ParameterDescriptor(
        name=name, type=_ROS_TYPES[p.type], description=f'{p.doc} ({p.unit})',
        additional_constraints='; '.join(c for c in constraints if c),
        read_only=p.applies == START, dynamic_typing=False)
    if p.low is not None and p.high is not None:
        if p.type is int:
            d.integer_range = [IntegerRange(from_value=int(p.low), to_value=int(p.high),
                                            step=1)]
        elif p.type is float:
            d.floating_point_range = [FloatingPointRange(from_value=float(p.low),
                                                         to_value=float(p.high), step=0.0)]
    return d


def coerce_parameter(param, spec=None):
    """
    Return param with the registry's type where the value converts exactly, else unchanged.

    Param.exact's rule: an integer literal for a double parameter (`-p v0:=-1`, `ros2 param
    set ... marker_magnification 100`) becomes the double; a whole double for an integer
    parameter the integer.  Anything else is left for rclpy's static type check, which
    refuses it.
    """
    from rclpy.parameter import Parameter
    spec = REGISTRY.get(param.name) if spec is None else spec
    if spec is None or param.type_ not in (Parameter.Type.INTEGER, Parameter.Type.DOUBLE):
        return param
    value = spec.exact(param.value)
    if type(value) is type(param.value):
        return param
    return Parameter(param.name, Parameter.Type.from_parameter_value(value), value)


def parameter_defaults() -> dict:
    """Return name -> default of every parameter umbrella_node declares."""
    return defaults()


def declare_from_registry(node, names) -> dict:
    """
    Declare the registry's parameters names on node; return name -> value given or default.

    Statically typed (``descriptor``); an integer literal given for a double (``-p v0:=-1``)
    is taken as the double before rclpy's type check sees it.  ValueError naming the
    parameter, the value given and the rule it breaks.
    """
    overrides = node._parameter_overrides     # (rclpy keeps what -p and files gave here)
    for name, override in list(overrides.items()):
        overrides[name] = coerce_parameter(override)
    return {name: _declared(node, REGISTRY[name], descriptor(name)) for name in names}


def _declared(node, spec, d: ParameterDescriptor, name: str | None = None):
    """
    Declare one parameter of spec (by name, else spec.name) with descriptor d; its value.

    ValueError naming the parameter, the value given and the rule it breaks (rclpy's own
    refusals of a wrong type or an out-of-range value name neither).
    """
    from rclpy.exceptions import InvalidParameterTypeException

    name = name or spec.name
    try:
        return node.declare_parameter(name, spec.default, d).value
    except InvalidParameterTypeException:
        given = node._parameter_overrides[name]
        raise ValueError(type_refusal(name, given, spec.type_name)) from None
    except Exception:  # noqa: BLE001 - rclpy's range refusal: say the registry's rule
        value = node._parameter_overrides[name].value
        try:
            spec.check(value, f'parameter {name}')
        except ValueError as exc:
            raise ValueError(str(exc)) from None
        raise


def known_parameter_names() -> set[str]:
    """Return every name umbrella_node declares: the registry's, the umbrella's, rib.<name>."""
    from ..core.umbrella3d.params3d import umbrella_parameter_names

    return set(parameter_defaults()) | umbrella_parameter_names()


def declare_umbrella(node) -> dict:
    """
    Declare the umbrella's parameters on node (read-only); return params3d.umbrella_values.

    Its own (params3d.UMBRELLA_SPECS: ribs, hub_radius, base...) typed as the registry's,
    each rib's own values as rib.<name> double arrays, one entry per rib (not given: None,
    every rib takes the planar or default value), and the rib<k>.<name> overrides given (a
    double each).  Fixed at start: the number of ribs
    sets the topics and the joint names.  ValueError naming the parameter.
    """
    from rclpy.exceptions import InvalidParameterTypeException
    from rclpy.parameter import Parameter

    from ..core.umbrella3d.params3d import (refuse_empty_rib_lists, RIB_LIST_PREFIX,
                                            rib_list_specs, rib_override_index,
                                            rib_override_spec, UMBRELLA_SPECS,
                                            umbrella_values)

    overrides = node._parameter_overrides
    values = {}
    for name, spec in UMBRELLA_SPECS.items():
        if name in overrides:
            overrides[name] = coerce_parameter(overrides[name], spec)
        values[name] = _declared(node, spec, descriptor(name, replace(spec, applies=START)))
    for name, spec in rib_list_specs().items():
        ros_name = RIB_LIST_PREFIX + name
        d = ParameterDescriptor(
            name=ros_name, type=ParameterType.PARAMETER_DOUBLE_ARRAY, read_only=True,
            dynamic_typing=False,
            description=f'per rib, one value each (rib 0 first): {spec.doc} ({spec.unit})',
            additional_constraints=f'each {spec.range_text()}; not given: every rib takes '
                                   f'{name} (its default or the planar value)')
        given = overrides.get(ros_name)
        if given is not None:       # (given, not left out: [] is no rib's value)
            refuse_empty_rib_lists({ros_name: given.value or []})
        if given is not None and given.type_ == Parameter.Type.INTEGER_ARRAY:
            overrides[ros_name] = Parameter(ros_name, Parameter.Type.DOUBLE_ARRAY,
                                            [float(v) for v in given.value])
        try:
            values[ros_name] = node.declare_parameter(
                ros_name, Parameter.Type.DOUBLE_ARRAY, d).value
        except InvalidParameterTypeException:
            raise ValueError(type_refusal(ros_name, overrides[ros_name], 'double[]')) from None
    for name in sorted(overrides):      # rib<k>.<name>: one rib's value, where given
        spec = rib_override_spec(name)
        if spec is None:
            continue
        overrides[name] = coerce_parameter(overrides[name], spec)
        d = descriptor(name, replace(spec, name=name, applies=START,
                                     doc=f"rib {rib_override_index(name)}'s own: {spec.doc}"))
        values[name] = _declared(node, spec, d, name)
    return umbrella_values(values)


def type_refusal(name: str, given, expected: str) -> str:
    """Return the refusal of a value of the wrong type: the parameter, the value, both types."""
    return (f'parameter {name}={given.value!r}: must be of type {expected}, got '
            f'{given.type_.name.lower()}')


def wrong_type_text(node, exc) -> str:
    """
    Return rclpy's InvalidParameterTypeException for a -p value as type_refusal says it.

    For the parameters rclpy declares itself from the overrides (use_sim_time,
    qos_overrides.*), whose exception ends a traceback otherwise; node: the node it was
    declared on (the value given, from its overrides), or None (the value as rclpy's text
    has it); the text as it is if it cannot be read.
    """
    text = ' '.join(str(exc).split())
    found = re.fullmatch(r"Trying to set parameter '(.+?)' to '(.*)' of type '(\w+)', "
                         r"expecting type '(?:Type\.)?(\w+)': .*", text)
    if found is None:
        return text
    name, value, got, expected = found.groups()
    given = getattr(node, '_parameter_overrides', {}).get(name)
    if given is not None:
        return type_refusal(name, given, expected.lower())
    shown = repr(value) if got == 'STRING' else value
    return (f'parameter {name}={shown}: must be of type {expected.lower()}, got '
            f'{got.lower()}')


#: why a read-only parameter is: the registry's are read at start; ROS's own (qos_overrides.*,
#: start_type_description_service) when the node creates its publishers and services
_READ_ONLY_WHY = 'it is fixed when the node starts; restart the node with -p {name}:=VALUE'


def rib_override_refusal(name: str, ribs: int) -> str | None:
    """
    Return why a runtime set of a rib<k>.<name> not given at start is refused (None: no such).

    A rib's own value is declared only where given at start, but any rib's is a parameter the
    node knows: read-only, as every umbrella value (or no rib k of the node's ribs).
    """
    from ..core.umbrella3d.params3d import rib_override_index, rib_override_spec

    try:
        if rib_override_spec(name) is None:
            return None
    except ValueError:          # (rib<k>.<unknown>: the unknown name's refusal)
        return None
    k = rib_override_index(name)
    if ribs < 2:
        return (f'parameter {name}: the node runs the planar model (ribs 1), which has no '
                f'per-rib values; restart the node with -p ribs:=N -p {name}:=VALUE')
    if k >= ribs:
        return f'parameter {name}: there are ribs 0 .. {ribs - 1}'
    return (f"parameter {name} is read-only: a rib's own value is fixed when the node starts; "
            f'restart the node with -p {name}:=VALUE')


def set_refusal(node, param) -> str | None:
    """
    Return why node refuses a runtime set of param, naming it; None if rclpy's checks pass.

    In the order a user needs them: an undeclared name raises ``UnknownParameter`` (did you
    mean ...?, as at start); then read-only (and why), a value that cannot be unset, the
    wrong type (after ``coerce_parameter``'s exact conversions), and out of the registry's
    range (its own message, as at start and offline).
    """
    from rclpy.parameter import Parameter

    name = param.name
    if not node.has_parameter(name):
        # (the umbrella's per-rib names: umbrella_node's, which has ribs)
        ribs = (rib_override_refusal(name, node.ribs) if hasattr(node, 'ribs') else None)
        if ribs is not None:
            return ribs
        try:
            check_known_names([name], node.get_parameters_by_prefix('').keys(),
                              f'set on {node.get_fully_qualified_name()}')
        except ValueError as exc:
            raise UnknownParameter(str(exc), name) from None
    descriptor = node.describe_parameter(name)
    if descriptor.read_only:
        return f'parameter {name} is read-only: {_READ_ONLY_WHY.format(name=name)}'
    if param.type_ == Parameter.Type.NOT_SET:
        return (f'parameter {name} cannot be unset: it is declared with a type '
                f'({Parameter.Type(descriptor.type).name.lower()}); set a value instead')
    param = coerce_parameter(param)
    spec = REGISTRY.get(name)
    if not descriptor.dynamic_typing and param.type_.value != descriptor.type:
        expected = spec.type_name if spec else Parameter.Type(descriptor.type).name.lower()
        return type_refusal(name, param, expected)
    if spec is not None:
        try:
            spec.check(param.value)
        except ValueError as exc:
            return str(exc)
    return None


class UnknownParameter(ParameterNotDeclaredException):
    """
    A set of a name the node does not declare, as rclpy raises it, with a text naming it.

    rclpy's parameter services put str(exception) in the SetParametersResult's reason.
    """

    def __init__(self, message: str, name: str):
        super().__init__([name])
        self.message = message

    def __str__(self) -> str:
        return self.message


class NamedRefusals:
    """
    A mixin before rclpy's Node: every runtime set refused with a reason naming the parameter.

    umbrella_node's and deploy_controller's: rclpy's descriptor checks, which run before
    any on-set callback, would answer first with reasons that do not (set_refusal).
    """

    def set_parameters_atomically(self, parameter_list) -> SetParametersResult:
        """
        Set parameters (rclpy's SetParameters services call this), refusing with our reasons.

        Every refusal names the parameter and says why (set_refusal); an unknown name raises
        ParameterNotDeclaredException (as rclpy does) whose text names it and suggests the
        closest declared one.
        """
        for param in parameter_list:
            reason = set_refusal(self, param)
            if reason is not None:
                return SetParametersResult(successful=False, reason=reason)
        return super().set_parameters_atomically(parameter_list)

    def set_parameters(self, parameter_list) -> list[SetParametersResult]:
        """Set parameters one at a time (rclpy's semantics), each as set_parameters_atomically."""
        return [self.set_parameters_atomically([param]) for param in parameter_list]
