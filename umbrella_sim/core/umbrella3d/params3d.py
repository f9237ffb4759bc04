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
The whole umbrella's parameters: N ribs around one sleeve, each rib's own values, the base.

``UmbrellaRibsParams`` holds the planar model's record (``UmbrellaParams``: geometry, section,
material, alpha0, v0, sleeve force, mesh, lock, step) as the value every rib takes unless told
otherwise, and what the whole umbrella adds: the number of ribs, the hub radius, the sleeve's
mass, and the base (hub fixed, a prescribed motion, or a free-floating bus).  A rib's own
value is given either as a list with one entry per rib (``{"tip_mass": [0, 0.1, 0]}``) or as
an override ``{"rib2.hinge_coulomb": 0.5}`` (ribs are numbered from 0, rib 0 at azimuth 0 on
+X); a name of the planar record (l1, youngs_modulus...) may be overridden per rib as well.
Every value is SI (m, kg, s, N, Pa, rad).  The specifications use the registry's ``Param``,
so the later integration can list them with the node's parameters.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import re
from typing import Any, Mapping

from ..params import UmbrellaParams
from ..registry import (check_types, closest_name, Param, parameter_help, REGISTRY,
                        START)

BASE_MODES = ('fixed', 'prescribed', 'free')

_P = Param
#: the whole umbrella's own parameters (one value each)
UMBRELLA_SPECS: dict[str, Param] = {p.name: p for p in (
    _P('ribs', int, 1, '-', 'number of ribs N at azimuths 2πk/N about the hub axis Y '
       '(1 = the planar model)', low=1, high=64),
    _P('hub_radius', float, 0.0, 'm', 'radius a of the hub circle on which the leaf hinges '
       "O_k and the link's sleeve hinges sit", low=0.0, high=10.0),
    _P('sleeve_mass', float, 0.0, 'kg', 'mass of the sleeve H sliding on Y (thesis: 0)',
       low=0.0, high=1e6),
    _P('poisson_ratio', float, 0.33, '-', "Poisson's ratio ν (shear modulus E / 2(1 + ν))",
       low=0.0, high=0.5, high_open=True),
    _P('hinge_regularisation', float, 1e-3, 'rad/s',
       "rate below which a hinge's Coulomb torque is smoothed (τ_c tanh(ω / this))",
       low=0.0, low_open=True, high=10.0),
    _P('base', str, 'fixed', '-', 'fixed hub; prescribed bus motion (base_accel, '
       'base_spin_rate); free-floating bus (bus_mass, bus_inertia); a base value set off its '
       'default with a base it does not act on is refused', choices=BASE_MODES),
    _P('bus_mass', float, 100.0, 'kg', 'bus mass: a free-floating bus, or a prescribed one '
       '(its drive moves it)', low=0.0, low_open=True, high=1e9),
    _P('bus_inertia', float, 10.0, 'kg m²', 'bus principal moment of inertia (the same about '
       'its three axes unless bus_inertia_y is given): a free-floating bus, or a prescribed '
       "one (its drive spins it: the drive's work)", low=0.0, low_open=True, high=1e12),
    _P('bus_inertia_y', float, 0.0, 'kg m²', 'bus moment about the hub axis Y: a free-floating '
       'bus, or a prescribed one; 0 = bus_inertia', low=0.0, high=1e12),
    _P('base_accel_x', float, 0.0, 'm/s²', 'prescribed base: peak of a half-sine acceleration '
       'pulse along X', low=-1e6, high=1e6),
    _P('base_accel_z', float, 0.0, 'm/s²', 'prescribed base: the same along Z', low=-1e6,
       high=1e6),
    _P('base_accel_start', float, 0.0, 's', 'prescribed base: start of the pulse', low=0.0,
       high=1e6),
    _P('base_accel_duration', float, 0.02, 's', 'prescribed base: length of the pulse',
       low=0.0, low_open=True, high=1e6),
    _P('base_spin_rate', float, 0.0, 'rad/s', 'prescribed base: angular rate about Y reached '
       'after base_spin_ramp (linear ramp from 0)', low=-1e3, high=1e3),
    _P('base_spin_ramp', float, 0.05, 's', 'prescribed base: ramp time of the spin rate',
       low=0.0, low_open=True, high=1e6),
)}

