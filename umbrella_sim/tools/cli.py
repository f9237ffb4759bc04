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

"""Offline command line: ``umbrella_sim simulate``, ``sweep`` and ``modes``."""
from __future__ import annotations

import argparse
import json
import math
import os
import sys

from . import modes, sweep
from .arguments import add_parameter_options, ArgumentParser, GivenOnce
from .csv_output import StepCsv, UmbrellaStepCsv
from .inputs import build_params, check_run_length, LONG_RUN_STEPS, read_force_profile
from .progress import Progress
from .. import __version__
from ..bag.paths import check_new_output, remove_recording
from ..core.driver import RunDriver, simulate, simulator_class
from ..core.params import shortened_step_note
from ..core.registry import parameter_help, SPECS
from ..core.umbrella3d.params3d import umbrella_parameter_help
from ..ros.signals import deferred, EXIT_READER_GONE, interruptible, print_for_reader


def make_parser() -> argparse.ArgumentParser:
    ap = ArgumentParser(prog='umbrella_sim',
                        description='Flexible umbrella-frame deployment simulator.')
    ap.add_argument('--version', action='version', version=f'umbrella_sim {__version__}')
    sub = ap.add_subparsers(dest='command', required=True)
    sp = sub.add_parser('simulate', help='run one simulation offline',
                        description='Run the physics core offline and report the result. '
                                    'Units SI (m, s, N, Pa, rad).',
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        epilog='parameters (--set NAME=VALUE, or a --params file):\n'
                               + '\n'.join(parameter_help(SPECS.values())
                                           + umbrella_parameter_help()))
    add_parameter_options(sp)
    sp.add_argument('--v0', type=float, action=GivenOnce,
                    help='initial sleeve velocity along Y (m/s)')
    force = sp.add_mutually_exclusive_group()
    force.add_argument('--force', type=float, action=GivenOnce,
                       help='constant sleeve force F_H >= 0 (N)')
    force.add_argument('--force-profile', metavar='CSV',
                       help='CSV of t,F rows (s, N): F_H held from each t until the next; '
                            'an optional header naming other units, t (ms), is refused')
    sp.add_argument('--lock', choices=SPECS['lock'].choices, action=GivenOnce)
    sp.add_argument('--time-step', type=float, dest='time_step', action=GivenOnce,
                    help='physics step (s)')
    sp.add_argument('--duration', type=float, default=1.0, help='simulated time (s)')
    sp.add_argument('--long-run', action='store_true',
                    help=f'run more than {LONG_RUN_STEPS:.0e} physics steps (refused without '
                         'it: hours of computing or more)')
    sp.add_argument('--csv', metavar='FILE',
                    help='write the time series of every grid step (its state at the '
                         "step's end; peak stresses: the largest over the step, stage 2's "
                         'substeps folded into their grid step), streamed as the run goes; '
                         'the umbrella of N ribs: the sleeve, the energies '
                         "and each rib's figures, named by the rib (rib0_alpha1, rib0_tip_w, "
                         'rib0_stress_von_mises, ...)')
    sp.add_argument('--csv-state', action='store_true',
                    help="add q, q' and the fibre stress at every stress point to the CSV")
    sp.add_argument('--json', action='store_true', help='print one JSON summary')
    sp.add_argument('--mcap', metavar='BAG_DIR',
                    help="record the node's topics to a new bag directory (BAG_DIR/"
                         'BAG_DIR_0.mcap + metadata.yaml), as umbrella_node would; the same '
                         'states, summary and --csv rows (every grid step) as without it '
                         "when the physics step divides the publication period (the default's "
                         'does; else the recording takes the largest step that does, as the '
                         'node, and says so)')
    sp.add_argument('--overwrite', action='store_true',
                    help='replace an existing --csv file and --mcap recording (a directory '
                         'of .mcap files and metadata.yaml, nothing else) when the run '
                         'starts; without it an existing output is an error')
    sp.add_argument('--publish-rate', type=float, default=None, dest='publish_rate',
                    action=GivenOnce,
                    help='publication rate of the --mcap recording (Hz, sim time; also '
                         "--set publish_rate=... or the params file's; default 100); the "
                         'summary is the same at any rate whose period the step divides')
    sp.set_defaults(marker_magnification=None)
    sweep.add_parser(sub)
    modes.add_parser(sub)
    return ap


