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

"""The publication path without DDS: encoded bytes, marker rate, recorded bytes."""
from pathlib import Path
import subprocess
import sys

from mcap.reader import make_reader
import pytest
from rclpy.serialization import deserialize_message

from umbrella_sim.bag.cdr import cdr_bytes
from umbrella_sim.core.driver import RunDriver
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.ros import messages as ros_io
from umbrella_sim.ros.publication import PublicationEncoder
from umbrella_sim.ros.recording import record_offline


def built(encoder, s, frame_prefix):
    return ros_io.sample_messages(s, encoder.driver.params, None, '', encoder.initial_energy,
                                  frame_prefix)


def next_period(driver, force=None):
    """Step one publication period (with the command, if given) as the node does."""
    if force is not None:
        driver.command(force)
    assert driver.advance_period()[-1].error is None


@pytest.mark.parametrize('frame_prefix', ['', 'a/', 'ab/', 'abc/', 'antenna_12/'])
def test_encoded_bytes_are_the_built_messages(frame_prefix):
    """Every per-publication topic: the serializer's bytes of the builder's message, exactly."""
    driver = RunDriver(UmbrellaParams(v0=-0.5), 1000.0)
    encoder = PublicationEncoder(driver)
    seen = set()
    for period in range(400):      # deploying, the lock and after it, a force change
        next_period(driver, 25.0 if period >= 100 else None)
        s = driver.publication()
        if period % 37:
            continue
        msgs = encoder.messages(s, 'ns', 1.0, frame_prefix)
        seen.add(s.stage)
        reference = built(encoder, s, frame_prefix)
        for key, ref in reference.items():
            data = msgs[key]
            assert isinstance(data, bytes), key
            assert data == cdr_bytes(ref), key       # exact size, zero padding, every value
            assert deserialize_message(data, type(ref)) == ref, key
    assert seen == {'deploying', 'locked'}


@pytest.mark.parametrize('mesh, model, ns, frame_prefix, magnification', [
    (3, 'flexible', 'ns', '', 1.0), (1, 'flexible', 'umbrella', 'a/', 50.0),
    (2, 'flexible-nonlinear', 'abc', 'antenna_12/', 10.0), (4, 'rigid-fe', 'x', 'ab/', 1.0)])
def test_marker_bytes_are_the_built_markers(mesh, model, ns, frame_prefix, magnification):
    """
    Markers: the encoder's bytes are those of markers_msg's message, byte for byte.

    (cdr_bytes sets the CDR alignment padding, which rclpy's serializer leaves as its buffer
    held it, to zero: the encoder's template too.)
    """
    driver = RunDriver(UmbrellaParams(v0=-0.5, elements_per_segment=mesh, model=model), 1000.0)
    encoder = PublicationEncoder(driver, marker_rate=1000.0)
    seen = set()
    for period in range(320):      # deploying, the lock and after it
        s = driver.publication()
        msgs = encoder.messages(s, ns, magnification, frame_prefix)
        seen.add(s.stage)
        ref = ros_io.markers_msg(s, driver.sim.model.deformed_shape(s.q, magnification), ns,
                                 frame_prefix)
        data, expected = msgs['markers'], cdr_bytes(ref)     # (colours: float32 on the wire)
        assert data == expected
        assert deserialize_message(data, ros_io.MarkerArray) == \
            deserialize_message(expected, ros_io.MarkerArray)
        next_period(driver)
    assert seen == {'deploying', 'locked'}


@pytest.mark.parametrize('publish_rate, marker_rate', [(1000.0, 30.0), (100.0, 30.0),
                                                       (200.0, 60.0), (50.0, 100.0)])
