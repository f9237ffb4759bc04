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
Test the `ros2 run` contract.

Colcon builds the package, the ament index resolves it, and
<prefix>/lib/umbrella_sim/umbrella_node runs (ros2cli itself is not on PyPI).
"""
import os
import shutil
import subprocess
import sys

import pytest

from tests.ros_helpers import ros_env

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
COLCON = os.path.join(os.path.dirname(sys.executable), 'colcon')
pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_colcon_build_and_ros2_run_resolution(tmp_path):
    assert os.path.exists(COLCON), 'colcon-common-extensions missing: install requirements.txt'
    src = tmp_path / 'src' / 'umbrella_sim'
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(
        '.git', '.venv', 'build', 'install', 'log', '__pycache__', '*.egg-info', '*.so',
        '.pytest_cache'))
    env = ros_env()
    env['AMENT_PREFIX_PATH'] = sys.prefix        # the venv is an ament prefix (rclpy wheels)
    build = subprocess.run([COLCON, 'build', '--base-paths', str(tmp_path / 'src'),
                            '--build-base', str(tmp_path / 'build'),
                            '--install-base', str(tmp_path / 'install')],
                           cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stdout + build.stderr
    # what `ros2 run umbrella_sim umbrella_node` does after `source install/setup.bash`
    script = f"""
source {tmp_path}/install/setup.bash
index="import ament_index_python.packages as p"
prefix=$({sys.executable} -c "$index; print(p.get_package_prefix('umbrella_sim'))")
share=$({sys.executable} -c "$index; print(p.get_package_share_directory('umbrella_sim'))")
echo "prefix=$prefix"
exec "$prefix/lib/umbrella_sim/umbrella_node" --ros-args \
    --params-file "$share/config/umbrella.yaml" \
    -p v0:=-0.5 -p duration:=0.2 -p real_time_factor:=0.0
"""
    workdir = tmp_path / 'work'        # `ros2 run` records into the working directory
    workdir.mkdir()
    run = subprocess.run(['bash', '-c', script], env=env, capture_output=True, text=True,
                         timeout=120, cwd=workdir)
    out = run.stdout + run.stderr
    assert run.returncode == 0, out
    assert f'prefix={tmp_path}/install/umbrella_sim' in out
    # the installed node runs the default config as the source tree's simulator does
    from umbrella_sim.core.driver import simulate
    from umbrella_sim.core.params import UmbrellaParams
    from umbrella_sim.core.registry import SPECS
    from umbrella_sim.ros.params_file import load_params_file

    config = load_params_file(os.path.join(ROOT, 'config', 'umbrella.yaml'))
    params = UmbrellaParams.from_mapping({k: v for k, v in config.items() if k in SPECS})
    offline = simulate(params.replace(v0=-0.5), 0.2, stop_after_lock=0.0).lock.time
    assert f'locked at t = {offline:.9f} s' in out and 'duration 0.2 s reached' in out
    assert 'kernel compiled' in out                   # colcon built the C step too
    # its own Fast DDS profile, the installed one (msg_docs/README.md)
    assert (f'Fast DDS profile {tmp_path}/install/umbrella_sim/share/umbrella_sim/config/'
            'fastdds_node.xml' in out), out
    for name in ('package.xml', 'config/umbrella.yaml', 'msg_docs/parameters.md',
                 'launch/umbrella.launch.py', 'launch/multi_antenna.launch.py',
                 'urdf/umbrella.urdf', 'rviz/umbrella.rviz'):
        assert (tmp_path / 'install/umbrella_sim/share/umbrella_sim' / name).exists()
    for exe in ('umbrella_node', 'umbrella_sim', 'umbrella_replay', 'umbrella_compare',
                'umbrella-sim', 'umbrella-replay', 'umbrella-compare'):
        assert (tmp_path / 'install/umbrella_sim/lib/umbrella_sim' / exe).exists(), exe
    # its --help points at the installed interface docs
    node = tmp_path / 'install/umbrella_sim/lib/umbrella_sim/umbrella_node'
    help_run = subprocess.run(['bash', '-c', f'source {tmp_path}/install/setup.bash; '
                               f'exec {node} --help'], env=env, capture_output=True,
                              text=True, timeout=120)
    assert (f'details: {tmp_path}/install/umbrella_sim/share/umbrella_sim/msg_docs/'
            in help_run.stdout), help_run.stdout[-300:] + help_run.stderr
    (bag,) = workdir.iterdir()                       # recorded by default, never elsewhere
    assert bag.name.startswith('umbrella_') and (bag / 'metadata.yaml').exists()