#: the bases each base parameter acts on: set off its default with another base, it would
#: change nothing (a spin-up forgotten without base prescribed), and is refused
BASE_PARAMETERS = {
    **{name: ('prescribed',) for name in ('base_accel_x', 'base_accel_z', 'base_accel_start',
                                          'base_accel_duration', 'base_spin_rate',
                                          'base_spin_ramp')},
    **{name: ('free', 'prescribed') for name in ('bus_mass', 'bus_inertia', 'bus_inertia_y')}}

#: a rib's own values (a list, or rib<k>.<name>), besides the names of the planar record
RIB_SPECS: dict[str, Param] = {p.name: p for p in (
    _P('tip_mass', float, 0.0, 'kg', 'point mass at the leaf tip G', low=0.0, high=1e6),
    _P('tip_offset_x', float, 0.0, 'm', 'tip mass offset from G along the leaf (leaf frame)',
       low=-10.0, high=10.0),
    _P('tip_offset_y', float, 0.0, 'm', 'tip mass offset, in-plane transverse', low=-10.0,
       high=10.0),
    _P('tip_offset_z', float, 0.0, 'm', 'tip mass offset, out of the rib plane (tangential)',
       low=-10.0, high=10.0),
    _P('hinge_coulomb', float, 0.0, 'N m', 'Coulomb friction torque at the leaf hinge O_k',
       low=0.0, high=1e6),
    _P('hinge_viscous', float, 0.0, 'N m s', 'viscous friction coefficient at O_k', low=0.0,
       high=1e6),
    _P('stick_until', float, 0.0, 's', 'the leaf hinge is stuck from t = 0 until this time '
       '(0 = never released by time: free, unless stick_torque > 0)', low=0.0, high=1e6),
    _P('stick_torque', float, 0.0, 'N m', 'the leaf hinge is stuck from t = 0 until its '
       'holding torque exceeds this or stick_until comes, whichever first (0 = only '
       'stick_until releases it)', low=0.0, high=1e9),
    _P('alpha0_offset', float, 0.0, 'rad', 'initial leaf angle perturbation (taken up '
       'elastically: the ribs share the sleeve); the rib starts at its start angle plus it, '
       'above its deployed angle and at most pi/2 - 0.001', low=-0.5, high=0.5),
    _P('rate_offset', float, 0.0, 'rad/s', 'initial leaf rate perturbation', low=-1e3,
       high=1e3),
    _P('out_of_plane_rate', float, 0.0, 'm/s', 'initial out-of-plane velocity of the leaf '
       'tip (a lateral kick; projected onto the joints)', low=-1e3, high=1e3),
    _P('torsion_constant', float, 0.0, 'm⁴', 'St-Venant torsion constant J; 0 = 0.8436 I_p '
       '(I_p = 2 I; the square section b x b: 0.1406 b⁴); with your own J give '
       'torsion_fibre_distance too', low=0.0, high=100.0),
    _P('torsion_fibre_distance', float, 0.0, 'm', 'c_t of the torsional shear stress tau = T '
       'c_t / J (a round bar: its radius; a thin tube: its outer radius); 0 = the square '
       "section's, 0.676 b (b = twice the bending fibre distance)", low=0.0, high=10.0),
)}

#: names of the planar record a rib may take its own value of
RIB_PLANAR_NAMES = ('l1', 'l2', 'l3', 'section_height', 'area', 'second_moment_of_area',
                    'youngs_modulus', 'density')
_OVERRIDE = re.compile(r'^rib(\d+)\.(\w+)$')
#: a node's name of a rib's own values, a list with one entry per rib: rib.<name>
RIB_LIST_PREFIX = 'rib.'


