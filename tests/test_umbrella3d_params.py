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
The whole umbrella's parameters: their page in msg_docs, the per-rib forms, clear errors.

msg_docs/umbrella3d_parameters.md holds one table row per specification of
umbrella_sim.core.umbrella3d.params3d (name, type, unit, default, range, meaning), generated
by ``rows()`` below: ``python tests/test_umbrella3d_params.py`` rewrites the tables.
"""
import math
import os
import re
import sys

import numpy as np
import pytest

from umbrella_sim.core.umbrella3d.model3d import UmbrellaModel3D
from umbrella_sim.core.umbrella3d.params3d import (refuse_empty_rib_lists, RIB_PLANAR_NAMES,
                                                   rib_reach, RIB_SPECS, umbrella_model,
                                                   UMBRELLA_SPECS, umbrella_values,
                                                   UmbrellaRibsParams)

PAGE = os.path.join(os.path.dirname(__file__), '..', 'msg_docs', 'umbrella3d_parameters.md')
_BLOCK = re.compile(r'(<!-- BEGIN GENERATED: (\w+) -->\n).*?(<!-- END GENERATED: \2 -->)', re.S)


def rows(specs) -> str:
    """Return the markdown table of a group of specifications."""
    out = ['| name | type | unit | default | range | meaning |', '|---|---|---|---|---|---|']
    for p in specs.values():
        cell = [f'`{p.name}`', p.type_name, p.unit, p.default_str, p.range_text(), p.doc]
        out.append('| ' + ' | '.join(c.replace('|', '\\|') for c in cell) + ' |')
    return '\n'.join(out) + '\n'


def generated(text: str) -> str:
    tables = {'umbrella': rows(UMBRELLA_SPECS), 'rib': rows(RIB_SPECS)}
    return _BLOCK.sub(lambda m: m.group(1) + tables[m.group(2)] + m.group(3), text)


def test_the_parameter_page_is_current():
    text = open(PAGE, encoding='utf-8').read()
    assert generated(text) == text, 'regenerate: python tests/test_umbrella3d_params.py'
    for name in RIB_PLANAR_NAMES:
        assert f'`{name}`' in text


def test_per_rib_values_as_lists_and_overrides():
    p = UmbrellaRibsParams.from_mapping({'ribs': 3, 'tip_mass': [0.0, 0.1, 0.0],
                                         'rib2.hinge_coulomb': 0.5, 'rib0.l2': 0.6,
                                         'youngs_modulus': 7e10})
    assert [r.tip_mass for r in p.ribs_list()] == [0.0, 0.1, 0.0]
    assert [r.hinge_coulomb for r in p.ribs_list()] == [0.0, 0.0, 0.5]
    assert [r.planar.l2 for r in p.ribs_list()] == [0.6, 0.5, 0.5]
    assert all(r.planar.youngs_modulus == 7e10 for r in p.ribs_list())
    assert p.replace(ribs=3).rib(2).hinge_coulomb == 0.5
    # rib.<name>, the node's and the command lines' spelling, is the same list everywhere
    q = UmbrellaRibsParams.from_mapping({'ribs': 3, 'rib.tip_mass': [0.0, 0.1, 0.0],
                                         'rib2.hinge_coulomb': 0.5, 'rib0.l2': 0.6,
                                         'youngs_modulus': 7e10})
    assert q == p


def test_a_command_is_held_to_what_the_weakest_ribs_link_carries():
    """
    A rib of its own section or length carries its own load: every command F a rib too.

    Its planar record refuses a larger sleeve_force at start; a command (the node's, a
    --force-profile's, the test API's check: command_force) was held only to the planar
    record's bound, 39x that of rib 1's 4 mm section here.
    """
    from umbrella_sim.core.forcing import command_force
    from umbrella_sim.core.params import UmbrellaParams

    weak = UmbrellaParams(section_height=0.004).sleeve_force_limit
    p = UmbrellaRibsParams.from_mapping({'ribs': 3, 'rib.section_height': [0.01, 0.004, 0.01]})
    assert p.sleeve_force_limit == weak < p.planar.sleeve_force_limit
    assert command_force(weak, p) == weak
    with pytest.raises(ValueError, match="the axial load rib 1's link can carry"):
        command_force(1.01 * weak, p)
    with pytest.raises(ValueError, match=r'rib 1: parameter sleeve_force=.*link can carry'):
        p.replace(sleeve_force=1.01 * weak)
    same = UmbrellaRibsParams.from_mapping({'ribs': 3})
    assert same.sleeve_force_limit == UmbrellaParams().sleeve_force_limit   # the planar's
    with pytest.raises(ValueError, match='the axial load the link can carry'):
        command_force(1.01 * same.sleeve_force_limit, same)


@pytest.mark.parametrize('values, culprit', [
    ({'ribs': 3, 'tip_mass': [0.0, 0.1]}, 'tip_mass'),
    ({'ribs': 3, 'rib.tip_mass': [0.0, 0.1]}, 'rib.tip_mass'),     # as the user spelled it
    ({'ribs': 2, 'rib.tip_masss': [0.0, 0.1]}, 'rib.tip_masss'),
    ({'ribs': 2, 'rib.tip_mass': [0.0, 0.1], 'tip_mass': 0.2}, 'tip_mass'),   # twice
    ({'ribs': 2, 'rib5.tip_mass': 0.1}, 'rib5.tip_mass'),
    ({'ribs': 2, 'rib1.stiffness': 1.0}, 'stiffness'),
    ({'ribs': 2, 'rib1.hinge_coulomb': -1.0}, 'rib1.hinge_coulomb'),
    ({'ribs': 3, 'rib1.l2': 0.0}, 'parameter rib1.l2=0.0: must be > 0'),   # a rib's planar
    ({'ribs': 3, 'rib.l2': [0.5, -0.6, 0.5]}, 'parameter rib1.l2=-0.6'),  # value: as a rib's
    ({'ribs': 0}, 'ribs'),
    ({'base': 'free', 'lock': 'energy'}, 'lock'),
    # a base's motion with the hub fixed would move nothing: a spin-up without base prescribed
    ({'ribs': 6, 'base_spin_rate': 20.0}, 'base_spin_rate'),
    ({'ribs': 6, 'base': 'free', 'base_accel_x': 5.0}, 'base_accel_x'),
    ({'ribs': 6, 'bus_mass': 5.0}, 'bus_mass'),
    ({'model': 'rigid'}, 'model'),
    ({'ribs': 3, 'damping_ratio': 1.0, 'model': 'flexible-nonlinear'},
     'damping_ratio'),                             # the co-rotational ribs: [0, 1) too
])
def test_bad_values_name_the_culprit(values, culprit):
    with pytest.raises(ValueError, match=re.escape(culprit)):
        UmbrellaRibsParams.from_mapping(values)


@pytest.mark.parametrize('values, said', [
    ({'ribs': 3, 'rib1.tip_mas': 0.1},
     "unknown per-rib parameter 'rib1.tip_mas' (did you mean 'rib1.tip_mass'?)"),
    ({'ribs': 3, 'rib.tip_mas': [0.0, 0.1, 0.0]},
     "unknown per-rib parameter 'rib.tip_mas' (did you mean 'rib.tip_mass'?)"),
    ({'ribs': 3, 'tip_mas': [0.0, 0.1, 0.0]},
     "unknown per-rib parameter 'tip_mas' (did you mean 'tip_mass'?)"),
    ({'ribs': 3, 'rib2.hinge_colomb': 0.5},
     "unknown per-rib parameter 'rib2.hinge_colomb' (did you mean 'rib2.hinge_coulomb'?)"),
])
def test_a_misspelt_ribs_name_is_named_as_given_with_the_one_meant(values, said):
    """From Python as on the command lines: the name as spelled, and the likely right one."""
    with pytest.raises(ValueError, match=re.escape(said)):
        UmbrellaRibsParams.from_mapping(values)


@pytest.mark.parametrize('values, said', [
    ({'ribs': 3, 'rib1.tip_mass': True}, 'parameter rib1.tip_mass=True: must be a number'),
    ({'ribs': 3, 'rib2.hinge_coulomb': 'abc'}, "parameter rib2.hinge_coulomb='abc'"),
    ({'ribs': 3, 'rib1.tip_offset_z': None}, 'parameter rib1.tip_offset_z=None'),
    ({'ribs': 3, 'tip_mass': [0.0, 'x', 0.0]}, "parameter rib1.tip_mass='x'"),
    ({'ribs': 3, 'rib.stick_until': [0.0, 0.0, False]}, 'parameter rib2.stick_until=False'),
])
def test_a_ribs_own_value_of_a_wrong_type_is_named_as_the_ribs(values, said):
    """As its out-of-range value and a rib's planar value: rib<k>.<name>, not the bare name."""
    with pytest.raises(ValueError, match=re.escape(said)):
        UmbrellaRibsParams.from_mapping(values)


