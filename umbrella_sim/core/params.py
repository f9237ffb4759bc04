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
The physics' parameters as one record, and the deploy controller's: built from the registry.

``UmbrellaParams`` has one field per model parameter of the registry (registry.SPECS), its
derived quantities (section, mass per length, sleeve heights, the force limits the link
carries, the physics step) and ``validated()``, which checks each value's range and the rules
that tie several together, naming the parameter.  ``ControllerConfig`` is the same for the
controller's parameters.  Every value is SI (m, kg, s, N, Pa, rad).
"""
from __future__ import annotations

import dataclasses
from dataclasses import fields
import math
from typing import Any, Mapping

from .registry import (check_known_names, check_types, coerce, CONTROLLER_PARAMETERS,
                       MIN_PHYSICS_STEP, MIN_YIELD_STRAIN, Param, SPECS)


#: parameters added after recordings were made, with the value an older recording (which
#: does not list them) was made with: replay re-runs it so
RECORDED_BEFORE_ADDED = {'phase_correction': False, 'step_follows_mesh': False}


def recorded_params(values: Mapping[str, Any]) -> 'UmbrellaParams':
    """
    Return the model a recording's parameters describe, validated (ValueError if none).

    Its recorded model parameters (node ones are skipped) and, for those added since, the
    value it was made with (RECORDED_BEFORE_ADDED).
    """
    return UmbrellaParams.from_mapping(
        {**RECORDED_BEFORE_ADDED, **{k: v for k, v in values.items() if k in SPECS}}
    ).validated()


def _exact_fields(record, specs: Mapping[str, Param]) -> None:
    """Give a record's numbers their parameter's type where they convert exactly (Param.exact)."""
    for name, spec in specs.items():
        value = getattr(record, name)
        exact = spec.exact(value)
        if exact is not value:
            object.__setattr__(record, name, exact)


class _DerivedQuantities:
    """Methods of UmbrellaParams; its fields come from the registry (SPECS)."""

    def __post_init__(self):
        _exact_fields(self, SPECS)

    # ------------------------------------------------------------------ derived
    @property
    def cross_section_area(self) -> float:
        return self.area if self.area > 0.0 else self.section_height ** 2

    @property
    def cross_section_inertia(self) -> float:
        if self.second_moment_of_area > 0.0:
            return self.second_moment_of_area
        return self.section_height ** 4 / 12.0

    @property
    def fibre_distance(self) -> float:
        """Distance from the neutral axis to the outer fibre (b/2, Eq. 5.44)."""
        if self.section_height > 0.0:
            return 0.5 * self.section_height
        # rectangle of the same A and I: I = A h^2 / 12
        return math.sqrt(3.0 * self.cross_section_inertia / self.cross_section_area)

    @property
    def mass_per_length(self) -> float:
        return self.density * self.cross_section_area

    @property
    def sleeve_force_limit(self) -> float:
        """
        Return the largest sleeve force F_H a command may ask for (N).

        Largest sleeve force F_H a command may ask for (N): the axial load the link O''-H
        can carry, min(Euler buckling load of a pinned-pinned column pi^2 E I / l3^2, squash
        load A sigma_y).  In stage 1 the link's compression is F_H / sin(alpha2) >= F_H, so a
        larger F_H buckles or crushes the link in every configuration, which this
        (geometrically linear, elastic) model cannot represent.
        """
        return min(self.link_euler_load, self.sleeve_force_tension_limit)   # (squash load)

    @property
    def link_euler_load(self) -> float:
        """Return the link O''-H's Euler load, a pinned-pinned column: pi^2 E I / l3^2 (N)."""
        return math.pi ** 2 * self.youngs_modulus * self.cross_section_inertia / self.l3 ** 2

    @property
    def sleeve_force_tension_limit(self) -> float:
        """Return the largest force holding the sleeve back (N): the link's squash load."""
        return self.cross_section_area * self.yield_strength

    @property
    def sleeve_stop_height(self) -> float:
        """Height of the stop S on the axle: the rigid geometry at alpha_deployed."""
        return _sleeve_height(self.l1, self.l3, self.alpha_deployed)

    @property
    def sleeve_start_height(self) -> float:
        return _sleeve_height(self.l1, self.l3, self.alpha0)

    @property
    def lock_rule(self) -> str:
        """Return the lock the run takes: energy or plastic (``lock`` auto resolved)."""
        if self.model in ('rigid', 'rigid-fe'):
            return 'plastic'
        return 'energy' if self.lock == 'auto' else self.lock

    def with_physics_step(self, step: float, follows_lock: bool = False) -> 'UmbrellaParams':
        """
        Return these parameters with the integrator's step set to step exactly.

        follows_lock: the step was chosen for the run (step_rule.follows_lock of the
        parameters it came from), so stage 2 still takes the step its lock needs: kept as
        step_follows_mesh, whose rule leaves a step the mesh's stresses already resolve as
        it is.
        """
        return self.replace(time_step=step, step_follows_mesh=follows_lock)

    # ---------------------------------------------------------------- building
    def replace(self, **changes: Any) -> 'UmbrellaParams':
        unknown = sorted(set(changes) - set(SPECS))
        if unknown:
            raise ValueError(_unknown_message(unknown))
        return dataclasses.replace(self, **{k: coerce(k, v) for k, v in changes.items()})

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], base: 'UmbrellaParams | None' = None,
                     ignore_unknown: bool = False) -> 'UmbrellaParams':
        base = base or cls()
        unknown = sorted(set(values) - set(SPECS))
        if unknown and not ignore_unknown:
            raise ValueError(_unknown_message(unknown))
        return base.replace(**{k: v for k, v in values.items() if k in SPECS})

    def validated(self, pairs: bool = True) -> 'UmbrellaParams':
        """Return self if valid, else raise ValueError (validate; pairs: its pair rule)."""
        validate(self, pairs)
        return self