def rib_list_specs() -> dict[str, Param]:
    """Return {name: spec} of every value a rib may have its own of (RIB_SPECS, planar)."""
    from ..registry import REGISTRY

    return {**RIB_SPECS, **{name: REGISTRY[name] for name in RIB_PLANAR_NAMES}}


def umbrella_parameter_names() -> frozenset:
    """
    Return the names of the umbrella's parameters on a node.

    Its own (UMBRELLA_SPECS), rib.<name> lists (one value per rib) and rib<k>.<name>
    overrides of one rib (k < the largest number of ribs).
    """
    names = rib_list_specs()
    return (frozenset(UMBRELLA_SPECS) | {RIB_LIST_PREFIX + n for n in names}
            | {f'rib{k}.{n}' for k in range(UMBRELLA_SPECS['ribs'].high) for n in names})


def umbrella_parameter_help() -> list[str]:
    """Return the --help lines of the umbrella's parameters (umbrella_node's and simulate's)."""
    return (['the umbrella of N ribs (read-only on a node, ribs >= 2; '
             'umbrella3d_parameters.md):']
            + parameter_help(dataclasses.replace(p, applies=START)
                             for p in UMBRELLA_SPECS.values())
            + ['  rib.<name>             double[], one value per rib (rib 0 first), for '
               f"{', '.join(rib_list_specs())}; rib<k>.<name>: rib k's alone"])


def names_a_rib(name: str) -> bool:
    """Tell whether a parameter name is the umbrella's per-rib form (rib.<name>, rib<k>.<name>)."""
    return name.startswith(RIB_LIST_PREFIX) or _OVERRIDE.match(name) is not None


def rib_override_index(name: str) -> int | None:
    """Return k of a rib<k>.<name> override (None: not one)."""
    match = _OVERRIDE.match(name)
    return None if match is None else int(match.group(1))


def rib_override_spec(name: str) -> Param | None:
    """Return the spec of a rib<k>.<name> override (None: not one; ValueError: no such name)."""
    match = _OVERRIDE.match(name)
    if match is None:
        return None
    _rib_spec(match.group(2), name)
    return rib_list_specs()[match.group(2)]


def refuse_empty_rib_lists(values: Mapping[str, Any], where: str = '') -> None:
    """
    Refuse a rib.<name> given as null or [] (where: what gave it, prefixed to the error).

    Where a value is given (a params file, a sweep spec, a node's override), a rib list
    holds one value per rib: leaving it out, not an empty one, leaves every rib its value.
    """
    for name, value in values.items():
        if name.startswith(RIB_LIST_PREFIX) and (
                value is None or isinstance(value, (list, tuple)) and not len(value)):
            raise ValueError(f'{where}parameter {name}: '
                             f"{'null' if value is None else 'an empty list'}: give one "
                             f'value per rib (rib 0 first), or leave {name} out (every rib '
                             f'then takes {name[len(RIB_LIST_PREFIX):]})')


def checked_umbrella_value(name: str, value):
    """
    Return one umbrella value typed and checked on its own (None: a rib list not given).

    umbrella_values' rules but the one that needs the others (ribs 1 takes no umbrella
    value): for a value that another source joins (a params file's, a launch argument's).
    ValueError naming it.
    """
    if name == 'ribs':
        return umbrella_values({name: value})[name]
    return umbrella_values({'ribs': 2, name: value}).get(name)


