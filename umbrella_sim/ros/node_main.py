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
umbrella_node's process: arguments, start-up, the executor, the exit code.

SIGINT/SIGTERM only ask for a stop (ros/signals.py: the entry point installs the handlers
before the heavy imports, so a signal during them is noted too, never a KeyboardInterrupt
traceback); rclpy's own handlers would shut the context down at once, under the physics
thread's feet.  Ours stop the physics first, then the recording is closed, then rclpy.  A
stop during start-up: exit 0, nothing started or left behind.
"""
from __future__ import annotations

import os
import sys

import rclpy
from rclpy.executors import ExternalShutdownException

from . import messages as ros_io, signals as stop_signals
from .dds_profile import use_node_profile
from .executor import CallbackPool
from .node import EXIT_FAULT, EXIT_OK, EXIT_RECORDING, EXIT_USAGE, StartupError, UmbrellaNode
from .params_file import init_ros, param_rules_in
from .ribs_messages import BUS_TOPIC, RIB_TOPICS
from .share import package_path
from ..core.registry import NODE_PARAMETERS, parameter_help, SPECS
from ..core.umbrella3d.params3d import umbrella_parameter_help

#: the main thread's executor wait (s): a stop signal is seen when it returns.  Each wait
#: rebuilds rclpy's wait set of the node's entities (~0.5 ms of CPU with its services and
#: publishers' event handlers): 0.1 s costs 0.006 core where 0.02 s cost 0.026, and a stop
#: is still seen within 0.1 s
SPIN_TIMEOUT_S = 0.1


def usage() -> str:
    lines = ['usage: umbrella_node [--help] [--ros-args -p name:=value ... --params-file FILE',
             '                      -r __ns:=/NAMESPACE]', '',
             'Real-time flexible umbrella-frame deployment simulator (ROS 2 node).', '',
             'model parameters (a runtime set applies on ~/reset):']
    lines += parameter_help(SPECS.values())
    lines.append('node parameters:')
    lines += parameter_help(NODE_PARAMETERS.values())
    lines += umbrella_parameter_help()
    lines += ['', 'topics: ' + ', '.join(t.name for t in ros_io.TOPICS.values())
              + ' (with ribs >= 2: ' + ', '.join(RIB_TOPICS) + ' too; with a moving base: '
              + BUS_TOPIC.name + ')'
              + f'; subscribes {ros_io.COMMAND.name} (std_msgs/Float64, N >= '
              'sleeve_force_min, 0 by default)',
              'services: ~/reset (std_srvs/Trigger), ~/pause (std_srvs/SetBool)',
              'exit: SIGINT/SIGTERM stop the physics, then finalise the recording (during '
              f'start-up: nothing is started); code {EXIT_OK} on a clean stop or when duration '
              f'is reached, {EXIT_USAGE} for '
              'invalid arguments, parameters or params files, '
              f'{EXIT_FAULT} if the simulation ended in a fault, {EXIT_RECORDING} if the '
              'recording stopped on a write error (the run itself went on)',
              f'details: {msg_docs_location()}']
    return '\n'.join(lines)


def msg_docs_location() -> str:
    """Return where the interface docs are here: the source tree's, or the installed ones."""
    found = package_path('msg_docs', 'README.md')
    if found:
        return os.path.dirname(found) + os.sep
    return 'msg_docs/ of the umbrella_sim sources (the package share directory of a colcon ' \
           'install)'


def main(argv: list[str] | None = None) -> int:
    # SIGINT/SIGTERM only ask for a stop (stop_signals.py: the entry points install the
    # handlers before the heavy imports, so a signal during them is noted too, never a
    # KeyboardInterrupt traceback); rclpy's own handlers would shut the context down at once,
    # under the physics thread's feet; ours stop the physics first, then the recording is
    # closed, then rclpy.  A stop during start-up: exit 0, nothing started or left behind.
    stop_signals.install()
    running: list[UmbrellaNode] = []        # the node, once built: a signal asks it to stop

    def on_signal(signum):
        for node in running:
            node.request_stop()

    stop_signals.add_listener(on_signal)
    try:
        return _run(list(sys.argv if argv is None else argv), running)
    finally:
        stop_signals.remove_listener(on_signal)


def _stopped_during_start_up() -> int:
    """Exit quietly after a stop signal that came before the node was running."""
    print(f'umbrella_node: stopped by {stop_signals.name(stop_signals.received[0])} during '
          'start-up; nothing was started', file=sys.stderr)
    rclpy.try_shutdown()
    return EXIT_OK


def _run(argv: list[str], running: list) -> int:
    stop_requested = stop_signals.received      # every stop signal since the process began
    if stop_requested:          # during the imports: before any ROS or simulation work
        return _stopped_during_start_up()
    if any(a in ('-h', '--help') for a in argv[1:argv.index('--ros-args')
                                               if '--ros-args' in argv else len(argv)]):
        stop_signals.print_for_reader(lambda: print(usage()))   # | head: no traceback
        return EXIT_OK

    def fail(text: str) -> int:
        print(f'umbrella_node: error: {text}', file=sys.stderr)
        rclpy.try_shutdown()
        return EXIT_USAGE

    profile = use_node_profile()    # (before rclpy.init: Fast DDS reads it then)
    try:
        files = init_ros(argv)
    except ValueError as exc:
        return fail(str(exc))
    if stop_requested:
        return _stopped_during_start_up()
    leftover = rclpy.utilities.remove_ros_args(argv)[1:]
    if leftover:
        return fail(f'unexpected arguments {leftover}; parameters go after --ros-args as '
                    '-p name:=value or --params-file FILE')
    try:
        node = UmbrellaNode(params_files=tuple(files), param_rules=param_rules_in(argv))
    except StartupError as exc:
        return fail(str(exc))
    running.append(node)
    if profile:
        node.get_logger().info(
            f"Fast DDS profile {profile}: the node's own, none being given (its writers' NACK "
            'suppression 5 ms; FASTRTPS_DEFAULT_PROFILES_FILE takes yours instead: '
            'msg_docs/README.md, DDS profile)')
    if stop_requested:          # a signal while the model was built: before any output
        node.destroy_node()
        return _stopped_during_start_up()
    try:
        node.start()
    except StartupError as exc:
        node.destroy_node()
        return fail(str(exc))
    executor = CallbackPool(num_threads=2)      # (rclpy's MultiThreadedExecutor: executor.py)
    executor.add_node(node)
    # the commands' subscription in a wait set of its own, on a thread of its own: in
    # lockstep each command wakes it alone, not the services and events (executor.py)
    executor.dedicate(node.command_sub.callback_group)
    ok = True
    try:
        # the timeout lets a signal's Python handler run while the executor waits (it runs
        # only when the wait returns: the timeout bounds how late a stop is seen)
        while not node.finished.done() and not stop_requested:
            executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
        node.stop()
        ok = bool(node.finished.result()) if node.finished.done() else node.fault is None
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.stop()
        executor.shutdown(timeout_sec=1.0)      # (its threads too: none takes a command now)
        node.drain_commands()       # those still queued: taken or counted, never lost
        node.close_recording()
        node.destroy_node()
        rclpy.try_shutdown()
    if not ok:
        return EXIT_FAULT
    return EXIT_RECORDING if node.recording_error else EXIT_OK