def test_markers_at_their_documented_rate(publish_rate, marker_rate):
    """markers: every k-th publication, k = round(publish_rate / marker_rate) >= 1, t = 0 in."""
    driver = RunDriver(UmbrellaParams(), publish_rate)
    encoder = PublicationEncoder(driver, marker_rate)
    k = max(1, round(publish_rate / marker_rate))
    with_markers = []
    for _ in range(int(0.4 * publish_rate)):
        msgs = encoder.messages(driver.publication(), 'ns', 1.0)
        if 'markers' in msgs:
            with_markers.append(driver.sim.time)
            assert isinstance(deserialize_message(msgs['markers'], ros_io.MarkerArray),
                              ros_io.MarkerArray)
        next_period(driver)
    assert with_markers[0] == 0.0
    sim_span = driver.sim.time
    # the rate from counts over sim time: within one marker of publish_rate / k
    assert abs(len(with_markers) - sim_span * publish_rate / k) <= 1.0
    gaps = {round((b - a) * publish_rate) for a, b in zip(with_markers, with_markers[1:])}
    assert gaps == {k}


def test_recorded_bytes_are_the_published_bytes(tmp_path):
    """The offline recorder writes the encoder's bytes: they decode to the built messages."""
    params = UmbrellaParams(v0=-0.5)
    bag = tmp_path / 'run'
    result = record_offline(params, str(bag), 0.05, publish_rate=1000.0, keep_samples=True)
    assert result.error is None
    samples = {ros_io.stamp_ns(s.time): s for s in result.samples}
    reference = PublicationEncoder(RunDriver(params, 1000.0))
    topics = {'/' + ros_io.TOPICS[k].name: k for k in ros_io.SampleEncoder.GROUPS}
    checked = 0
    with open(Path(bag) / 'run_0.mcap', 'rb') as fh:
        for schema, channel, message in make_reader(fh).iter_messages():
            key = topics.get(channel.topic)
            if key not in ('joint_states', 'tip_deflection', 'clock'):
                continue        # (peak_stress and energy carry per-period values)
            ref = built(reference, samples[message.log_time], '')[key]
            assert len(message.data) == len(cdr_bytes(ref))
            assert deserialize_message(message.data, type(ref)) == ref
            checked += 1
    assert checked == 3 * len(samples)


def test_a_recording_does_not_depend_on_the_process_that_made_it(tmp_path):
    """
    Check that two processes recording the same run write the same bytes for every message.

    rclpy's serializer leaves the CDR alignment padding as its buffer held it, which differs
    from one process to the next; the encoders' templates have it zeroed (cdr_bytes).
    """
    code = ('import sys\n'
            'from umbrella_sim.core.params import UmbrellaParams\n'
            'from umbrella_sim.ros.recording import record_offline\n'
            'record_offline(UmbrellaParams(v0=-0.5, elements_per_segment=2), sys.argv[1], 0.3,'
            ' force_profile=[(0.1, 5.0)], publish_rate=200.0)\n')
    runs = []
    for name in ('a', 'b'):
        subprocess.run([sys.executable, '-c', code, str(tmp_path / name)], check=True,
                       timeout=300)
        with open(tmp_path / name / f'{name}_0.mcap', 'rb') as fh:
            runs.append([(channel.topic, message.log_time, message.data)
                         for _, channel, message in make_reader(fh).iter_messages()])
    topics = {topic for topic, _, _ in runs[0]}
    assert {'/joint_states', '/energy', '/peak_stress', '/tip_deflection', '/clock',
            '/markers'} <= topics
    assert len(runs[0]) > 300
    assert runs[0] == runs[1]