def test_a_moving_bases_own_values_are_taken_on_it():
    """The bus's mass and inertia act on a driven base too (its drive's work moves them)."""
    p = UmbrellaRibsParams.from_mapping({'ribs': 3, 'base': 'prescribed', 'bus_mass': 5.0,
                                         'base_spin_rate': 3.0})
    assert UmbrellaModel3D(p).bus_mass == 5.0


def test_a_prescribed_bus_takes_its_mass_and_inertia_into_the_drives_work():
    """
    A driven bus's own kinetic energy is the drive's work too, which the docs say.

    The drive moves the bus as prescribed whatever its mass and inertia (the ribs' motion is
    the same), so between two buses the drive's work differs by their kinetic energies'
    difference: 1/2 dI_y Omega^2 + 1/2 dm v^2 (v the pulse's end speed 2 A T / pi).
    """
    from umbrella_sim.core import UmbrellaSimulator3D

    drive = {'ribs': 2, 'base': 'prescribed', 'base_accel_x': 20.0, 'base_accel_start': 0.0,
             'base_accel_duration': 0.02, 'base_spin_rate': 3.0, 'base_spin_ramp': 0.02}
    runs = [UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(dict(drive, **bus))).run(0.03)
            .arrays() for bus in ({}, {'bus_mass': 10.0, 'bus_inertia': 1.0,
                                       'bus_inertia_y': 2.0})]
    np.testing.assert_allclose(runs[1]['alpha1'], runs[0]['alpha1'], rtol=0, atol=1e-9)
    speed = 2 * 20.0 * 0.02 / math.pi
    bus_energy = 0.5 * (10.0 - 2.0) * 3.0 ** 2 + 0.5 * (100.0 - 10.0) * speed ** 2
    for name in ('drive_work', 'kinetic_energy'):
        assert runs[0][name][-1] - runs[1][name][-1] == pytest.approx(bus_energy, rel=1e-6)
    text = open(PAGE, encoding='utf-8').read()
    for name in ('bus_inertia', 'bus_inertia_y'):
        assert 'a prescribed one' in UMBRELLA_SPECS[name].doc
    doc = open(os.path.join(os.path.dirname(PAGE), 'topic_ribs.md'), encoding='utf-8').read()
    assert "the bus's own kinetic energy" in ' '.join(doc.split())
    assert 'a prescribed one' in text


