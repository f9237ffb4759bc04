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
Each recording segment's figures of every physics step, not only the last one's.

A ~/reset ends a run: the node writes its events and its summary then (``.K`` records), as
it writes the last run's at close, so that ``umbrella_compare --segment K`` reports the
figures of every physics step of each segment.  A recording made before that (events only)
falls back to the recorded samples, says so, and says that they do not compare with the
thesis's; ``--physics-rate`` re-runs such a segment for its figures of every physics step.
The figures are checked against an offline run of the segment's parameters at its step.
"""
import json
import re

import pytest

from umbrella_sim.bag.format import EVENTS_RECORD, PARAMETERS_RECORD, SUMMARY_RECORD
from umbrella_sim.bag.provenance import events_metadata, run_metadata
from umbrella_sim.bag.reader import read_log
from umbrella_sim.bag.writer import BagRecorder
from umbrella_sim.core.driver import RunDriver, simulate
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.registry import node_defaults, SPECS
from umbrella_sim.ros import messages
from umbrella_sim.ros.publication import run_driver
from umbrella_sim.ros.recording import RunRecording
from umbrella_sim.ros.ribs_messages import node_topics
from umbrella_sim.tools import compare, replay
from umbrella_sim.tools.replay import DEFAULT_TOLERANCE, resimulate
from umbrella_sim.tools.runs import NOT_JUDGED_FROM_SAMPLES

#: the user's session: a short run at the default 100 Hz, publish_rate set to 37 Hz and
#: ~/reset, a run past its lock and stage-2 window (the thesis's data: lock at ~0.226 s, the
#: window 0.3 s after it), ~/reset again, a short last run
SEGMENTS = ((100.0, 0.05), (37.0, 0.6), (37.0, 0.1))
PARAMS = UmbrellaParams()
#: the figures compared with the offline run (of every physics step)
FIGURES = ('deploy_time', 'lock_time', 'tip_deflection_max', 'tip_deflection_max_time',
           'stage2_tip_amplitude', 'stage2_tip_period', 'peak_stress_leaf',
           'peak_stress_leaf_time', 'peak_stress_link', 'peak_stress_link_time')


def record_segments(bag, segments=SEGMENTS, summaries: bool = True) -> None:
    """
    Record runs one after another in one bag, a segment each, as the node's ~/reset does.

    Each segment: (publish_rate, duration) of PARAMS.  The node's recording path
    (RunRecording): its t = 0 publication, every publication, the applied forces, the
    phases; a new segment through RunRecording.start_segment with the ended run's sim and
    summary figures, as umbrella_node._on_reset calls it.  summaries=False writes what a
    recording made before the ended segments' summaries holds: their events only.
    """
    rec = ended = None
    for rate, duration in segments:
        driver, encoder = run_driver(PARAMS, {}, rate)
        cfg = dict(node_defaults(), publish_rate=rate, record_path=str(bag))
        meta = run_metadata(PARAMS, cfg, driver.step, driver.sim.model, driver.backend,
                            source='tests/test_segment_records.py')
        if rec is None:
            rec = RunRecording(BagRecorder(str(bag), meta),
                               {key: '/' + t.name for key, t in node_topics(1).items()},
                               '/' + messages.COMMAND.name)
        elif summaries:
            rec.start_segment(meta, driver, ended.sim, ended.summary.figures(), None)
        else:
            rec.recorder.start_segment(meta[PARAMETERS_RECORD],
                                       gap_ns=messages.stamp_ns(driver.step),
                                       ended=events_metadata(ended.sim))

        def published(s, encoder=encoder):
            rec.publish_all(encoder.messages(s, 'umbrella', 1.0), s.time)

        def chunk_done(chunk, driver=driver):
            for t, f in chunk.applied:
                rec.applied(f, t)
            if chunk.lock is not None:
                rec.publish('deployment_phase', messages.phase_msg('locked'), driver.sim.time)

        rec.publish('deployment_phase', messages.phase_msg('deploying'), 0.0)
        published(driver.publication())
        assert driver.run(duration, on_chunk=chunk_done, on_publication=published) is None
        ended = driver
    rec.close(ended.sim, accepted=0, refused=0, figures=ended.summary.figures())
    assert rec.error is None


def assert_figures(got: dict, expected: dict, what='') -> None:
    """Each of FIGURES as expected, within --resimulate's tolerance (None: a run unlocked)."""
    for key in FIGURES:
        if expected[key] is None:
            assert got[key] is None, (what, key)
        else:
            assert got[key] == pytest.approx(expected[key], rel=DEFAULT_TOLERANCE), (what, key)


def offline(rate: float, duration: float) -> dict:
    """Return the summary figures of an offline run of PARAMS at the node's step for rate."""
    return simulate(PARAMS, duration, driver=RunDriver(PARAMS, rate),
                    keep_samples=False).figures


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """Two recordings of the same session: of today, and one of before (no summary.K)."""
    root = tmp_path_factory.mktemp('segments')
    record_segments(root / 'now')
    record_segments(root / 'older', summaries=False)
    return {'now': str(root / 'now'), 'older': str(root / 'older')}


