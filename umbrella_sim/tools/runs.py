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
A recorded run as umbrella_compare reads it: its signals, figures, shapes and warnings.

``load_run`` reads one segment of a recording (live or offline) into a ``Run``: the joint
angles and rate, the tip deflection, the stresses, the energy balance, the deformed shapes
of its markers, the exact lock instant and the summary figures the recording holds;
``physics_run`` re-runs the segment for its signals at every physics step;
``default_window`` is the span the plots show unless told; ``thesis_figures`` are the
thesis's figures (Hu, McGill 2006, ch. 6) for a run of its data.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import json
import math
import os

import numpy as np

from ..bag.format import EVENTS_RECORD, MAGNIFICATION_RECORD, SUMMARY_RECORD
from ..bag.provenance import summary_metadata, summary_of
from ..bag.reader import LogError, read_log
from ..core.beam import shape_abscissae
from ..core.params import UmbrellaParams
from ..core.step_rule import beams_record, follows_lock
from ..core.summary import (centrifugal_tension_per_rate, deploy_start_of, leaf_tension_ratio,
                            mesh_resolution, relative_drift, stage2_figures, validity_warnings)
from ..ros.messages import (energy_figures, joint_state_figures, peak_stress_figures,
                            tip_deflection_figures)

#: the figures compared between runs (outputs.SummaryAccumulator names)
FIGURE_KEYS = ('deploy_time', 'deploy_start', 'lock_time', 'tip_deflection_max',
               'tip_deflection_max_time', 'stage2_tip_amplitude', 'stage2_tip_period',
               'stage2_window',
               'peak_stress_leaf', 'peak_stress_leaf_x', 'peak_stress_leaf_time',
               'peak_stress_link', 'peak_stress_link_x', 'peak_stress_link_time',
               'stress_ratio_max', 'tip_deflection_ratio_max', 'leaf_tension_ratio_max',
               'axial_load_ratio_max')


RIGID_MODELS = ('rigid', 'rigid-fe')
#: what the validity rule cannot judge on recorded samples (Run.not_judged)
NOT_JUDGED_FROM_SAMPLES = ("'axial load' (its figure, the members' axial stress at every step, "
                           'is in the summary record, not in a topic): --physics-rate re-runs '
                           'the segment for it')


#: the shapes plot draws the largest elastic displacement of a stage at most this fraction
#: of the leaf length l1 + l2: --magnification is reduced to it (the title says to what)
SHAPE_DISPLACEMENT_LIMIT = 0.2

#: the plots' default window: the deployment and this many periods of the locked frame's
#: first mode after the lock (with the thesis's data: t = 0 .. 0.6 s)
WINDOW_PERIODS = 8

#: Table 6.1 (deformable FEA, rigid FEA) and the V0 = -0.2 figures quoted in ch. 6
THESIS_TABLE_6_1 = {-0.5: (0.09040, 0.09033), -1.0: (0.04525, 0.04517), -2.0: (0.02343, 0.02259)}
THESIS_V02 = {'deploy_time': 0.2259, 'tip_deflection_max': 0.665e-3,
              'tip_deflection_max_time': 0.08, 'stage2_tip_amplitude': 0.060,
              'stage2_tip_period': 0.05}
#: the parameters that are the thesis's data (its figures apply to a run only with these)
THESIS_DATA = ('l1', 'l2', 'l3', 'section_height', 'area', 'second_moment_of_area',
               'youngs_modulus', 'density', 'alpha0', 'alpha_deployed', 'sleeve_force',
               'damping_ratio')


def thesis_figures(params: dict) -> dict:
    """
    Return the thesis's figures for a run of these parameters ({} where it has none).

    Table 6.1's deployment times at V0 = -0.5, -1, -2 m/s (deploy_time_deformable_fea,
    deploy_time_rigid_fea) and the V0 = -0.2 m/s figures (THESIS_V02's names; of them a
    rigid model gets the deployment time only), for a run of the thesis's data (THESIS_DATA
    as the defaults; any model, mesh and step).
    """
    if _not_thesis_data(params):
        return {}
    v0 = params.get('v0')
    if v0 in THESIS_TABLE_6_1:
        deformable, rigid = THESIS_TABLE_6_1[v0]
        return {'deploy_time_deformable_fea': deformable, 'deploy_time_rigid_fea': rigid}
    if v0 != -0.2:
        return {}
    if params.get('model') in RIGID_MODELS:       # (its tip and stresses are not elastic)
        return {'deploy_time': THESIS_V02['deploy_time']}
    return dict(THESIS_V02)