def test_a_free_bus_starts_with_the_momentum_zero_as_the_docs_say():
    """
    A free bus takes at t = 0 the rates that cancel the ribs' momentum.

    v0 and a rib's rates are relative to the bus: the whole system's centre of mass stays
    put from t = 0.
    """
    from umbrella_sim.core import UmbrellaSimulator3D

    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
        {'ribs': 3, 'base': 'free', 'bus_mass': 5.0, 'bus_inertia': 0.2,
         'rib.tip_mass': [0.05, 0.0, 0.0]}))
    s = sim.state
    p, h = sim.model.momentum(sim.model.kinematics(s.qr, s.qs), s.vr, s.vs)
    assert np.max(np.abs(p)) < 1e-14 and np.max(np.abs(h)) < 1e-14
    assert s.vs[0] == -0.2                                   # v0: the sleeve on the bus
    assert s.vs[6] == pytest.approx(0.41, abs=0.01)          # the bus turns about Z,
    assert s.vs[2] == pytest.approx(0.025, abs=0.001)        # and moves up, from t = 0
    text = ' '.join(open(PAGE, encoding='utf-8').read().split())
    assert 'A free bus starts with the whole momentum zero' in text


def test_a_start_angle_offset_starts_its_rib_strained_as_the_docs_say():
    """
    Near the folded start the sleeve hardly moves with a leaf's angle (the toggle).

    So a rib's alpha0_offset is taken up by straining the rib (the nearest configuration on
    the joints in the mass metric): 0.01 rad starts it at ~200 MPa, past 0.05 rad beyond
    yield, which the page says, with these figures.
    """
    from umbrella_sim.core import UmbrellaSimulator3D

    def start(offset):
        sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
            {'ribs': 3, 'rib1.alpha0_offset': offset}))
        a = sim.record.arrays()
        return a['stress_von_mises'][0], a['strain_energy'][0]

    (quiet, _), (small, energy), (large, _) = start(0.0), start(-0.01), start(-0.05)
    assert np.max(quiet) < 1e6
    assert small[1] == pytest.approx(204e6, rel=0.02) and energy == pytest.approx(1.5, rel=0.02)
    assert large[1] == pytest.approx(1118e6, rel=0.02) and large[1] > 2 * 500e6
    text = ' '.join(open(PAGE, encoding='utf-8').read().split())
    assert '-0.01 rad starts rib 1 of 3 at 204 MPa' in text


