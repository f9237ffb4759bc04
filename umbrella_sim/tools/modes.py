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
``umbrella_sim modes``: the deployed antenna's natural frequencies (core/modal.py), no run.

On a prescribed base spinning at base_spin_rate, the spinning antenna's: in the frame turning
with the hub, about its spun equilibrium (core/umbrella3d/spun_modes3d.py), each row's whirl.
"""
from __future__ import annotations

import argparse
import json
import sys

from .arguments import add_parameter_options
from .inputs import build_params
from ..core.modal import base_spin, BEAM_MODELS, deployed_modes
from ..core.summary import parameter_warnings
from ..core.umbrella3d.summary3d import rib_parameter_warnings

#: rows printed by default
DEFAULT_COUNT = 12
#: a rib named as a mode's own when it holds at least this share of the mode's strain energy
OWN_RIB_SHARE = 0.9
#: a mesh up to this many elements a segment, unchecked (no --mesh-check), says so: its rows
#: past the first few are far from converged (the thesis's frame at 1: mode 2 11 % high, 4 37 %)
COARSE_MESH = 2


def add_parser(sub) -> argparse.ArgumentParser:
    sp = sub.add_parser(
        'modes', help="the deployed frame's natural frequencies (no run)",
        description='Print the natural frequencies of the frame locked at full deployment '
                    '(the sleeve at the stop; linearised about the undeformed deployed '
                    'frame): the modes stage 2 vibrates in. Repeated frequencies (N '
                    'identical ribs) are one row, with their count; the umbrella of N ribs '
                    "says where each mode's strain energy is (in-plane, out-of-plane "
                    'bending, twist) and which rib holds it. On a prescribed base spinning '
                    '(base_spin_rate), the modes of the spinning antenna in the frame turning '
                    'with the hub, about its spun equilibrium (centrifugal stiffening, spin '
                    "softening, Coriolis coupling), with each mode's whirl. Parameters as for "
                    'simulate.')
    add_parameter_options(sp, BEAM_MODELS)    # (a rigid frame has no elastic modes)
    sp.add_argument('--count', type=int, default=DEFAULT_COUNT,
                    help=f'rows to print (default {DEFAULT_COUNT}; repeated frequencies '
                         'are one row)')
    sp.add_argument('--mesh-check', action='store_true',
                    help="each row's change against the same mode on twice the elements a "
                         'segment (>= 0: the frequencies converge from above); '
                         'elements_per_segment 32 at most')
    sp.add_argument('--json', action='store_true', help='print the rows as JSON')
    sp.set_defaults(v0=None, force=None, lock=None, time_step=None, publish_rate=None,
                    mcap=None, marker_magnification=None)
    return sp


def _first_modes(rows) -> list[int]:
    """Return each row's first mode number (the text's 'mode': repeated modes counted)."""
    first = [1]
    for r in rows[:-1]:
        first.append(first[-1] + r.multiplicity)
    return first


def _mesh_changes(params, rows) -> list[float]:
    """
    Return each row's omega over the same mode's on twice the elements a segment, less 1.

    Modes matched by number (repeated ones counted): the nested mesh's k-th frequency is at
    most the coarse one's (Rayleigh-Ritz), so the change bounds the row's error from below.
    """
    n = getattr(params, 'planar', params).elements_per_segment
    if 2 * n > 64:
        raise ValueError(f'--mesh-check: elements_per_segment {n}: twice it passes 64; give '
                         '32 or fewer')
    fine = [r.omega for r in deployed_modes(params.replace(elements_per_segment=2 * n))
            for _ in range(r.multiplicity)]
    return [r.omega / fine[m - 1] - 1.0 for m, r in zip(_first_modes(rows), rows)]


def _json_row(row, mode: int, change: float | None) -> dict:
    """Return a row for --json: its rib the text's, None where no rib holds OWN_RIB_SHARE."""
    out = {'mode': mode, **row.as_dict(), 'mesh_change': change}
    if row.rib_share < OWN_RIB_SHARE:
        out['rib'] = None
    return out


def _warnings(params) -> list[str]:
    """
    Return the static parameter warnings a run gives (summary.parameter_warnings).

    A modulus in GPa, a density in g/cm³, a member too stubby for Euler-Bernoulli beams: the
    frequencies they spoil; each rib's own where its values differ, naming it; not the run's
    'coarse stage-1 step', which has no bearing on the modes.
    """
    planar = getattr(params, 'planar', params)
    out = parameter_warnings(planar.as_dict())
    if planar is not params:
        out += rib_parameter_warnings(params)
    return [w for w in out if not w.startswith('coarse stage-1 step')]