def check_umbrella_types(values: Mapping[str, Any], params_file: bool = True) -> None:
    """
    Refuse a typed umbrella value (YAML: a params file, a sweep SPEC) the node would refuse.

    registry.check_types' rule for the umbrella's own values and a rib's rib<k>.<name>, a
    double ("5" in quotes is a string), and the node's for a rib.<name> list, a double[] of
    numbers; in a params file (params_file) every one an integer or every one a double, as
    rcl reads the file ([0, 0.1] refused).  Names not the umbrella's are left to the
    registry's check.
    """
    for name, value in values.items():
        override = _OVERRIDE.match(name)
        if name.startswith(RIB_LIST_PREFIX) and isinstance(value, (list, tuple)):
            kinds = {type(v) for v in value}
            if not kinds <= {int, float}:
                bad = next(v for v in value if type(v) not in (int, float))
                kind = {str: 'string', bool: 'bool'}.get(type(bad), type(bad).__name__)
                raise ValueError(f'parameter {name}={list(value)!r}: must be of type '
                                 f'double[], got the {kind} {bad!r} in it')
            if params_file and len(kinds) > 1:
                raise ValueError(f'parameter {name}={list(value)!r}: a list of doubles needs '
                                 'every value written as a double, [0.0, 0.1] not [0, 0.1] '
                                 '(the node refuses it)')
        elif name in UMBRELLA_SPECS:
            check_types({name: value}, UMBRELLA_SPECS[name])
        elif override and override.group(2) in rib_list_specs():
            check_types({name: value}, rib_list_specs()[override.group(2)])


def umbrella_values(values: Mapping[str, Any]) -> dict:
    """
    Return a node's umbrella parameters typed (rib lists not given dropped), by their names.

    values: the umbrella's own parameters (UMBRELLA_SPECS names) and rib.<name> lists
    (None or [] where not given); the result is what ``UmbrellaRibsParams.of_node`` takes.
    With ribs 1 (the planar model, exactly) no umbrella value may differ from its default
    and no rib list be given: ValueError naming it.
    """
    out = {}
    for name, value in values.items():
        if name.startswith(RIB_LIST_PREFIX):
            key = name[len(RIB_LIST_PREFIX):]
            if value is not None and not isinstance(value, (list, tuple)):
                raise ValueError(f'parameter {name}={value!r}: a list of one value per rib '
                                 f'(rib 0 first: [0.0, 0.1, 0.0]); rib<k>.{key} sets rib '
                                 "k's alone")
            _rib_spec(key, name)
            if value is not None and len(value):
                spec = dataclasses.replace(rib_list_specs()[key], name=name)
                out[name] = [float(spec.coerce(v)) for v in value]
        elif name in UMBRELLA_SPECS:
            out[name] = UMBRELLA_SPECS[name].coerce(value)
            UMBRELLA_SPECS[name].check(out[name])      # (ribs 0 is no planar model)
        else:                                   # rib<k>.<name>: one rib's value
            spec = dataclasses.replace(rib_override_spec(name), name=name)
            if isinstance(value, (list, tuple)):
                k, key = _OVERRIDE.match(name).groups()
                raise ValueError(f"parameter {name}={value!r}: one value, rib {k}'s own "
                                 f'(rib.{key} takes a list of every rib)')
            out[name] = spec.coerce(value)
    if out.get('ribs', 1) == 1:
        given = sorted(n for n, v in out.items()
                       if n != 'ribs' and (n not in UMBRELLA_SPECS
                                           or v != UMBRELLA_SPECS[n].default))
        if given:
            raise ValueError(f'parameter {given[0]}: set with ribs 1 (the planar model, which '
                             'has no hub, bus or per-rib values); set ribs >= 2')
    return out