def compared(capsys, bag, tmp_path, name, *options) -> tuple[dict, str]:
    """Return umbrella_compare's compare.json entry of segment 1 and its text."""
    out = tmp_path / name
    assert compare.main([bag, '--segment', '1', '--thesis', '--out', str(out),
                         *options]) == 0
    text = capsys.readouterr().out
    return json.loads((out / 'compare.json').read_text())['runs'][0], text


def test_each_reset_writes_the_ended_segment_s_records(bags):
    """Each segment has its events and summary, in the last segment's form, of its run."""
    log = read_log(bags['now'])
    assert [s.params['publish_rate'] for s in log.segments()] == [100.0, 37.0, 37.0]
    # the ended segments' under .K, the last one's (at close) under the record's own name
    for name in (EVENTS_RECORD, SUMMARY_RECORD):
        assert {f'{name}.0', f'{name}.1', name} <= set(log.metadata)
        assert f'{name}.2' not in log.metadata
        assert log.run_record(name, 2) is log.metadata[name]
    assert log.metadata[f'{SUMMARY_RECORD}.1'].keys() == log.metadata[SUMMARY_RECORD].keys()
    for k, (rate, duration) in enumerate(SEGMENTS):
        figures, warnings = log.summary(k)
        expected = offline(rate, duration)
        assert_figures(figures, expected, k)
        assert warnings == expected['warnings']
        assert log.run_record(EVENTS_RECORD, k)['locked'] == ('true' if k == 1 else 'false')
    # the older form: the events of each ended segment, no summary but the last one's
    older = read_log(bags['older'])
    assert older.summary(0) is None and older.summary(1) is None
    assert older.summary(2) == log.summary(2)
    assert older.run_record(EVENTS_RECORD, 1) == log.run_record(EVENTS_RECORD, 1)


def test_compare_reports_an_earlier_segment_s_figures_of_every_physics_step(
        bags, tmp_path, capsys):
    """
    Segment 1 at 37 Hz: the figures of every physics step, as the offline run of it.

    The user's report: stage 2 53.88 mm / 0.0541 s of the 37 Hz samples where its physics
    gives 62.26 mm / 0.0470 s.
    """
    expected = offline(37.0, 0.6)
    run, text = compared(capsys, bags['now'], tmp_path, 'cmp', '--no-plots')
    figures = run['figures']
    assert figures['figures_from'] == 'every physics step (recording metadata)'
    assert_figures(figures, expected)
    amplitude, period = expected['stage2_tip_amplitude'], expected['stage2_tip_period']
    assert f'stage 2 {amplitude * 1e3:.4g} mm / {period:.4f} s' in text, text
    assert 'thesis_note' not in run and 'caveat' not in text and 'not_judged' not in run
    # the samples at 37 Hz fall beside the crests: what the segment printed before
    samples = compare.load_run(bags['now'], segment=1)
    samples.summary = None
    sampled = samples.figures()
    assert sampled['stage2_tip_amplitude'] < 0.9 * amplitude
    assert sampled['stage2_tip_period'] != pytest.approx(period, rel=0.05)


def test_an_older_recording_s_earlier_segment_falls_back_with_its_caveat(
        bags, tmp_path, capsys):
    """No summary record of segment 1: the samples, saying so, and not as the thesis's."""
    run, text = compared(capsys, bags['older'], tmp_path, 'cmp', '--no-plots')
    why = run['figures']['figures_from']
    assert why.startswith('recorded samples at 37.0 Hz: the log has no summary record of '
                          'segment 1') and 'depend on the recording rate' in why
    assert '--physics-rate re-runs' in why
    assert run['thesis'] and 'not comparable' in run['thesis_note']
    thesis_line = next(i for i, line in enumerate(text.splitlines())
                       if line.strip().startswith('thesis:'))
    assert text.splitlines()[thesis_line + 1].strip().startswith('caveat: not comparable')
    # what the samples cannot judge is said, not left as if judged quiet
    assert run['not_judged'] == [NOT_JUDGED_FROM_SAMPLES]
    assert "not judged: 'axial load'" in text
    # a deployment time alone (Table 6.1's V0) is the exact lock's: no caveat
    r = compare.load_run(bags['older'], segment=1)
    assert r.summary is None and r.lock_time_exact
    r.params = dict(r.params, v0=-0.5)
    entry = compare.compare([r], thesis=True)['runs'][0]
    assert entry['thesis'] and 'thesis_note' not in entry
    # the segment 2, the last, has its record: no caveat
    out = tmp_path / 'last'
    assert compare.main([bags['older'], '--segment', '2', '--thesis', '--no-plots',
                         '--out', str(out)]) == 0
    assert 'caveat' not in capsys.readouterr().out


@pytest.mark.parametrize('plots', [False, pytest.param(True, marks=pytest.mark.slow)],
                         ids=['no-plots', 'plots'])      # (the plots: ~8 s)