def _unknown_message(unknown: list[str]) -> str:
    try:
        check_known_names(unknown, SPECS, 'parameters')
    except ValueError as exc:
        return str(exc)
    return ''


#: the physics' parameters as one frozen record; fields and defaults from SPECS
UmbrellaParams = dataclasses.make_dataclass(
    'UmbrellaParams', [(p.name, p.type, dataclasses.field(default=p.default))
                       for p in SPECS.values()],
    bases=(_DerivedQuantities,), frozen=True)
UmbrellaParams.__module__ = __name__     # pickles as umbrella_sim.core.params.UmbrellaParams
UmbrellaParams.__doc__ = ("The physics' parameters (SI), one field per entry of SPECS; "
                          'immutable: change with replace(), check with validated().')


def _sleeve_height(l1: float, l3: float, alpha: float) -> float:
    """Return y_H of the rigid mechanism at leaf angle alpha (H on the axle above O'')."""
    return l1 * math.sin(alpha) + math.sqrt(max(l3 ** 2 - (l1 * math.cos(alpha)) ** 2, 0.0))


def _check_each(p: UmbrellaParams, names) -> None:
    """Raise ValueError for the first of names whose value has the wrong type or range."""
    _check_fields(p, {name: SPECS[name] for name in names})


def check_values(values: Mapping[str, Any]) -> None:
    """
    Check each value on its own: its type and range, not the rules tying several together.

    For values from one typed source (a params file), so that the error can name the
    source before they are merged with others.
    """
    check_types(values)
    _check_each(UmbrellaParams.from_mapping(values), values)