@dataclasses.dataclass(frozen=True)
class RibProperties:
    """One rib's values, resolved: its planar record and its own (RIB_SPECS)."""

    index: int
    azimuth: float
    planar: UmbrellaParams
    own: Mapping[str, float]

    def __getattr__(self, name: str):
        own = self.__dict__.get('own', {})
        if name in own:
            return own[name]
        raise AttributeError(name)

    @property
    def shear_modulus_factor(self) -> float:
        """Return 1 / (2 (1 + nu)), filled in by UmbrellaRibsParams.rib."""
        return self.own['_shear_factor']

    @property
    def torsion_j(self) -> float:
        """Return the St-Venant torsion constant J (m^4)."""
        j = self.own['torsion_constant']
        if j > 0.0:
            return j
        return 0.8436 * 2.0 * self.planar.cross_section_inertia

    @property
    def torsion_fibre(self) -> float:
        """
        Return c_t with tau_max = G phi' c_t = T c_t / J (m): torsion_fibre_distance if given.

        Else the square section's: tau_max = T / (0.208 b^3) and T = G J phi' with
        J = 0.1406 b^4, so c_t = 0.676 b; b is twice the bending fibre distance.
        """
        c_t = self.own['torsion_fibre_distance']
        if c_t > 0.0:
            return c_t
        return 0.1406 / 0.208 * 2.0 * self.planar.fibre_distance