def assert_layout_plots(name: str, messages: dict, expected: dict) -> dict:
    """
    Resolve every plot path of config/<name> on messages: each the figure its label names.

    Returns the layout's panels; every expected label drawn, every panel placed.
    """
    import json
    import re

    root = Path(__file__).resolve().parents[1]
    layout = json.loads((root / 'config' / name).read_text('utf-8'))
    panels = layout['configById']
    three_d = panels['3D!umbrella']
    assert three_d['followTf'] == ros_io.INERTIAL_FRAME and list(three_d['topics']) == ['/markers']
    drawn = set()
    for key, panel in panels.items():
        if not key.startswith('Plot!'):
            continue
        for path in panel['paths']:
            # one time axis for the synced plots, which every topic has: the receive time
            # (a recording's log time, sim time; live, the bridge's clock).  headerStamp:
            # the Float64MultiArray topics have none, and live it is sim time against the
            # others' wall-clock receive times (foxglove_bridge without use_sim_time), so
            # its plots were drawn ~1.8e9 s out of view
            assert path['timestampMethod'] == 'receiveTime', path
            topic, *fields = re.split(r'\.', path['value'])
            value = messages[topic.lstrip('/')]
            for field in fields:
                field_name, _, index = field.partition('[')
                value = getattr(value, field_name)
                if index:
                    value = value[int(index.rstrip(']'))]
            assert value == pytest.approx(expected[path['label']], rel=1e-12, abs=0), path
            assert expected[path['label']] != 0.0
            drawn.add(path['label'])
    assert drawn == set(expected)
    # every panel is placed in the layout tree
    placed, stack = set(), [layout['layout']]
    while stack:
        node = stack.pop()
        if isinstance(node, str):
            placed.add(node)
        else:
            stack += [node['first'], node['second']]
    assert placed == set(panels)
    return panels


def test_foxglove_layout_plots_the_figures_it_names():
    """
    config/umbrella.foxglove.json: each plot path, resolved on the node's messages, is its label.

    The 3D panel shows the markers in their frame; the plots' paths (topic, field, index)
    give the tip deflection, the peak stresses, alpha1 and y_H of the sample published.
    """
    driver = RunDriver(UmbrellaParams(v0=-0.5), 100.0)
    for _ in range(15):                              # past the lock (0.09 s): all non-zero
        next_period(driver)
    s = driver.publication()
    assert s.stage.name.lower() == 'locked'
    messages = built(PublicationEncoder(driver), s, '')
    expected = {'v_G transverse (m)': s.tip_transverse, 'u_G axial (m)': s.tip_axial,
                'leaf peak |σ| (Pa)': s.peak_stress_leaf,
                'link peak |σ| (Pa)': s.peak_stress_link,
                'alpha1 (rad)': s.alpha1, 'y_H (m)': s.sleeve_position}
    assert_layout_plots('umbrella.foxglove.json', messages, expected)


def test_foxglove_layout_of_six_ribs_plots_each_ribs_figures():
    """
    config/umbrella_ribs6.foxglove.json (ribs: 6): each rib's tips, von Mises peak, alpha1.

    Every path resolved on the 6-rib node's messages (their CDR bytes, deserialized) is the
    figure of the rib its label names, in a deployment where the ribs differ (each kicked out
    of its plane at its own rate, one stiffer, one with a tip mass).
    """
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
    from umbrella_sim.ros.ribs_messages import RibsPublicationEncoder

    params = UmbrellaRibsParams.from_mapping({
        'ribs': 6, 'v0': -0.5, 'rib.out_of_plane_rate': [0.1, 0.3, -0.1, -0.2, 0.05, 0.15],
        'rib4.youngs_modulus': 8e10, 'rib5.tip_mass': 0.02})
    driver = RunDriver(params, 100.0)
    for _ in range(5):
        next_period(driver)
    s = driver.publication()
    raw = RibsPublicationEncoder(driver).messages(s)
    messages = {'joint_states': deserialize_message(raw['joint_states'], JointState),
                **{key: deserialize_message(raw[key], Float64MultiArray)
                   for key in ('rib_tip_deflection', 'rib_peak_stress')}}
    expected = {'y_H (m)': s.sleeve_position}
    for k in range(6):
        expected.update({f'rib{k} w_G (m)': s.tip[k, 2], f'rib{k} v_G (m)': s.tip[k, 1],
                         f'rib{k} peak von Mises (Pa)': s.stress_von_mises[k],
                         f'rib{k} alpha1 (rad)': s.alpha1[k]})
    assert len(set(s.alpha1)) > 1                   # (the ribs differ: each path is its own)
    assert_layout_plots('umbrella_ribs6.foxglove.json', messages, expected)