def validate(p: UmbrellaParams, pairs: bool = True) -> None:
    """
    Raise ValueError naming the parameter and the rule it breaks.

    pairs=False leaves out the rule of parameters given together (area and
    second_moment_of_area): the live node takes parameter sets one parameter at a time and
    checks the pair when they apply, at ~/reset.
    """
    _check_each(p, SPECS)
    # the rules that tie parameters together (each registry entry's `rule` names its own)
    if pairs and (p.area > 0.0) != (p.second_moment_of_area > 0.0):
        raise ValueError('parameters area and second_moment_of_area: give both or neither')
    if (p.area == 0.0 or p.second_moment_of_area == 0.0) and p.section_height <= 0.0:
        raise ValueError(f'parameter section_height={p.section_height}: must be > 0 '
                         'unless area and second_moment_of_area are given')
    if p.area > 0.0 and p.second_moment_of_area > 0.0 and p.section_height > 0.0:
        most = p.area * (0.5 * p.section_height) ** 2   # every fibre at the outer ones
        if p.second_moment_of_area > most * (1.0 + 1e-12):
            raise ValueError(
                f'parameter second_moment_of_area={p.second_moment_of_area}: more than '
                f'area * (section_height / 2)^2 = {most:.6g} m^4, which no section of '
                f'height section_height={p.section_height} m has (its outer fibre, where '
                "the stress is recovered, is at section_height / 2): give the section's "
                'height, or section_height 0 for the rectangle of that area and I')
    if p.yield_strength < MIN_YIELD_STRAIN * p.youngs_modulus:
        raise ValueError(
            f'parameter yield_strength={p.yield_strength:g}: a yield strain of '
            f'{p.yield_strength / p.youngs_modulus:.3g} of youngs_modulus='
            f'{p.youngs_modulus:g} Pa, below {MIN_YIELD_STRAIN:g}, which no structural '
            'material has (the softest metals yield at ~1e-4): both are in Pa, not MPa '
            f'({p.yield_strength:g} MPa = {p.yield_strength * 1e6:g} Pa)')
    if not p.alpha_deployed < p.alpha0:
        raise ValueError(f'parameter alpha0={p.alpha0}: must be above alpha_deployed='
                         f'{p.alpha_deployed} and below pi/2')
    for name in ('alpha0', 'alpha_deployed'):
        reach = p.l1 * abs(math.cos(getattr(p, name)))
        if reach >= p.l3:     # (the link named first, the leaf with it: either was set)
            raise ValueError(f'parameter l3={p.l3} with l1={p.l1}: the link is too short for '
                             f'the leaf, geometry cannot close: l1*|cos({name})| = '
                             f'{reach:.6g} m must be < l3 ({name}={getattr(p, name):.6g}); '
                             'lengthen l3 or shorten l1')
    if 0.0 < p.time_step < MIN_PHYSICS_STEP:
        raise ValueError(f'parameter time_step={p.time_step}: must be 0 (the step chosen for '
                         f'the mesh) or >= {MIN_PHYSICS_STEP:g} s')
    if p.sleeve_force_min < -p.sleeve_force_tension_limit:
        raise ValueError(f'parameter sleeve_force_min={p.sleeve_force_min}: must be >= '
                         f'{-p.sleeve_force_tension_limit:.6g} N: a force holding the sleeve '
                         'back puts the link in tension, which it carries up to its squash '
                         'load area * yield_strength')
    if p.sleeve_force < p.sleeve_force_min:
        raise ValueError(f'parameter sleeve_force={p.sleeve_force}: must be >= '
                         f'{p.sleeve_force_min:g} = sleeve_force_min (F_H pushes the sleeve '
                         'along -Y)')
    if p.sleeve_force > p.sleeve_force_limit:
        raise ValueError(f'parameter sleeve_force={p.sleeve_force}: must be <= '
                         f'{p.sleeve_force_limit:.6g} N, the load the link can carry '
                         '(Euler buckling / squash load, msg_docs/topic_sleeve_force.md)')


def physics_step(time_step: float, publish_rate: float) -> float:
    """Return the largest step <= time_step that divides the publication period."""
    period = 1.0 / publish_rate
    return period / math.ceil(period / time_step - 1e-9)


def shortened_step_note(time_step: float, publish_rate: float) -> str | None:
    """
    Say how the publications shorten the step, if they do (None if time_step divides them).

    A recording (live, or offline with --mcap) then steps at physics_step(), so its states
    differ from a run at time_step by that step's error.
    """
    step = physics_step(time_step, publish_rate)
    if abs(step - time_step) <= 1e-12 * time_step:
        return None
    return (f'physics step {step:.9g} s, not {time_step:g} s: the largest step <= it that '
            f'divides the {1e3 / publish_rate:g} ms publication period (publish_rate '
            f'{publish_rate:g} Hz), so the states differ from a run at {time_step:g} s by the '
            "step's error; a time_step dividing the period keeps them the same")


def _check_fields(record, specs: Mapping[str, Param]) -> None:
    """Raise ValueError for the first field of record whose type or range is wrong."""
    for name, spec in specs.items():
        value = getattr(record, name)
        if not isinstance(value, spec.type) or (spec.type is not bool
                                                and isinstance(value, bool)):
            raise ValueError(f'parameter {name}={value!r}: must be of type {spec.type_name}')
        spec.check(value)


class _ControllerChecks:
    """Methods of ControllerConfig; its fields come from the registry (CONTROLLER_PARAMETERS)."""

    def __post_init__(self):
        _exact_fields(self, CONTROLLER_PARAMETERS)

    def validated(self) -> 'ControllerConfig':
        """Return self if every value is in its range, else raise ValueError naming it."""
        _check_fields(self, CONTROLLER_PARAMETERS)
        return self


#: deploy_controller's parameters as one frozen record; fields and defaults from the registry
ControllerConfig = dataclasses.make_dataclass(
    'ControllerConfig', [(p.name, p.type, dataclasses.field(default=p.default))
                         for p in CONTROLLER_PARAMETERS.values()],
    bases=(_ControllerChecks,), frozen=True)
ControllerConfig.__module__ = __name__
ControllerConfig.__doc__ = "deploy_controller's parameters (SI); check with validated()."