@dataclasses.dataclass(frozen=True)
class UmbrellaRibsParams:
    """The whole umbrella's parameters; see the module docstring."""

    planar: UmbrellaParams = dataclasses.field(default_factory=UmbrellaParams)
    values: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    per_rib: Mapping[int, Mapping[str, Any]] = dataclasses.field(default_factory=dict)

    def __getattr__(self, name: str):
        spec = UMBRELLA_SPECS.get(name)
        if spec is None:
            raise AttributeError(name)
        return self.__dict__['values'].get(name, spec.default)

    # ------------------------------------------------------------- building
    @classmethod
    def from_mapping(cls, values: Mapping[str, Any],
                     planar: UmbrellaParams | None = None) -> 'UmbrellaRibsParams':
        """
        Build from {name: value}: planar names, umbrella names, rib lists and overrides.

        A planar name with a list value, or rib<k>.<planar name>, is a per-rib value; a planar
        name with one value sets it for every rib.  rib.<name> (the node's and the command
        lines' spelling) is <name>'s list.  Raises ValueError naming the culprit as given.
        """
        planar = planar or UmbrellaParams()
        base_planar, own, lists, overrides, spelled = {}, {}, {}, {}, {}

        def every_rib(key: str, value, given: str) -> None:
            # a value or a list of every rib (given: as the user spelled it, for the errors)
            _rib_spec(key, given)
            if key in lists:
                raise ValueError(f'parameter {given}: given twice (as {spelled[key]} too)')
            lists[key] = list(value) if isinstance(value, (list, tuple)) else value
            spelled[key] = given

        for name, value in values.items():
            match = _OVERRIDE.match(name)
            if name.startswith(RIB_LIST_PREFIX):
                every_rib(name[len(RIB_LIST_PREFIX):], value, name)
            elif match:
                k, key = int(match.group(1)), match.group(2)
                _rib_spec(key, name)
                overrides.setdefault(k, {})[key] = value
            elif name in UMBRELLA_SPECS:
                own[name] = UMBRELLA_SPECS[name].coerce(value)
            elif isinstance(value, (list, tuple)) or name in RIB_SPECS:
                every_rib(name, value, name)
            else:
                base_planar[name] = value
        planar = planar.replace(**base_planar) if base_planar else planar
        n = own.get('ribs', UMBRELLA_SPECS['ribs'].default)
        per_rib: dict[int, dict] = {k: {} for k in range(n)}
        for name, value in lists.items():
            if isinstance(value, list):
                if len(value) != n:
                    raise ValueError(f'parameter {spelled[name]}: a list of '
                                     f'{len(value)} values for '
                                     f'{n} ribs (give one per rib)')
                for k, v in enumerate(value):
                    per_rib[k][name] = v
            else:
                for k in range(n):
                    per_rib[k][name] = value
        for k, vals in overrides.items():
            if not 0 <= k < n:
                raise ValueError(f'parameter rib{k}.{next(iter(vals))}: there are ribs '
                                 f'0 .. {n - 1}')
            per_rib[k].update(vals)
        out = cls(planar, own, {k: v for k, v in per_rib.items() if v})
        return out.validated()

    @classmethod
    def of_node(cls, umbrella: Mapping[str, Any], planar: UmbrellaParams
                ) -> 'UmbrellaRibsParams':
        """Build from a node's umbrella parameters (umbrella_values: rib.<name> lists...)."""
        return cls.from_mapping(umbrella, planar)

    def validated(self) -> 'UmbrellaRibsParams':
        """Return self if every value is in range, else raise ValueError naming it."""
        self.planar.validated()
        for name, value in self.values.items():
            UMBRELLA_SPECS[name].check(value)
        if self.planar.model not in ('flexible', 'flexible-nonlinear'):
            raise ValueError(f'parameter model={self.planar.model!r}: the umbrella model is '
                             'flexible (3D Euler-Bernoulli beams) or flexible-nonlinear '
                             '(co-rotational beams) only')
        for name, bases in BASE_PARAMETERS.items():
            value = self.values.get(name, UMBRELLA_SPECS[name].default)
            if self.base not in bases and value != UMBRELLA_SPECS[name].default:
                raise ValueError(
                    f"parameter {name}={value:g}: acts on base {' or '.join(bases)} only, and "
                    f'base is {self.base!r}: it would move nothing; set base '
                    f'{bases[0]} or leave {name} at {UMBRELLA_SPECS[name].default:g}')
        if self.base == 'free' and self.planar.lock == 'energy':
            raise ValueError("parameter lock='energy' with base 'free': the energy lock keeps "
                             "each rib's kinetic energy and would change the momentum of a "
                             "free-floating bus; use lock 'plastic'")
        for k in range(self.ribs):
            rib = self.rib(k)
            self._check_reach(rib)
            self._check_start_angle(rib)
        return self

    def _check_start_angle(self, rib: 'RibProperties') -> None:
        """Raise ValueError naming rib<k>.alpha0_offset if it starts the leaf out of range."""
        offset = rib.alpha0_offset
        if offset == 0.0:
            return
        start = rib_start_angle(rib.planar, self.planar)
        deployed = rib_deployed_angle(rib.planar, self.planar)
        highest = REGISTRY['alpha0'].high       # (the toggle: no lever on the leaf)
        angle = start + offset
        if not deployed < angle <= highest:
            side = (f'past pi/2 - 0.001 = {highest:.7g} rad, where the sleeve has no lever '
                    f'on the leaf' if angle > highest else
                    f'at or below its deployed angle {deployed:.7g} rad')
            raise ValueError(
                f'parameter rib{rib.index}.alpha0_offset={offset:g}: rib {rib.index} would '
                f'start at leaf angle {angle:.7g} rad ({start:.7g} + the offset), {side}; '
                f'its offset must lie in ({deployed - start:.4g}, {highest - start:.4g}] rad')

    def _check_reach(self, rib: 'RibProperties') -> None:
        """Raise ValueError naming the rib if its lengths cannot put the sleeve where it runs."""
        l1, l3 = rib.planar.l1, rib.planar.l3
        _, lowest, highest = rib_reach(l1, l3)
        for what, y in (('start', self.planar.sleeve_start_height),
                        ('stop', self.planar.sleeve_stop_height)):
            if not lowest - 1e-12 <= y <= highest + 1e-12:
                raise ValueError(
                    f'rib {rib.index}: its leaf l1={l1:g} m and link l3={l3:g} m cannot reach '
                    f"the sleeve's {what} height {y:.6g} m (a rigid rib of these lengths puts "
                    f'the sleeve between {lowest:.6g} and {highest:.6g} m)')

    def rib(self, k: int) -> RibProperties:
        """Return rib k's values (its planar record validated, its own values checked)."""
        vals = dict(self.per_rib.get(k, {}))
        planar_changes = {n: vals.pop(n) for n in list(vals) if n in RIB_PLANAR_NAMES}
        try:
            planar = self.planar.replace(**planar_changes).validated()
        except ValueError as exc:
            text = str(exc)
            own = next((n for n in planar_changes if text.startswith(f'parameter {n}=')), None)
            if own is not None:     # (the rib's own value: named as a rib's, rib<k>.<name>)
                raise ValueError(f'parameter rib{k}.{text[len("parameter "):]}') from None
            raise ValueError(f'rib {k}: {text}') from None
        own = {name: spec.default for name, spec in RIB_SPECS.items()}
        for name, value in vals.items():
            spec = RIB_SPECS[name]
            try:
                own[name] = spec.coerce(value)
            except ValueError as exc:   # (named as the rib's, as its range and planar values)
                raise ValueError(f'parameter rib{k}.{str(exc)[len("parameter "):]}') from None
            spec.check(own[name], f'parameter rib{k}.{name}')
        own['_shear_factor'] = 1.0 / (2.0 * (1.0 + self.poisson_ratio))
        return RibProperties(k, 2.0 * math.pi * k / self.ribs, planar, own)

    @property
    def lock_rule(self) -> str:
        """Return the lock the run takes: the planar rule; plastic for auto on a free bus."""
        if self.base == 'free' and self.planar.lock == 'auto':
            return 'plastic'
        return self.planar.lock_rule

    def as_dict(self) -> dict:
        """
        Return every value by name, JSON-ready.

        The planar record's, the umbrella's own, and each rib's own as a list of N (a name
        no rib has its own value of is left out).
        """
        out = {**self.planar.as_dict(), **{n: getattr(self, n) for n in UMBRELLA_SPECS}}
        for name in sorted({n for vals in self.per_rib.values() for n in vals}):
            out[name] = [getattr(rib, name) if name in RIB_SPECS else getattr(rib.planar, name)
                         for rib in self.ribs_list()]
        return out

    @property
    def sleeve_force(self) -> float:
        """Return F per rib at t = 0 (the planar record's; the sleeve takes N F)."""
        return self.planar.sleeve_force

    @functools.cached_property
    def _link_limits(self) -> tuple[float, ...]:
        """Return each rib's link's load limit (its planar record's sleeve_force_limit)."""
        return tuple(rib.planar.sleeve_force_limit for rib in self.ribs_list())

    @property
    def sleeve_force_limit(self) -> float:
        """
        Return the largest F per rib: the least a rib's link carries (each carries ~F).

        A rib of its own section or length has its own limit (its planar record's, which
        refuses a larger ``sleeve_force`` at start): a command is held to the same bound.
        """
        return min(self._link_limits)

    @property
    def weakest_link(self) -> str:
        """Say whose link sets sleeve_force_limit: 'rib k's link' where the ribs' differ."""
        limits = self._link_limits
        if min(limits) == max(limits):
            return 'the link'
        return f"rib {limits.index(min(limits))}'s link"

    @property
    def sleeve_force_min(self) -> float:
        """Return the smallest F per rib (the planar record's)."""
        return self.planar.sleeve_force_min

    def with_physics_step(self, step: float, follows_lock: bool = False
                          ) -> 'UmbrellaRibsParams':
        """Return these parameters with the integrator's step set to step exactly."""
        return dataclasses.replace(self, planar=self.planar.with_physics_step(step, follows_lock))

    def ribs_list(self) -> list[RibProperties]:
        return [self.rib(k) for k in range(self.ribs)]

    def replace(self, **changes: Any) -> 'UmbrellaRibsParams':
        """Return a copy with changes (any name from_mapping takes)."""
        merged = dict(self.values)
        for k, vals in self.per_rib.items():
            for name, value in vals.items():
                merged[f'rib{k}.{name}'] = value
        merged.update(changes)
        return UmbrellaRibsParams.from_mapping(merged, self.planar)