#: text summary: key -> (unit, scale, format); keys in this order, then any others
TEXT_FIELDS = {
    'deploy_time': ('s', 1.0, '.6f'),
    'deploy_start': ('s', 1.0, '.6f'),
    'lock_time': ('s', 1.0, '.6f'),
    'tip_deflection_max': ('mm', 1e3, '.4g'),
    'tip_deflection_max_time': ('s', 1.0, '.4f'),
    'stage2_tip_amplitude': ('mm', 1e3, '.4g'),
    'stage2_tip_period': ('s', 1.0, '.5f'),
    'stage2_window': ('s', 1.0, '.4f'),
    'stage2_tip_w_amplitude': ('mm', 1e3, '.4g'),
    'stage2_tip_w_period': ('s', 1.0, '.5f'),
    'peak_stress_leaf': ('MPa', 1e-6, '.4g'),
    'peak_stress_leaf_x': ('m', 1.0, '.4g'),
    'peak_stress_leaf_time': ('s', 1.0, '.4f'),
    'peak_stress_link': ('MPa', 1e-6, '.4g'),
    'peak_stress_link_x': ('m', 1.0, '.4g'),
    'peak_stress_link_time': ('s', 1.0, '.4f'),
    'yield_strength': ('MPa', 1e-6, '.4g'),
    'stress_ratio_max': ('-', 1.0, '.3g'),
    'tip_deflection_ratio_max': ('% of l1+l2', 100.0, '.3g'),
    'leaf_tension_ratio_max': ('% of the Euler load', 100.0, '.3g'),
    'axial_load_ratio_max': ("% of the link's Euler load", 100.0, '.3g'),
    'lock': ('', None, ''),
    'lock_energy_before': ('J', 1.0, '.6g'),
    'lock_energy_after': ('J', 1.0, '.6g'),
    'lock_free_velocities': ('', None, ''),
    'energy_drift': ('-', 1.0, '.2e'),
    'constraint_residual_max': ('m, m/s', 1.0, '.1e'),
    'final_time': ('s', 1.0, '.4f'),
    'steps': ('', None, ''),
    'wall_time': ('s', 1.0, '.2f'),
    'real_time_factor': ('-', 1.0, '.3g'),
    'figures_from': ('', None, ''),
    # the umbrella of N ribs (Summary3D): lists are per rib, rib 0 first
    'ribs': ('', None, ''),
    'rib_deploy_time': ('s', 1.0, '.6f'),
    'deployment_lag': ('s', 1.0, '.3e'),
    'latest_rib': ('', None, ''),
    'max_leaf_angle_spread': ('rad', 1.0, '.3e'),
    'max_leaf_angle_spread_time': ('s', 1.0, '.4f'),
    'max_out_of_plane_tip': ('mm', 1e3, '.4g'),
    'max_out_of_plane_tip_rib': ('', None, ''),
    'max_out_of_plane_tip_time': ('s', 1.0, '.4f'),
    'max_in_plane_tip': ('mm', 1e3, '.4g'),
    'peak_stress': ('MPa', 1e-6, '.4g'),
    'sleeve_work': ('J', 1.0, '.4g'),
    'friction_work': ('J', 1.0, '.4g'),
    'drive_work': ('J', 1.0, '.4g'),
    'damping_dissipation': ('J', 1.0, '.4g'),
    'lock_energy_loss': ('J', 1.0, '.4g'),
    'energy_balance_residual': ('J', 1.0, '.2e'),
    'energy_scale': ('J', 1.0, '.6g'),
}
#: the summary's lists that are per rib (the others with a unit: a range, 'from to')
PER_RIB = ('rib_deploy_time', 'max_in_plane_tip', 'friction_work', 'stage2_tip_amplitude',
           'stage2_tip_period', 'stage2_tip_w_amplitude', 'stage2_tip_w_period')