@pytest.mark.parametrize('values, message', [
    ({'ribs': 0}, 'parameter ribs=0: must be between 1 and 64'),    # (was the planar model)
    ({'ribs': -2, 'rib.tip_mass': [0.0, 0.1]}, 'parameter ribs=-2'),
    ({'ribs': 6, 'rib1.tip_mass': 'abc'}, "parameter rib1.tip_mass='abc'"),
    ({'ribs': 3, 'rib.tip_mass': [0.0, 'abc', 0.0]}, "parameter rib.tip_mass='abc'"),
    ({'ribs': 6, 'rib1.tipmass': 0.1}, "'rib1.tipmass'"),
    # one number where a list of every rib's is meant, a list where one rib's value is
    ({'ribs': 4, 'rib.tip_mass': 0.2}, 'parameter rib.tip_mass=0.2: a list of one value per '
                                       'rib'),
    ({'ribs': 4, 'rib.tip_mass': 'abc'}, "parameter rib.tip_mass='abc': a list"),
    ({'ribs': 3, 'rib1.tip_mass': [0.1]}, "parameter rib1.tip_mass=[0.1]: one value, rib 1's "
                                          'own'),
])
def test_a_nodes_umbrella_values_name_the_culprit(values, message):
    """A node's or a command line's values (umbrella_values): every one checked, by its name."""
    with pytest.raises(ValueError, match=re.escape(message)):
        umbrella_model(None, umbrella_values(values))


@pytest.mark.parametrize('values, height', [
    ({'ribs': 3, 'rib1.l1': 0.2}, 'start'),      # leaf + link shorter than the start height
    ({'ribs': 3, 'rib2.l3': 2.0}, 'start'),      # the link holds the sleeve above it
    ({'ribs': 2, 'rib1.l3': 0.8}, 'stop'),
])
def test_a_rib_that_cannot_reach_the_sleeve_is_named_before_any_step(values, height):
    """Its lengths and the height it misses, at validation (not scipy's root-find error)."""
    with pytest.raises(ValueError) as err:
        UmbrellaRibsParams.from_mapping(values)
    k, name = next(iter((k, n) for k, n in (key.split('.') for key in values if '.' in key)))
    text = str(err.value)
    assert text.startswith(f'rib {k[3:]}: ') and f'{name}={values[k + "." + name]:g} m' in text
    assert f"sleeve's {height} height" in text
    planar = UmbrellaRibsParams.from_mapping({}).planar
    lowest, highest = rib_reach(*(values.get(f'{k}.{n}', getattr(planar, n))
                                  for n in ('l1', 'l3')))[1:]
    y = getattr(planar, f'sleeve_{height}_height')
    assert not lowest <= y <= highest


def test_a_short_link_reaches_the_start_height_from_its_lowest_angle():
    """A link shorter than the leaf: the rib's start angle puts the sleeve where it starts."""
    l1, l3 = 0.51, 0.495
    m = UmbrellaModel3D(UmbrellaRibsParams.from_mapping({'ribs': 2, 'rib1.l1': l1,
                                                         'rib1.l3': l3}))
    a = m.rib_angle_at_height(1, m.y_start)
    assert rib_reach(l1, l3)[0] < a
    assert l1 * math.sin(a) + math.sqrt(l3 ** 2 - (l1 * math.cos(a)) ** 2) == pytest.approx(
        m.y_start, abs=1e-14)


def test_a_free_bus_takes_the_plastic_lock_by_default():
    assert UmbrellaRibsParams.from_mapping({'base': 'free'}).lock_rule == 'plastic'
    assert UmbrellaRibsParams.from_mapping({}).lock_rule == 'energy'


if __name__ == '__main__':
    with open(PAGE, encoding='utf-8') as fh:
        page = fh.read()
    with open(PAGE, 'w', encoding='utf-8') as fh:
        fh.write(generated(page))
    sys.exit(0)


