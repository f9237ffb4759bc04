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


"""The node's Fast DDS profile: set only where nobody set one, and one that Fast DDS reads."""
import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

from umbrella_sim.ros.dds_profile import (PROFILE, PROFILE_ENV, use_node_profile,
                                          WORKING_DIR_PROFILE)
from umbrella_sim.ros.share import package_path
from umbrella_sim.testing import ros_env

NS = '{http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles}'


def test_the_profile_is_set_when_nobody_set_one(tmp_path):
    for rmw in ({}, {'RMW_IMPLEMENTATION': 'rmw_fastrtps_cpp'}):
        environ = dict(rmw)
        path = use_node_profile(environ, cwd=str(tmp_path))
        assert path == package_path(*PROFILE) and os.path.isfile(path)
        assert environ == {**rmw, PROFILE_ENV: path}


@pytest.mark.parametrize('environ', [
    {'FASTRTPS_DEFAULT_PROFILES_FILE': '/somewhere/mine.xml'},
    {'FASTDDS_DEFAULT_PROFILES_FILE': '/somewhere/mine.xml'},
    {'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp'},
    {'RMW_IMPLEMENTATION': 'rmw_zenoh_cpp'},
])
def test_a_users_profile_or_another_rmw_is_left_alone(environ, tmp_path):
    given = dict(environ)
    assert use_node_profile(environ, cwd=str(tmp_path)) is None
    assert environ == given


def test_a_profile_fast_dds_reads_from_the_working_directory_is_left_alone(tmp_path):
    (tmp_path / WORKING_DIR_PROFILE).write_text('<profiles/>')
    environ = {}
    assert use_node_profile(environ, cwd=str(tmp_path)) is None and environ == {}
    environ = {'SKIP_DEFAULT_XML': '1'}         # Fast DDS skips that file: ours applies
    assert use_node_profile(environ, cwd=str(tmp_path)) == package_path(*PROFILE)


def test_the_profile_sets_the_writers_nack_suppression_and_nothing_else():
    root = ET.parse(package_path(*PROFILE)).getroot()
    assert [child.tag for child in root] == [NS + 'data_writer']    # no participant, transport
    writer = root[0]
    assert writer.get('is_default_profile') == 'true'
    assert [child.tag for child in writer] == [NS + 'times']         # no QoS policy
    (times,) = writer
    assert [child.tag for child in times] == [NS + 'nackSupressionDuration']
    duration = {child.tag[len(NS):]: int(child.text) for child in times[0]}
    assert duration == {'sec': 0, 'nanosec': 5_000_000}


FAST_DDS_READS = """
import rclpy
rclpy.init()
node = rclpy.create_node('profile_check')
node.create_publisher(__import__('std_msgs.msg').msg.Float64, 'profile_check', 10)
node.destroy_node()
rclpy.shutdown()
print('made')
"""


@pytest.mark.ros
def test_fast_dds_reads_the_profile_without_an_error(tmp_path):
    # a misspelt element is an error Fast DDS prints: the check sees one
    bad = tmp_path / 'bad.xml'
    bad.write_text(open(package_path(*PROFILE)).read().replace('<times>', '<timez>')
                   .replace('</times>', '</timez>'))
    for path, errors in ((package_path(*PROFILE), False), (str(bad), True)):
        out = subprocess.run([sys.executable, '-c', FAST_DDS_READS], capture_output=True,
                             text=True, timeout=60, cwd=str(tmp_path),
                             env={**ros_env(), PROFILE_ENV: path})
        said = out.stdout + out.stderr          # (Fast DDS logs to stdout)
        assert out.stdout.strip().endswith('made'), said
        assert ('XMLPARSER' in said) is errors, said


@pytest.mark.ros
def test_the_node_runs_on_its_profile_and_is_heard():
    """A node started as users start it says which profile it took, and its topics come."""
    from umbrella_sim.testing import SimulatedAntenna

    with SimulatedAntenna({'ribs': 2, 'publish_rate': 100.0}) as antenna:
        antenna.wait_for('joint_states', lambda m: True, timeout=30)
        assert f'Fast DDS profile {package_path(*PROFILE)}' in antenna.node.output()
