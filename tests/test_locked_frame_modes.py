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
Stage 2 against an independent linear frame analysis of the locked frame.

The locked frame is a plane frame: the leaf O-O''-G pinned at O, the link O''-H pinned at O''
to the leaf and at H to the locked sleeve (the latch holds it both ways), every member an
Euler-Bernoulli frame element (axial bar + cubic beam, consistent masses) in the inertial
frame, no floating frames: its first mode is the stage-2 tip vibration's (the summary's
period), and a damping ratio zeta of that mode decays its amplitude as exp(-zeta omega1 t).
"""
import math

import numpy as np
import pytest
import scipy.linalg

from umbrella_sim.core.driver import simulate
from umbrella_sim.core.params import UmbrellaParams


def _element(p, length, c, s):
    """Return a frame element's stiffness and consistent mass in the inertial frame."""
    ea, ei = p.youngs_modulus * p.cross_section_area, p.youngs_modulus * p.cross_section_inertia
    mass, h = p.mass_per_length * length, length
    k, m = np.zeros((6, 6)), np.zeros((6, 6))
    k[np.ix_([0, 3], [0, 3])] = ea / h * np.array([[1, -1], [-1, 1]])
    m[np.ix_([0, 3], [0, 3])] = mass / 6 * np.array([[2, 1], [1, 2]])
    bend = [1, 2, 4, 5]
    k[np.ix_(bend, bend)] = ei / h ** 3 * np.array([
        [12, 6 * h, -12, 6 * h], [6 * h, 4 * h * h, -6 * h, 2 * h * h],
        [-12, -6 * h, 12, -6 * h], [6 * h, 2 * h * h, -6 * h, 4 * h * h]])
    m[np.ix_(bend, bend)] = mass / 420 * np.array([
        [156, 22 * h, 54, -13 * h], [22 * h, 4 * h * h, 13 * h, -3 * h * h],
        [54, 13 * h, 156, -22 * h], [-13 * h, -3 * h * h, -22 * h, 4 * h * h]])
    r = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
    t = np.zeros((6, 6))
    t[:3, :3] = t[3:, 3:] = r
    return t.T @ k @ t, t.T @ m @ t


def locked_frame_frequencies(p, n):
    """Return the locked frame's natural frequencies (rad/s), n elements a segment."""
    a = p.alpha_deployed
    joint = p.l1 * np.array([math.cos(a), math.sin(a)])
    link = np.array([0.0, p.sleeve_stop_height]) - joint
    count = iter(range(10 ** 6))
    leaf = [[next(count) for _ in range(3)] for _ in range(2 * n + 1)]
    chain = [leaf[n][:2] + [next(count)]] + [[next(count) for _ in range(3)] for _ in range(n)]
    size = next(count)
    k, m = np.zeros((size, size)), np.zeros((size, size))

    def add(a_dofs, b_dofs, length, c, s):
        ke, me = _element(p, length, c, s)
        dofs = a_dofs + b_dofs
        k[np.ix_(dofs, dofs)] += ke
        m[np.ix_(dofs, dofs)] += me

    for i in range(2 * n):
        add(leaf[i], leaf[i + 1], (p.l1 if i < n else p.l2) / n, math.cos(a), math.sin(a))
    length = float(np.linalg.norm(link))
    for i in range(n):
        add(chain[i], chain[i + 1], length / n, *(link / length))
    free = [i for i in range(size) if i not in leaf[0][:2] + chain[-1][:2]]   # pins O, H
    return np.sqrt(scipy.linalg.eigh(k[np.ix_(free, free)], m[np.ix_(free, free)],
                                     eigvals_only=True))


@pytest.mark.parametrize('n', [1, 2])
def test_the_stage2_period_is_the_locked_frames_first_mode(n):
    """The summary's stage-2 period is 2 pi / omega1 of the same mesh within 0.1 %."""
    p = UmbrellaParams(elements_per_segment=n)
    omega = locked_frame_frequencies(p, n)
    period = simulate(p, 2.0, stop_after_lock=0.3).summary()['stage2_tip_period']
    assert period == pytest.approx(2 * math.pi / omega[0], rel=1e-3)
    # and the mesh is converged in it: 64 elements a segment move omega1 by < 0.3 %
    assert omega[0] == pytest.approx(locked_frame_frequencies(p, 64)[0], rel=3e-3)


def test_damping_ratio_decays_the_first_mode_as_exp_minus_zeta_omega1_t():
    """
    damping_ratio zeta: the stage-2 tip peaks fall as exp(-zeta omega1 t), within 1 %.

    omega1 from the frame analysis above; both signs of peak, 0.45 s of stage 2 (the higher
    modes, damped at zeta omega_i / omega1, are gone after the first few peaks).
    """
    zeta = 0.02
    p = UmbrellaParams(damping_ratio=zeta)
    r = simulate(p, 2.0, stop_after_lock=0.45)
    locked = np.array([s.stage == 'locked' for s in r.samples])
    t, v = r.column('time')[locked], r.column('tip_transverse')[locked]
    inner = slice(1, -1)
    crest = (np.abs(v[inner]) >= np.abs(v[:-2])) & (np.abs(v[inner]) > np.abs(v[2:]))
    crest &= np.sign(v[inner]) != np.sign(v[:-2] - v[inner])     # maxima of +v, minima of -v
    times, peaks = t[inner][crest], np.abs(v[inner][crest])
    keep = times > times[0] + 0.05
    rate = -np.polyfit(times[keep], np.log(peaks[keep]), 1)[0]
    omega1 = locked_frame_frequencies(p, 1)[0]
    assert keep.sum() >= 12
    assert rate == pytest.approx(zeta * omega1, rel=0.01)