#: the umbrella's vectors at the end of the run (a moving base's): each component, its unit
_BUS = (('X', 'm'), ('Y', 'm'), ('Z', 'm'), ('psi', 'rad'), ('beta', 'rad'), ('gamma', 'rad'))
VECTORS = {'bus_q': _BUS,
           'bus_v': tuple((f"{c}'", u + '/s') for c, u in _BUS),
           'linear_momentum': tuple((c, 'kg m/s') for c in 'XYZ'),
           'angular_momentum': tuple((c, 'kg m²/s') for c in 'XYZ')}


def format_summary(summary: dict) -> str:
    """
    Return the summary as text: one figure a line, with its unit, rounded to what it means.

    The warnings and the error are printed to stderr (main).
    """
    lines = []
    keys = [k for k in TEXT_FIELDS if k in summary]
    keys += sorted(k for k in summary if k not in TEXT_FIELDS and k not in ('warnings', 'error'))
    for key in keys:
        value = summary[key]
        unit, scale, spec = TEXT_FIELDS.get(key, ('', None, ''))
        if key == 'peak_stress' and isinstance(value, dict):    # the umbrella's, per rib
            lines += _rib_peaks(value, unit, scale, spec)
            continue
        if key == 'stage2_resolution' and isinstance(value, dict):
            lines.append(f'{key:28s} {_resolution_text(value)}')
            continue
        if key in VECTORS and isinstance(value, list):
            text = ', '.join(f'{c} {v:.4g} {u}' for (c, u), v in zip(VECTORS[key], value))
            lines.append(f'{key:28s} {text}')
            continue
        if key in PER_RIB and isinstance(value, list):
            text = ', '.join('-' if v is None else format(v * scale, spec) for v in value)
            lines.append(f'{key:28s} {text} {unit}')
            continue
        if value is None:
            text = '-'
        elif isinstance(value, list) and scale is None:
            text = ', '.join(str(v) for v in value) or '-'
        elif isinstance(value, list):
            text = ' to '.join(format(v * scale, spec) for v in value) + f' {unit}'
        elif scale is None or isinstance(value, str):
            text = str(value)
        else:
            text = f'{format(value * scale, spec)} {unit}'.rstrip()
        lines.append(f'{key:28s} {text}')
    return '\n'.join(lines)


def _resolution_text(resolution: dict) -> str:
    """Return step_rule.stage2_resolution as text: the steps in ms, the shares in per cent."""
    def ms(key):
        h = resolution.get(key)
        return '-' if h is None else f'{h * 1e3:.4g} ms'

    def percent(key):
        share = resolution.get(key)
        return '-' if share is None else f'{share * 100:.2g} %'
    text = (f"step {ms('step')} (needed {ms('needed_step')}: resolving {ms('resolving_step')}, "
            f"coupled {ms('coupled_step')}); stress crest unresolved: leaf {percent('leaf')}, "
            f"link {percent('link')}")
    if resolution.get('deflection') is not None:
        text += f"; the lock's tip crest {percent('deflection')} of l1+l2"
    return text


def _rib_peaks(peaks: dict, unit: str, scale: float, spec: str) -> list[str]:
    """Return the umbrella's peak stresses as text: a line a component, each rib's peak."""
    lines = []
    for name, peak in peaks.items():
        values = ', '.join(format(v * scale, spec) for v in peak['value'])
        lines.append(f"{'peak_' + name:28s} {values} {unit}")
        if name == 'von_mises':
            where = ', '.join(f'{b} {x:.4g} m at {t:.4f} s'
                              for b, x, t in zip(peak['body'], peak['x'], peak['time']))
            lines.append(f"{'peak_von_mises_at':28s} {where}")
    return lines