def rib_reach(l1: float, l3: float) -> tuple[float, float, float]:
    """
    Return (lowest leaf angle, lowest, highest sleeve height) of a rigid rib (leaf l1, link l3).

    The sleeve's height y(a) = l1 sin a + sqrt(l3^2 - (l1 cos a)^2) rises with the leaf
    angle a from the lowest angle (acos(l3 / l1) when the link is the shorter, below which it
    cannot reach the axis; else just above 0) to pi / 2, where it is l1 + l3.
    """
    low = max(1e-9, math.acos(min(1.0, l3 / l1)))
    return low, _rigid_height(l1, l3, low), l1 + l3


def _rigid_height(l1: float, l3: float, a: float) -> float:
    return l1 * math.sin(a) + math.sqrt(max(l3 ** 2 - (l1 * math.cos(a)) ** 2, 0.0))


def rib_start_angle(rib: UmbrellaParams, base: UmbrellaParams) -> float:
    """Return the leaf angle at which a rib's rigid geometry puts H at the sleeve's start."""
    if (rib.l1, rib.l3) == (base.l1, base.l3):
        return base.alpha0
    return rigid_rib_angle(rib.l1, rib.l3, base.sleeve_start_height)


def rib_deployed_angle(rib: UmbrellaParams, base: UmbrellaParams) -> float:
    """Return the leaf angle at which a rib's rigid geometry puts H at the common stop."""
    if (rib.l1, rib.l3) == (base.l1, base.l3):
        return base.alpha_deployed
    return rigid_rib_angle(rib.l1, rib.l3, base.sleeve_stop_height)