def test_physics_rate_re_runs_an_earlier_segment_for_its_figures(
        bags, tmp_path, capsys, plots):
    """--physics-rate on segment 1 of an older recording: the re-run's every-step figures."""
    if plots:
        pytest.importorskip('matplotlib')
    expected = offline(37.0, 0.6)
    options = ['--physics-rate'] + ([] if plots else ['--no-plots'])
    run, text = compared(capsys, bags['older'], tmp_path, 'cmp', *options)
    figures = run['figures']
    assert figures['figures_from'].startswith('every physics step (--physics-rate: a re-run')
    assert_figures(figures, expected)
    assert run['warnings'] == expected['warnings']
    assert 'thesis_note' not in run and 'caveat' not in text
    # the same figures as the record a recording of today holds
    now, _ = compared(capsys, bags['now'], tmp_path, 'cmp_now', *options)
    assert_figures(figures, now['figures'])
    if plots:       # (drawn from the re-run's series)
        assert len(json.loads((tmp_path / 'cmp' / 'compare.json').read_text())['plots']) >= 4


def test_replay_info_names_each_segment_s_summary(bags, capsys):
    assert replay.main([bags['now'], '--info']) == 0
    info = capsys.readouterr().out
    assert ('summary:       the figures of every physics step of segment(s) 0, 1, 2 in the '
            "'umbrella_sim.summary[.K]' metadata records") in info, info
    # each segment's run alike, and its own lock (its events record): segment 1's alone
    # locked (0 and 2 end before theirs)
    for k in (0, 1, 2):
        assert re.search(rf'^segment {k}: .*model flexible, 1 element\(s\) a segment, '
                         r'v0 -0.2 m/s, lock auto, grid step [0-9.e-]+ s'
                         r"( \(stage 2's physics step [0-9.e-]+ s\))?$", info, re.M), info
    locked = re.findall(r'^locked: +at t = [0-9.]+ s \(energy lock\) \((.*)\)$', info, re.M)
    assert locked == ['segment 1'], info
    # the build record is written at the start: its kernel is segment 0's
    assert re.search(r'^build: .*, kernel \S+ \(segment 0\)', info, re.M), info
    assert replay.main([bags['older'], '--info']) == 0
    info = capsys.readouterr().out
    assert 'of segment(s) 2 in the' in info and 'none of segment(s) 0, 1 (' in info, info


def test_both_recordings_re_simulate_segment_by_segment(bags):
    for bag in bags.values():
        res = resimulate(read_log(bag))
        assert len(res['segments']) == 3 and not res['problems']
        assert max(res['relative_diff'].values()) == 0.0


def _segment_model(params: dict) -> UmbrellaParams:
    return UmbrellaParams.from_mapping({n: v for n, v in params.items() if n in SPECS})


@pytest.mark.ros
@pytest.mark.slow
def test_the_node_writes_each_ended_segment_s_summary_at_reset(
        antenna_factory, tmp_path, capsys):
    """
    The user's session on a live node: publish_rate 37, ~/reset, a run, ~/reset, stop.

    umbrella_compare --segment 1 --thesis --physics-rate printed the 37 Hz samples' figures
    (53.88 mm / 0.0541 s) for segment 1; its summary record now gives those of every
    physics step, as an offline run of its parameters at its step.
    """
    bag = tmp_path / 'pr'
    antenna = antenna_factory(record_path=str(bag))
    antenna.set_parameters(publish_rate=37.0)
    antenna.reset()
    antenna.wait_for_phase('locked', timeout=60)
    antenna.wait_for_sim_time(0.6, timeout=60)   # past the lock and the stage-2 window
    antenna.reset()
    assert antenna.stop() == 0
    log = read_log(str(bag))
    seg = log.segment(1)
    assert seg.params['publish_rate'] == 37.0 and len(log.segments()) == 3
    assert {f'{SUMMARY_RECORD}.0', f'{SUMMARY_RECORD}.1', SUMMARY_RECORD} <= set(log.metadata)
    figures, _ = log.summary(1)
    model = _segment_model(seg.params)
    expected = simulate(model, figures['final_time'], driver=RunDriver(model, 37.0),
                        keep_samples=False).figures
    assert figures['stage2_tip_amplitude'] == pytest.approx(
        expected['stage2_tip_amplitude'], rel=DEFAULT_TOLERANCE)
    assert figures['stage2_tip_period'] == pytest.approx(expected['stage2_tip_period'],
                                                         rel=DEFAULT_TOLERANCE)
    assert float(log.run_record(EVENTS_RECORD, 1)['lock_time']) == pytest.approx(
        expected['lock_time'], abs=1e-12)
    assert log.summary(0) is not None and log.summary(2) is not None
    run, text = compared(capsys, str(bag), tmp_path, 'c1', '--physics-rate')
    assert run['figures']['figures_from'] == 'every physics step (recording metadata)'
    assert run['figures']['stage2_tip_amplitude'] == figures['stage2_tip_amplitude']
    assert 'caveat' not in text