@pytest.mark.parametrize('value, said', [([], 'an empty list'), (None, 'null')])
def test_an_empty_rib_list_given_is_refused_where_it_is_given(value, said):
    """A params file's or a sweep's rib.<name>: null or []: refused, naming the source."""
    with pytest.raises(ValueError, match=re.escape(
            f'params file f.yaml: parameter rib.tip_mass: {said}: give one value per rib')):
        refuse_empty_rib_lists({'ribs': 3, 'rib.tip_mass': value}, 'params file f.yaml: ')
    refuse_empty_rib_lists({'ribs': 3, 'rib.tip_mass': [0.0, 0.1, 0.0], 'tip_mass': None})


@pytest.mark.parametrize('alpha0, offset, side', [
    (0.49 * math.pi, 0.04, 'past pi/2 - 0.001'),
    (0.5, -0.3, 'at or below its deployed angle')])
def test_a_start_angle_offset_past_the_ribs_range_is_named_before_any_step(alpha0, offset, side):
    """
    rib<k>.alpha0_offset within its spec's range, yet the leaf's start out of the rib's.

    alpha0 = 0.49 pi leaves 0.0304 rad to pi/2 - 0.001, where the sleeve has no lever on
    the leaf (the run faulted at t = 0: 'the leaf reached the axle'); below, the deployed
    angle.  Refused at validation, naming the rib's value and the offsets it may take.
    """
    planar = UmbrellaRibsParams.from_mapping({'alpha0': alpha0}).planar
    room = (math.pi / 2 - 1e-3 - planar.alpha0, planar.alpha_deployed - planar.alpha0)
    with pytest.raises(ValueError, match=re.escape(f'parameter rib1.alpha0_offset={offset:g}: '
                                                   'rib 1 would start at leaf angle')) as err:
        UmbrellaRibsParams.from_mapping({'ribs': 3, 'alpha0': alpha0,
                                         'rib1.alpha0_offset': offset})
    assert side in str(err.value)
    assert f'({room[1]:.4g}, {room[0]:.4g}] rad' in str(err.value)
    UmbrellaRibsParams.from_mapping({'ribs': 3, 'alpha0': alpha0,
                                     'rib1.alpha0_offset': 0.03 if offset > 0 else -0.2})


@pytest.mark.parametrize('name, ribs, said', [
    ('rib1.tip_mass', 3, "parameter rib1.tip_mass is read-only: a rib's own value is fixed"),
    ('rib5.tip_mass', 3, 'parameter rib5.tip_mass: there are ribs 0 .. 2'),
    ('rib1.tip_mass', 1, 'parameter rib1.tip_mass: the node runs the planar model (ribs 1)'),
    ('rib1.tipmass', 3, None),              # (not a rib's value: the unknown name's refusal)
    ('v0', 3, None),
])
def test_a_runtime_set_of_a_ribs_own_value_is_refused_as_read_only(name, ribs, said):
    """A node's rib<k>.<name> not given at start: read-only, not 'unknown parameter'."""
    from umbrella_sim.ros.parameters import rib_override_refusal

    text = rib_override_refusal(name, ribs)
    assert text == said if said is None else text.startswith(said)


def test_a_ribs_torsion_fibre_distance_sets_its_torsional_stress_alone():
    """
    The torsional stress is T c_t / J: a round bar's c_t is its radius, not 0.676 b.

    Rib 1 kicked out of its plane (it twists): the same run with rib 1's c_t given moves its
    torsional stress by c_t / (0.676 b) and nothing else (c_t enters no dynamics).
    """
    from umbrella_sim.core import UmbrellaSimulator3D

    base = {'ribs': 3, 'rib1.out_of_plane_rate': 0.3, 'v0': 0.0, 'sleeve_force': 10.0}
    radius = 0.0056        # the round bar of the default 10 mm square's area
    runs = [UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(v)).run(0.02).arrays()
            for v in (base, dict(base, **{'rib1.torsion_fibre_distance': radius}))]
    square = 0.1406 / 0.208 * 0.01
    assert np.max(runs[0]['stress_torsion'][:, 1]) > 1e5           # it twists: > 0.1 MPa
    np.testing.assert_allclose(runs[1]['stress_torsion'][:, 1],
                               runs[0]['stress_torsion'][:, 1] * radius / square, rtol=1e-12)
    for name in runs[0]:
        if name != 'stress_torsion' and not name.startswith('stress_von_mises') \
                and name != 'von_mises':
            np.testing.assert_array_equal(runs[1][name], runs[0][name], err_msg=name)
    np.testing.assert_array_equal(runs[1]['stress_torsion'][:, [0, 2]],
                                  runs[0]['stress_torsion'][:, [0, 2]])
