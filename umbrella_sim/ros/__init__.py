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
The ROS 2 face: the node, its messages and parameters, the deploy controller, launch.

    node, node_main    umbrella_node (a thin adapter around core.driver.RunDriver) and its process
    pacing, lockstep   real-time pacing; the co-simulation handshake
    commands           the sleeve_force intake: checked, counted, recorded, held
    messages, publication
                       topics, QoS, Sample -> messages; a publication's CDR bytes
    recording          a run's channels and records on a bag (the node and record_offline)
    parameters, params_file
                       typed, ranged descriptors from the registry, why a runtime set is
                       refused; ROS params files
    deploy_controller  the closed-loop controller node (the law: core.control)
    launch_description, robot_description
                       what the launch files start; the URDF
    signals, share     stop signals as requests; where the package's data files are

Importing this package imports nothing: the entry points install the signal handlers
before any heavy import.
"""