def rigid_rib_angle(l1: float, l3: float, y: float) -> float:
    """Return the leaf angle at which a rigid rib (leaf l1, link l3) puts the sleeve at y."""
    from scipy.optimize import brentq

    # (within the rib's reach: the parameters' validation checks the sleeve's heights)
    return brentq(lambda a: _rigid_height(l1, l3, a) - y, rib_reach(l1, l3)[0], math.pi / 2,
                  xtol=1e-15)


def _rib_spec(name: str, given: str | None = None) -> None:
    """
    Refuse a per-rib name no rib takes (given: as the user spelled it, for the error).

    The error names it as given and, where one is close (registry.closest_name, the
    parameters' rule), the name meant in the same spelling: 'rib1.tip_mas' is rib1.tip_mass.
    """
    if name not in RIB_SPECS and name not in RIB_PLANAR_NAMES:
        known = sorted(RIB_SPECS) + list(RIB_PLANAR_NAMES)
        given = given or name
        meant = closest_name(name, known)
        hint = (f' (did you mean {given[:len(given) - len(name)] + meant!r}?)'
                if meant and given.endswith(name) else '')
        raise ValueError(f'unknown per-rib parameter {given!r}{hint}; a rib takes '
                         + ', '.join(known))


def node_model(values: Mapping[str, Any]) -> 'UmbrellaParams | UmbrellaRibsParams':
    """
    Return the model a node's parameters make (name -> value, as a params file flattens them).

    The planar record's names and the umbrella's (umbrella_parameter_names, and every name
    of the per-rib forms rib.<name> and rib<k>.<name>: a misspelt one is refused, not left
    out); the others are not the model's and are left out.  ribs >= 2: the umbrella of N
    ribs, else the planar model.  ValueError naming a bad value.
    """
    from ..registry import SPECS

    planar = UmbrellaParams.from_mapping({k: v for k, v in values.items()
                                          if k in SPECS}).validated()
    names = umbrella_parameter_names()
    return umbrella_model(planar, umbrella_values({k: v for k, v in values.items()
                                                   if k in names or names_a_rib(k)}))


def umbrella_model(planar: UmbrellaParams, umbrella: Mapping[str, Any]
                   ) -> 'UmbrellaParams | UmbrellaRibsParams':
    """
    Return the model of a planar record and a node's umbrella values (umbrella_values).

    ribs >= 2: the umbrella of N ribs, each rib taking planar unless it has its own value;
    else planar itself (ribs 1 is the planar model, exactly).  ValueError naming a value.
    """
    if umbrella.get('ribs', 1) > 1:
        return UmbrellaRibsParams.of_node(umbrella, planar)
    return planar