class CsvStream:
    """
    --csv FILE while the run goes: a write error stops the file, not the run.

    The file keeps the rows it holds whole (a row cut by the error is cut off; a file
    without one whole row is removed), and ``error`` says how many.
    """

    def __init__(self, path: str, initial, state_model=None, umbrella: bool = False):
        """Stream to path; umbrella: the umbrella of N ribs' columns (initial a Sample3D)."""
        self.path, self.initial, self.state_model = path, initial, state_model
        self.umbrella = umbrella
        self.error: str | None = None
        self.rows = 0
        self._out = None

    def write(self, chunk) -> None:
        if self.error is not None:
            return
        try:
            with deferred():    # a stop signal lands between chunks, never inside a row
                if self._out is None:
                    self._out = (UmbrellaStepCsv(self.path, self.initial) if self.umbrella
                                 else StepCsv(self.path, self.state_model))
                    self._out.write_sample(self.initial)
                self._out.write(chunk.block, chunk.lock_sample)
                self.rows = self._out.rows
        except OSError as exc:
            self.error = f'--csv {self.path}: {exc.strerror or exc}'
            self.close()
            self.rows, last = keep_whole_rows(self.path)
            self.error += (f' (the file keeps its first {self.rows} rows whole, to '
                           f"t = {float(last.split(b',', 1)[0]):g} s)" if self.rows
                           else ' (removed: it held no whole row)')

    def close(self) -> None:
        if self._out is not None:
            try:
                self._out.close()
            except OSError as exc:
                self.error = self.error or f'--csv {self.path}: {exc.strerror or exc}'
            self._out = None


def keep_whole_rows(path: str) -> tuple[int, bytes]:
    """
    Cut a text file after its last whole line; return its rows after the header, and the last.

    What a write error left: the row it cut is cut off.  A file without one whole row is
    removed (0, b''); one that cannot be reached counts 0.
    """
    try:
        with open(path, 'r+b') as fh:
            lines, end, chunk = 0, 0, 1 << 20
            while block := fh.read(chunk):
                lines += block.count(b'\n')
                if b'\n' in block:
                    end = fh.tell() - len(block) + block.rindex(b'\n') + 1
            fh.truncate(end)
            fh.seek(max(0, end - chunk))
            last = fh.read().rstrip(b'\n').rsplit(b'\n', 1)[-1]
        if lines < 2:           # (not one whole row: nothing worth keeping)
            os.unlink(path)
            return 0, b''
        return lines - 1, last
    except OSError:
        return 0, b''


def write_stdout(text: str) -> bool:
    """Print text; False if the reader went away (``umbrella_sim simulate | head``)."""
    return print_for_reader(lambda: sys.stdout.write(text + '\n'))


@interruptible('umbrella_sim', 'what was written is complete (a --mcap recording is '
               'finalised up to the interruption, --csv holds every step before it)')
