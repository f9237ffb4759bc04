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
The umbrella's validity warnings judge each rib by its own material and leaf.

A rib may have its own Young's modulus and lengths (rib<k>.youngs_modulus, rib<k>.l2): its
fibre strain is its own peak stress over its own E, and its tip deflection is a share of its
own leaf l1 + l2.  Each run below has one rib past a limit only by its own values: judged by
the planar record's E or leaf (as the rule did), it passed unnoticed.  Each test applies the
rule to the run's own summary figures and the ribs' parameters, not to a recorded figure.
"""
from umbrella_sim.core import simulate, UmbrellaParams, UmbrellaRibsParams
from umbrella_sim.core.summary import STRAIN_LIMIT, TIP_DEFLECTION_LIMIT


def _run(values: dict, duration: float):
    params = UmbrellaRibsParams.from_mapping({'ribs': 2, 'v0': -0.3, **values})
    return params, simulate(params, duration).summary()


def _keyed(warnings: list, key: str) -> list:
    return [w for w in warnings if w.startswith(key + ':')]


def test_a_soft_rib_strained_past_the_limit_is_named_by_its_own_modulus():
    # rib 1 of a stiff polymer (E = 3 GPa), through the lock at V0 = -0.3 m/s
    params, s = _run({'rib1.youngs_modulus': 3e9, 'rib1.density': 1500.0}, 0.18)
    assert s['lock_time'] is not None
    peaks = s['peak_stress']['von_mises']['value']
    strains = [p / rib.planar.youngs_modulus for p, rib in zip(peaks, params.ribs_list())]
    # the case: rib 1 past the limit by its own E, no rib past it by the planar record's
    assert strains[1] > STRAIN_LIMIT > max(peaks) / params.planar.youngs_modulus
    assert max(peaks) <= params.planar.yield_strength
    said = _keyed(s['warnings'], 'large strain')
    assert len(said) == 1 and said[0].startswith('large strain: rib 1, ')
    assert f'{100 * strains[1]:.3g} %' in said[0]


def test_a_short_leaf_deflected_past_the_limit_is_judged_on_its_own_length():
    # rib 1's leaf 0.85 m (l2 0.35 m) and softer (E = 15 GPa)
    params, s = _run({'rib1.l2': 0.35, 'rib1.youngs_modulus': 1.5e10}, 0.18)
    tips = s['max_in_plane_tip']
    leaves = [rib.planar.l1 + rib.planar.l2 for rib in params.ribs_list()]
    shares = [tip / leaf for tip, leaf in zip(tips, leaves)]
    planar_leaf = params.planar.l1 + params.planar.l2
    # the case: rib 1 past 10 % of its own leaf, no rib past 10 % of the planar record's
    assert shares[1] > TIP_DEFLECTION_LIMIT > max(tips) / planar_leaf
    said = _keyed(s['warnings'], 'large deflection')
    assert len(said) == 1 and said[0].startswith('large deflection: rib 1, ')
    assert f'{100 * shares[1]:.3g} % of the leaf length {leaves[1]:g} m' in said[0]


def test_identical_ribs_are_judged_as_the_planar_model():
    # where every rib takes the planar record, the planar run's rule, with its figures
    params, s = _run({}, 0.18)
    planar = simulate(UmbrellaParams(v0=-0.3), 0.18).summary()
    for key in ('large strain', 'large deflection'):
        assert bool(_keyed(s['warnings'], key)) == bool(_keyed(planar['warnings'], key))
