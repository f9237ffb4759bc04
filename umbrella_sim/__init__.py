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
umbrella_sim: real-time flexible multibody simulation of an umbrella-frame antenna.

Layers, each importing only those below it (tests/test_architecture.py):

    tools    the command lines                                   umbrella_sim.tools
    ros      the node, messages, controller, launch              umbrella_sim.ros
    bag      the MCAP / rosbag2 recording format                 umbrella_sim.bag
    core     the physics, usable from a plain Python script      umbrella_sim.core

and on top the actuation-test API, umbrella_sim.testing.
"""
import os as _os

# The physics works on small dense matrices (tens to ~150 rows): BLAS threads only contend.
# Measured on the shared 2-core machine: one nonlinear step at N = 16 took 0.76 s with
# OpenBLAS's default threads and 0.03 s with one.  Set before numpy is first imported (any
# entry point that imports umbrella_sim first); an explicit setting by the user wins.
for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    _os.environ.setdefault(_var, '1')

__version__ = '0.1.0'
