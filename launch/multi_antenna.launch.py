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
Launch several antennas in one ROS graph, each in its own namespace.

    ros2 launch umbrella_sim multi_antenna.launch.py namespaces:=a1,a2,a3 v0:=0.0

Every antenna gets umbrella_node (topics /<ns>/..., its own /<ns>/clock, a bag
umbrella_<ns>_<date>-<time> in the working directory, or <record_path>_<ns>) and a
robot_state_publisher with frame_prefix '<ns>/', so one TF tree holds a1/umbrella_base,
a2/umbrella_base, ...
Diagnostics of all of them arrive on /diagnostics, named '<ns>/umbrella_node: physics'.
Nothing publishes /clock: each antenna's robot_state_publisher follows its /<ns>/clock; for
another use_sim_time node remap one antenna's clock (msg_docs/topic_clock.md).
The other arguments are those of umbrella.launch.py and apply to every antenna.
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction

from umbrella_sim.ros import launch_description as umbrella


def _setup(context, *args, **kwargs):
    values = umbrella.launch_values(context)
    actions = []
    for ns in umbrella.split_namespaces(context.launch_configurations.get('namespaces',
                                                                          'a1,a2')):
        actions += umbrella.to_launch_actions(umbrella.plan(umbrella.antenna_values(values,
                                                                                    ns)))
    return actions


def generate_launch_description():
    return LaunchDescription(
        [DeclareLaunchArgument('namespaces', default_value='a1,a2',
                               description="antennas' namespaces, comma-separated")]
        + [DeclareLaunchArgument(a.name, default_value=a.default, description=a.description)
           for a in umbrella.arguments() if a.name != 'namespace']
        + [OpaqueFunction(function=_setup)])