def _spun_heading(spin: float, params) -> str:
    """Return the heading's account of the spin: the frame, the equilibrium, what counts."""
    nonlinear = params.planar.model == 'flexible-nonlinear'
    return (f'on the base spinning at {spin:g} rad/s about Y (base_spin_rate): in the frame '
            'turning with the hub, linearised about the spun equilibrium (the ribs deflected '
            "by the centrifugal load); the co-rotational beams' centrifugal stiffening, the "
            'spin softening and the Coriolis coupling counted'
            + ('' if nonlinear else " (model flexible's linear beams lack the stiffening: "
               "its runs ring lower, flexible-nonlinear's at these)")
            + '; whirl: the orbit about the spin axis against a circular one, + forward (with '
            'the spin), - backward (Coriolis splits a pair of equal frequencies into one of '
            'each)')


def _whirl(whirl: float) -> str:
    """Return a row's whirl as the text prints it: signed, and its sense where it has one."""
    text = f'{whirl:+.4f}'
    if float(text) == 0.0:
        return f'{abs(whirl):.4f}'
    return text + (' forward' if whirl > 0 else ' backward')


def main(args, ap: argparse.ArgumentParser) -> int:
    try:
        if args.count < 1:
            raise ValueError(f'--count {args.count}: must be >= 1')
        build_params(args)
        rows = deployed_modes(args.model, args.count)
        changes = (_mesh_changes(args.model, rows) if args.mesh_check else
                   [None] * len(rows))
    except ValueError as exc:
        ap.exit(2, f'umbrella_sim: error: {exc}\n')
    for text in _warnings(args.model):
        print(f'umbrella_sim: warning: {text}', file=sys.stderr)
    spin = base_spin(args.model)
    if args.json:
        print(json.dumps([_json_row(r, m, c) for m, r, c in
                          zip(_first_modes(rows), rows, changes)], indent=2))
        return 0
    umbrella = args.model is not getattr(args.model, 'planar', args.model)
    base = getattr(args.model, 'base', 'fixed')
    damped = any(r.damping_ratio > 0.0 for r in rows)
    n = getattr(args.model, 'planar', args.model).elements_per_segment
    coarse = (f'; {n} element{"s" if n > 1 else ""} a segment: past the first modes far '
              'from converged, from above (--mesh-check: their change on twice the elements)'
              if n <= COARSE_MESH and not args.mesh_check else '')
    print('natural frequencies of the frame locked at full deployment (the sleeve at the stop), '
          + (_spun_heading(spin, args.model) if spin else
             'linearised about the undeformed frame') + (
              '; on the free-floating bus (its six rigid-body modes left out)' if base == 'free'
              else '; the hub held' if umbrella else
              '; the planar frame: its in-plane modes only (out of its plane, bending and '
              'twist: --set ribs=2 or more)') + (
              '; f, period and omega undamped (a damped mode rings at f sqrt(1 - ratio^2); '
              'one of ratio >= 1 does not oscillate)' if damped else '') + coarse)
    head = f"{'mode':>4}  {'f (Hz)':>10}  {'period (ms)':>11}  {'omega (rad/s)':>13}"
    if args.mesh_check:
        head += f"  {'2N change':>9}"
    if umbrella:
        head += f"  {'count':>5}  {'in-plane':>8}  {'out-of-plane':>12}  {'twist':>6}  rib"
    print(head + ('  damping ratio' if damped else '') + ('  whirl' if spin else ''))
    for number, r, change in zip(_first_modes(rows), rows, changes):
        line = (f'{number:>4}  {r.frequency:>10.4f}  {1e3 * r.period:>11.4f}  '
                f'{r.omega:>13.2f}')
        if change is not None:
            line += f"  {f'{100 * change:+.3g}%':>9}"
        if umbrella:
            rib = (f'rib {r.rib}' if r.rib_share >= OWN_RIB_SHARE else
                   f'one in each of {r.multiplicity} ribs' if r.one_a_rib else
                   f'spread, <= {100 * r.rib_share:.0f} % a rib')
            line += (f'  {r.multiplicity:>5}  {100 * r.in_plane:>7.1f}%  '
                     f'{100 * r.out_of_plane:>11.1f}%  {100 * r.twist:>5.1f}%  {rib}')
        print(line + (f'  {r.damping_ratio:.4g}' if damped else '')
              + (' (overdamped)' if r.damping_ratio >= 1.0 else '')
              + (f'  {_whirl(r.whirl)}' if spin else ''))
    return 0