def main(argv: list[str] | None = None) -> int:
    ap = make_parser()
    args = ap.parse_args(argv)
    if args.command == 'sweep':
        return sweep.main(args, ap)
    if args.command == 'modes':
        return modes.main(args, ap)
    try:
        params = build_params(args)
        # checked against the run's model: the umbrella's bound is its weakest link's
        profile = (read_force_profile(args.force_profile, args.model)
                   if args.force_profile else None)
        if not (math.isfinite(args.duration) and args.duration > 0):
            raise ValueError(f'--duration {args.duration}: must be > 0')
        # the planar model, or with ribs >= 2 the umbrella of N ribs
        run = args.model
        step = simulator_class(run).grid_step(run)
        if args.duration < step * (1.0 - 1e-9):   # (it ran no step)
            raise ValueError(f'--duration {args.duration}: shorter than one physics step '
                             f'({step:g} s); the run takes every step that ends by then')
        check_run_length(args.duration, step, args.long_run, '--long-run')
        outputs = {}
        for option, path, kind in (('--csv', args.csv, 'file'),
                                   ('--mcap', args.mcap, 'recording')):
            if path is not None:
                outputs[option] = check_new_output(path, option,
                                                   kind if args.overwrite else None)
        if len(set(outputs.values())) < len(outputs):
            raise ValueError(f'--csv and --mcap name the same path {args.csv}: give each '
                             'output its own')
        if args.csv_state and run is not params:
            raise ValueError('--csv-state: the umbrella of N ribs (ribs >= 2) offers no state '
                             "rows (q, q' and every stress point); its --csv has each rib's "
                             'figures')
        if args.csv_state and not args.csv:
            raise ValueError('--csv-state adds columns to --csv FILE: give --csv too')
        if not (math.isfinite(args.publish_rate) and 1.0 <= args.publish_rate <= 5000.0):
            raise ValueError(f'--publish-rate {args.publish_rate}: must be in [1, 5000] Hz')
        # the model, before the run (a ModelError names the parameters); --mcap's recording
        # builds its own on the publication grid
        driver = RunDriver(run, force_profile=profile)
    except ValueError as exc:
        ap.exit(2, f'umbrella_sim: error: {exc}\n')
    progress = (Progress(args.duration, lambda t: f't = {t:.3f} of {args.duration:g} s')
                if sys.stderr.isatty() and not args.json else None)
    csv = (CsvStream(args.csv, driver.initial, driver.sim.model if args.csv_state else None,
                     umbrella=run is not params) if args.csv else None)

    def on_chunk(chunk) -> None:
        if csv is not None:
            csv.write(chunk)
        if progress is not None:
            progress.update(chunk.end_time)

    try:
        if args.mcap:
            note = shortened_step_note(step, args.publish_rate)
            if note:
                print(f'umbrella_sim: note: the --mcap recording takes a {note}',
                      file=sys.stderr)
            from ..ros.recording import record_offline
            try:
                if args.overwrite:          # (the run starts now: the old one goes)
                    remove_recording(outputs['--mcap'], '--mcap')
                result = record_offline(params, args.mcap, args.duration, profile,
                                        publish_rate=args.publish_rate,
                                        marker_magnification=args.marker_magnification,
                                        on_chunk=on_chunk, states=args.csv_state,
                                        what='--mcap', umbrella=args.umbrella)
            except ValueError as exc:
                ap.exit(2, f'umbrella_sim: error: {exc}\n')
        else:
            result = simulate(run, args.duration, keep_samples=False, on_chunk=on_chunk,
                              states=args.csv_state, driver=driver)
    finally:
        if csv is not None:
            csv.close()
    if progress:
        progress.close()
    summary = result.summary()
    end = summary.get('final_time')
    if not result.error and end is not None and end < args.duration * (1.0 - 1e-9):
        print(f'umbrella_sim: note: the run ends at t = {end:.9g} s, its last step that ends '
              f'by --duration {args.duration:g} s (not a whole number of steps)',
              file=sys.stderr)
    for text in summary.get('warnings', []):
        print(f'umbrella_sim: warning: {text}', file=sys.stderr)
    reader_there = write_stdout(json.dumps(summary, indent=2, sort_keys=True) if args.json
                                else format_summary(summary))
    output_errors = [e for e in (getattr(result, 'recording_error', None),
                                 csv.error if csv else None) if e]
    for output_error in output_errors:      # (each output that failed, named)
        print(f'umbrella_sim: error: output incomplete: {output_error} (the summary above '
              'is complete)', file=sys.stderr)
    if result.error:
        kept = (f' (kept the {csv.rows} rows before it in {args.csv})'
                if csv is not None and not csv.error else '')
        print(f'umbrella_sim: error: {result.error}{kept}', file=sys.stderr)
        return 3
    if output_errors:
        return 4
    return 0 if reader_there else EXIT_READER_GONE


if __name__ == '__main__':
    sys.exit(main())