def _not_thesis_data(params: dict) -> list[str]:
    """Return the names of THESIS_DATA whose value in params is not the thesis's."""
    thesis = UmbrellaParams()
    out = []
    for name in THESIS_DATA:
        try:
            if not math.isclose(float(params[name]), float(getattr(thesis, name)),
                                rel_tol=1e-9, abs_tol=1e-12):
                out.append(name)
        except (KeyError, TypeError, ValueError):
            out.append(name)
    return out


def no_thesis_figures(params: dict) -> str:
    """Say why the thesis has no figures for a run of these parameters (thesis_figures: {})."""
    changed = _not_thesis_data(params)
    if changed:
        return (f"its {', '.join(changed)} {'differs' if len(changed) == 1 else 'differ'} "
                "from the thesis frame's (config/umbrella.yaml)")
    speeds = ', '.join(f'{v:g}' for v in sorted(THESIS_TABLE_6_1, reverse=True))
    return (f'the thesis has figures at V0 = -0.2 m/s (ch. 6) and {speeds} m/s (Table 6.1), '
            f"not at V0 = {params.get('v0')} m/s")


@dataclass
class Run:
    label: str
    path: str
    params: dict
    t: np.ndarray
    alpha1: np.ndarray
    alpha1_rate: np.ndarray
    tip_t: np.ndarray
    tip_v: np.ndarray
    stress_t: np.ndarray
    peak_leaf: np.ndarray
    peak_link: np.ndarray
    stress_joint: np.ndarray
    stress_mid: np.ndarray
    lock_time: float | None        # the lock instant (sim time)
    energy_drift: float | None
    shapes: list = field(default_factory=list)      # [(t, leaf_xy, link_xy)]
    magnification: float = 1.0
    alpha2: np.ndarray | None = None
    leaf_node_x: np.ndarray | None = None
    link_node_x: np.ndarray | None = None
    summary: dict | None = None       # umbrella_sim.summary metadata: every physics step
    warnings: list | None = None
    lock_kind: str | None = None
    # every physics step of a re-run of the log (--physics-rate): replay.physics_series
    physics: dict | None = None
    # lock_time is the exact lock instant (the events record); False: the time of the
    # first publication after it (the "locked" phase message of a log without that record),
    # whose samples are already of stage 2
    lock_time_exact: bool = True
    deploy_start: float | None = 0.0     # outputs.deploy_start of the recorded run
    segment: int | None = None           # a segment before the log's last (its own record)
    # where summary is from: the recording's record, or a re-run (physics_figures)
    summary_from: str = 'recording metadata'
    ended_early: str | None = None       # the recording's write error, if it stopped on one
    # the solver fault that ended the segment: (sim time of its last good state, the reason)
    fault: tuple | None = None
    # runtime sets of marker_magnification: [(sim time, value)], the markers after each time
    # drawn at its value (before the first: magnification, the segment's parameter)
    magnifications: list = field(default_factory=list)
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def deploy_time(self) -> float | None:
        """Return the deploy time: the lock less the start of the deployment (one rule)."""
        if self.lock_time is None:
            return None
        return self.lock_time - (self.deploy_start or 0.0)

    @property
    def rigid(self) -> bool:
        """Say whether the model has no elastic field (its zero stress is not a result)."""
        return self.params.get('model') in RIGID_MODELS

    def shape(self, t: float, magnification: float):
        """
        Return the deformed shape nearest to t at another magnification.

        The elastic part is re-scaled from the recorded
        marker magnification to another one (undeformed frames from the joint angles).
        Each body's recorded points are its nodes and, in a recording since the markers
        draw each element's cubic, points evenly between them (drawn_abscissae).
        """
        tm, leaf, link = min(self.shapes, key=lambda s: abs(s[0] - t))
        leaf_x = drawn_abscissae(self.leaf_node_x, len(leaf))
        link_x = drawn_abscissae(self.link_node_x, len(link))
        drawn_at = self.magnification_at(tm)
        if leaf_x is None or link_x is None or drawn_at <= 0:
            return tm, leaf, link
        a1 = np.interp(tm, self.t, self.alpha1)
        a2 = np.interp(tm, self.t, self.alpha2)
        leaf_u = np.outer(leaf_x, [math.cos(a1), math.sin(a1)])
        link_u = link[0] + np.outer(link_x, [math.cos(a2), math.sin(a2)])
        scale = magnification / drawn_at
        return tm, leaf_u + scale * (leaf - leaf_u), link_u + scale * (link - link_u)

    def magnification_at(self, t: float) -> float:
        """Return the magnification the markers of sim time t were drawn at."""
        drawn_at = self.magnification
        for since, value in self.magnifications:
            if t > since + 0.5e-9:      # (the recording's times are whole ns)
                drawn_at = value
        return drawn_at

    def nodes(self, points: np.ndarray, body: str) -> np.ndarray:
        """Return the nodes among a body's drawn points (all of them if not known)."""
        node_x = self.leaf_node_x if body == 'leaf' else self.link_node_x
        if drawn_abscissae(node_x, len(points)) is None:
            return points
        return points[::(len(points) - 1) // (len(node_x) - 1)]

    def locked_period(self) -> float | None:
        """Return the period (s) of the locked frame's first mode, of the run's parameters."""
        from ..core.model import UmbrellaModel
        from ..core.params import recorded_params

        if 'locked_period' not in self._cache:
            try:
                omega = UmbrellaModel(recorded_params(self.params)).locked_modes[0]
                omega = omega[omega > 0]
            except (ValueError, KeyError, TypeError, np.linalg.LinAlgError):
                omega = []
            self._cache['locked_period'] = (float(2 * math.pi / omega[0]) if len(omega)
                                            else None)
        return self._cache['locked_period']

    def figures(self) -> dict:
        """
        Return the summary figures, saying where they come from (figures_from).

        From the segment's summary record (every physics step) when the log has it, or
        from a re-run of the segment (--physics-rate: physics_figures), else from the
        recorded samples (older or killed recordings), which depend on the rate.
        """
        if self.summary is not None:
            out = {k: self.summary.get(k) for k in FIGURE_KEYS}
            out['figures_from'] = f'every physics step ({self.summary_from})'
            return out
        out = {'deploy_time': self.deploy_time, 'deploy_start': self.deploy_start,
               'lock_time': self.lock_time}
        lock = self.lock_time if self.lock_time is not None else math.inf
        s1 = self.tip_t <= lock if self.lock_time_exact else self.tip_t < lock
        if s1.any():
            i = int(np.argmax(np.abs(self.tip_v[s1])))
            out['tip_deflection_max'] = float(abs(self.tip_v[s1][i]))
            out['tip_deflection_max_time'] = float(self.tip_t[s1][i])
        out.update(stage2_figures(self.tip_t, self.tip_v, self.lock_time))
        for body, peaks in (('leaf', self.peak_leaf), ('link', self.peak_link)):
            i = int(np.argmax(peaks))
            out[f'peak_stress_{body}'] = float(peaks[i])
            out[f'peak_stress_{body}_time'] = float(self.stress_t[i])
        rate = self.params.get('publish_rate')
        why = (f'the log has no summary record of segment {self.segment} (a recording made '
               "before a ~/reset wrote the ended run's)" if self.segment is not None else
               f'the recording ended early ({self.ended_early}) before its summary record'
               if self.ended_early else
               'the log has no summary record (an older recording, or its writer was killed)')
        out['figures_from'] = (f'recorded samples at {rate} Hz: {why}, so these figures '
                               'depend on the recording rate (--physics-rate re-runs the '
                               'segment for the figures of every physics step)')
        return out

    def not_judged(self) -> list[str]:
        """
        Return what validity() cannot judge: on the samples, 'axial load' of a locked run.

        Its figure (the members' axial stress at every step, model flexible) is the summary
        record's, in no topic.
        """
        if (self.warnings is None and self.lock_time is not None
                and self.params.get('model') == 'flexible'):
            return [NOT_JUDGED_FROM_SAMPLES]
        return []

    def validity(self) -> list:
        """Return the recorded validity warnings, or the same rule applied to the samples."""
        if self.warnings is not None:
            return list(self.warnings)
        tip = float(np.abs(self.tip_v).max()) if len(self.tip_v) else 0.0
        peak = float(max(self.peak_leaf.max(), self.peak_link.max()))
        step = self.params.get('physics_step', self.params.get('time_step'))
        try:
            beams = beams_record(self.params)
            # stage 2 took the step its lock needs where the step was chosen for the run
            # (the live summary is silent there too); else it stepped on the grid
            resolution = (None if beams is not None and follows_lock(beams)
                          else mesh_resolution(self.params, step))
            return validity_warnings(self.params, self.lock_kind, peak, tip,
                                     locked=self.lock_time is not None,
                                     energy_drift=self.energy_drift,
                                     stage2_resolution=resolution,
                                     centrifugal_tension=self.leaf_tension())
        except (KeyError, TypeError):
            return []

    def leaf_tension(self) -> float | None:
        """
        Return the leaf's largest centrifugal tension over its Euler load in stage 1.

        summary.leaf_tension_ratio at the recorded hinge rates before the lock (at the
        recording's rate: a peak between two samples is missed); None for a model without
        beams.  A recording load_run reads is the planar model's (ribs 1), whose hub is fixed:
        it has no base rate, and the hinge rate's tension is the whole of it (a moving base
        needs ribs 2 or more, read by compare_ribs, whose sampled figures judge no validity).
        """
        beams = beams_record(self.params)
        if beams is None:
            return None
        lock = self.lock_time if self.lock_time is not None else math.inf
        rate = self.alpha1_rate[self.t < lock]
        return float(np.max(leaf_tension_ratio(centrifugal_tension_per_rate(beams), rate),
                            initial=0.0))


def drawn_abscissae(node_x, n_points: int) -> np.ndarray | None:
    """
    Return the body abscissae of a drawn shape of n_points over these nodes, or None.

    Each element in the same number of equal pieces (core.model.shape_abscissae): one
    (the nodes) in recordings made before the markers drew each element's cubic.
    """
    if node_x is None or len(node_x) < 2:
        return None
    per, rest = divmod(n_points - 1, len(node_x) - 1)
    return shape_abscissae(node_x, per) if per >= 1 and not rest else None


def default_window(runs: list[Run]) -> tuple[float, float]:
    """
    Return the span (t0, t1) the plots show unless told (--window).

    Per run: from the start of its deployment (less a tenth of it, when it starts after
    t = 0) to WINDOW_PERIODS periods of the locked frame's first mode after its lock,
    within what it recorded; a run that never locked, all of it.  The union of the runs'.
    """
    spans = []
    for r in runs:
        first, last = float(r.t[0]), float(r.t[-1])
        if r.lock_time is None:
            spans.append((first, last))
            continue
        start = first if r.deploy_start is None else max(first, r.deploy_start)
        period = r.locked_period() or (r.figures().get('stage2_tip_period') or 0.0)
        t1 = r.lock_time + max(WINDOW_PERIODS * period, r.lock_time - start)
        spans.append((max(first, start - 0.1 * (r.lock_time - start)), min(last, t1)))
    return min(s[0] for s in spans), max(s[1] for s in spans)


def _series(log, topic, fn, segment, width: int, stride: int = 1):
    """
    Return (t, values) of one topic of one segment.

    (t, values) of one topic of one segment, streamed: only the extracted numbers are kept
    (every stride-th message).
    """
    t, rows = [], []
    for i, (tm, m) in enumerate(log.iter_decoded(topic, segment)):
        if i % stride:
            continue
        try:
            row = fn(m)
        except (IndexError, KeyError, AttributeError, TypeError) as exc:
            raise LogError(f'{log.path}: topic {topic}: message {i} lacks the fields '
                           f'umbrella_sim writes ({exc})') from None
        t.append(tm)
        rows.append(row)
    if not t and width:
        raise LogError(f'{log.path}: topic {topic} has no messages'
                       + (f' in segment {segment.index}' if segment.index else '')
                       + log.truncation_note())
    order = np.argsort(np.array(t), kind='stable')
    return np.array(t)[order], [rows[i] for i in order]


def default_label(path: str) -> str:
    """Return a run's label: its bag directory's name, or its .mcap file's without .mcap."""
    name = os.path.basename(os.path.normpath(path)) or path
    return name[:-len('.mcap')] if name.endswith('.mcap') and len(name) > 5 else name


def label_width(entries: list) -> int:
    """Return the width of a text table's run column: its longest label, at least 18."""
    return max([18] + [len(e['label']) for e in entries])


#: the stress figures of a Run, in the order of its fields
STRESS_FIGURES = ('peak_stress_leaf', 'peak_stress_link', 'stress_leaf_joint', 'stress_link_mid')


#: the energy figures compare reads
ENERGY_FIGURES = ('kinetic_energy', 'strain_energy', 'work', 'energy_balance',
                  'phase_correction_energy')


def _figures(figures: dict, *names: str) -> tuple:
    return tuple(figures[n] for n in names)


def recorded_lock(log, segment: int) -> tuple[dict, float | None, bool]:
    """
    Return a segment's events record, its lock instant (None: no lock) and whether exact.

    The events record's (umbrella_sim.events.K: segment K ended by a reset;
    umbrella_sim.events: the last one), else the first 'locked' phase message's time (not
    exact: the publication after the lock).
    """
    events = log.run_record(EVENTS_RECORD, segment)
    if events.get('locked') == 'true':
        return events, float(events['lock_time']), True
    phase = log.find_topic('deployment_phase', required=False)
    locked = ([tm for tm, m in log.iter_decoded(phase, log.segment(segment))
               if m.data == 'locked'] if phase else [])
    return events, (min(locked) if locked else None), not locked


def recorded_magnifications(log, seg) -> list[tuple[float, float]]:
    """Return a segment's runtime marker_magnification sets: [(sim time, value)], in order."""
    out = []
    for name, rec in log.metadata.items():
        if not name.startswith(MAGNIFICATION_RECORD + '.'):
            continue
        try:
            n, log_ns = int(name.rsplit('.', 1)[1]), int(rec['log_time_ns'])
            value = float(json.loads(rec['value']))
        except (KeyError, TypeError, ValueError):
            raise LogError(f'{log.path}: metadata record {name} is malformed') from None
        if log_ns >= seg.offset_ns and (seg.end_ns is None or log_ns < seg.end_ns):
            out.append((n, (log_ns - seg.offset_ns) * 1e-9, value))
    return [(t, value) for _, t, value in sorted(out)]      # (in the order they were set)


def recorded_fault(log, segment: int, events: dict) -> tuple | None:
    """
    Return the solver fault that ended a segment: (its last good state's time, the reason).

    The events record's, else the first 'fault' phase message's time (a log killed before
    its events record: the reason is only in the node's log); None if it did not fault.
    """
    if 'fault' in events:
        return float(events['fault_time']), events['fault']
    phase = log.find_topic('deployment_phase', required=False)
    faulted = ([tm for tm, m in log.iter_decoded(phase, log.segment(segment))
                if m.data == 'fault'] if phase else [])
    return (min(faulted), "deployment_phase 'fault' (the log has no events record: the "
            "reason is in the node's log)") if faulted else None


def load_run(path: str, label: str | None = None, segment: int = 0) -> Run:
    log = read_log(path)
    seg = log.segment(segment)
    params = seg.params
    ribs = params.get('ribs', 1)
    if isinstance(ribs, int) and ribs > 1:
        raise LogError(f'{log.path}: a recording of the umbrella of {ribs} ribs: load_run '
                       "reads the planar rib's topics (tip_deflection, peak_stress); "
                       'compare_ribs.load_ribs_run reads its per-rib series (umbrella_compare '
                       'compares such recordings rib by rib, with per-rib plots and a top '
                       'view)')
    t, js = _series(log, log.find_topic('joint_states'),
                    lambda m: _figures(joint_state_figures(m), 'alpha1', 'alpha1_rate',
                                       'alpha2'), seg, 3)
    tt, tip = _series(log, log.find_topic('tip_deflection'),
                      lambda m: tip_deflection_figures(m)['tip_transverse'], seg, 1)
    ts, st = _series(log, log.find_topic('peak_stress'),
                     lambda m: _figures(peak_stress_figures(m), *STRESS_FIGURES), seg,
                     len(STRESS_FIGURES))
    st = np.array(st)
    last = len(log.segments()) - 1
    events, deploy, exact = recorded_lock(log, segment)
    drift = None
    energy = log.find_topic('energy', required=False)
    if energy:
        # (the earlier phase correction's term, in the energy that integrator kept, where an
        # older recording has it; 0 elsewhere)
        _, e = _series(log, energy, lambda m: _figures(
            {'phase_correction_energy': 0.0, **energy_figures(m)}, *ENERGY_FIGURES), seg, 0)
        e = dict(zip(ENERGY_FIGURES, np.array(e).reshape(-1, len(ENERGY_FIGURES)).T))
        if len(e['work']):
            mechanical = (e['kinetic_energy'] + e['strain_energy']
                          + e['phase_correction_energy'])
            drift = relative_drift(e['energy_balance'], mechanical, e['work'])
    shapes = []
    markers = log.find_topic('markers', required=False)
    if markers:           # at most ~2000 shapes kept, whatever the log's length
        stride = max(1, log.count(markers) // 2000)

        def shape(m):
            return [np.array([[p.x, p.y] for p in mk.points]) for mk in m.markers[:2]]
        tm_all, pts_all = _series(log, markers, shape, seg, 0, stride)
        shapes = [(tm, pts[0], pts[1]) for tm, pts in zip(tm_all, pts_all) if len(pts) == 2]
    if label is None:
        label = default_label(path)
    a = np.array(js)
    mesh = log.metadata.get('umbrella_sim.mesh', {})       # the first segment's
    leaf_x = np.array(json.loads(mesh['leaf_node_x'])) if 'leaf_node_x' in mesh else None
    link_x = np.array(json.loads(mesh['link_node_x'])) if 'link_node_x' in mesh else None
    if segment and leaf_x is not None:      # a later segment: its own mesh (a reset may change N)
        leaf_x, link_x = _segment_mesh(log, params)
    summary, warnings = log.summary(segment) or (None, None)
    applied_topic = log.find_topic('sleeve_force/applied', required=False)
    applied = ([(tm, m.data) for tm, m in log.iter_decoded(applied_topic, seg)]
               if applied_topic else [])
    start = deploy_start_of(params, applied)
    return Run(label, log.path, params, t, a[:, 0], a[:, 1], tt, np.array(tip), ts,
               *st.T, deploy, drift, shapes,
               float(params.get('marker_magnification', 1.0)), a[:, 2], leaf_x, link_x,
               summary, warnings, events.get('lock_kind'), lock_time_exact=exact,
               deploy_start=start, segment=segment if segment != last else None,
               ended_early=log.ended_early or None,
               fault=recorded_fault(log, segment, events),
               magnifications=recorded_magnifications(log, seg))


def _segment_mesh(log, params: dict):
    """Return the leaf's and the link's node positions of a segment's own parameters."""
    from ..core.model import UmbrellaModel
    from ..core.params import recorded_params

    try:
        model = UmbrellaModel(recorded_params(params))
    except ValueError as exc:
        raise LogError(f"{log.path}: a segment's parameters cannot be used ({exc})") from None
    return np.array(model.leaf.node_x), np.array(model.link.node_x)


def physics_run(path: str, segment: int = 0, until: float | None = None,
                figures: bool = False) -> dict:
    """
    Return the signals of one log's segment at every physics step (a re-run of it).

    figures: the re-run goes on to the segment's end for its summary figures (replay.
    physics_series); physics_figures gives them to a Run.
    """
    from .replay import physics_series

    log = read_log(path)
    return physics_series(log, log.segment(segment), until, figures)


def physics_figures(run: Run, figures: dict) -> None:
    """
    Give a run the summary figures of a re-run of its segment (every physics step).

    In the summary record's form (provenance.summary_metadata, read back by summary_of:
    the figures and the warnings apart, as JSON holds them), so that they read as a
    recorded summary does.
    """
    run.summary, run.warnings = summary_of(summary_metadata(figures)[SUMMARY_RECORD])
    run.summary_from = ('--physics-rate: a re-run of the segment from its recorded '
                        'parameters and commands')
