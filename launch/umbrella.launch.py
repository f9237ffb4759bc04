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
Launch one umbrella antenna: umbrella_node, robot_state_publisher with the URDF, RViz.

    ros2 launch umbrella_sim umbrella.launch.py namespace:=a1 v0:=-0.5 record:=false
    ros2 launch umbrella_sim umbrella.launch.py --show-args

A thin wrapper: what is started is decided by umbrella_sim.ros.launch_description (tested
without ROS 2's launch, which is not on PyPI).
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction

from umbrella_sim.ros import launch_description as umbrella


def _setup(context, *args, **kwargs):
    return umbrella.to_launch_actions(umbrella.plan(umbrella.launch_values(context)))


def generate_launch_description():
    return LaunchDescription(
        [DeclareLaunchArgument(a.name, default_value=a.default, description=a.description)
         for a in umbrella.arguments()]
        + [OpaqueFunction(function=_setup)])
