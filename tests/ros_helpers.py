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
Test-suite names for the public test API (umbrella_sim.testing): one helper, not two.

Importing this module also puts the session's domain and localhost discovery into this
process's environment, so in-process rclpy and subprocess calls with env=ros_env() agree.
"""
import os

from umbrella_sim.testing import (DOMAIN_ID, NodeProcess, poll, Probe,  # noqa: F401
                                  ros_env, SimulatedAntenna, summary_from_recording)

os.environ.update({k: v for k, v in ros_env().items()
                   if k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE',
                            'RMW_IMPLEMENTATION')})


def signal_and_collect(proc, signum, ready=None, timeout: float = 90.0) -> tuple[str, str]:
    """
    Send signum to a running tool (once ready() returns), return its (stdout, stderr).

    The process is killed if it outlives timeout after the signal.
    """
    try:
        if ready is not None:
            ready()
        proc.send_signal(signum)
        return proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def stamp(msg) -> float:
    """Return a message's header stamp in seconds."""
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def keep_every_message(probe, namespace: str = '',
                       keys=('joint_states', 'tip_deflection', 'peak_stress')):
    """
    Subscribe probe to a node's per-publication topics keeping every message; return it.

    A reader history as deep as a run (reliable, keep last 100 000) instead of the topics' 10:
    the probe's thread takes one message per executor turn, and a test process that got no
    CPU for ten publications on a loaded machine (50 ms at 200 Hz) lost messages out of a
    depth-10 history.  Call it before handing the probe to an antenna (``probe=``): the
    antenna keeps a subscription the probe already has.
    """
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    from umbrella_sim.ros import messages as ros_io

    every = QoSProfile(depth=100_000, reliability=ReliabilityPolicy.RELIABLE,
                       history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.VOLATILE)
    prefix = f"/{namespace.strip('/')}/" if namespace.strip('/') else '/'
    for key in keys:
        topic = ros_io.TOPICS[key]
        probe.subscribe(prefix + topic.name, topic.type, every)
    return probe


def wait_for_stamp_in_last_run(probe, topic: str, t: float, timeout: float = 30.0):
    """
    Return the first message on topic stamped past t since sim time last went back.

    A ~/reset restarts sim time at 0: messages of the run before it (stamped past t too)
    do not count.  The probe must have received the old run's last message and the new
    run's first one (a topic it subscribed to before the reset).
    """
    def found():
        msgs = probe.messages(topic)
        stamps = [stamp(m) for m in msgs]
        start = max((i for i in range(1, len(stamps)) if stamps[i] < stamps[i - 1]),
                    default=0)
        return next((m for m, s in zip(msgs[start:], stamps[start:]) if s > t), None)

    def seen() -> str:
        msgs = probe.messages(topic)
        return f'latest stamp {stamp(msgs[-1]):.6f} s' if msgs else 'no message'
    return poll(found, timeout, lambda: f'no message on {topic} stamped past {t:.6f} s in the '
                                        f'run since the last reset within {timeout} s '
                                        f'({seen()})')


def cpu_seconds(pid: int) -> float:
    """Return the CPU time (user + system, s) a live process has used so far (proc(5))."""
    with open(f'/proc/{pid}/stat') as fh:
        fields = fh.read().rsplit(')', 1)[1].split()      # from field 3, the state, on
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def main_thread_sleeps(pid: int) -> int:
    """
    Return how often a process's main thread has given up the CPU of its own accord.

    Its voluntary context switches (proc(5)): each sleep or blocking wait counts one.
    """
    with open(f'/proc/{pid}/task/{pid}/status') as fh:
        return next(int(line.split()[1]) for line in fh
                    if line.startswith('voluntary_ctxt_switches:'))


def parameter_value(kind: int, v):
    """Return a rcl_interfaces ParameterValue of that ParameterType holding v."""
    from rcl_interfaces.msg import ParameterType, ParameterValue
    field = {ParameterType.PARAMETER_DOUBLE: 'double_value',
             ParameterType.PARAMETER_INTEGER: 'integer_value',
             ParameterType.PARAMETER_STRING: 'string_value',
             ParameterType.PARAMETER_BOOL: 'bool_value'}.get(kind)
    return ParameterValue(type=kind, **({field: v} if field else {}))


def parameter_calls(probe, node: str):
    """
    Return set_param(name, kind, value) -> SetParametersResult and get(name) -> ParameterValue.

    Each a call of the node's own parameter service (as ``ros2 param set/get`` makes).
    """
    from rcl_interfaces.msg import Parameter
    from rcl_interfaces.srv import GetParameters, SetParameters

    def set_param(name, kind, v):
        req = SetParameters.Request(parameters=[Parameter(name=name,
                                                          value=parameter_value(kind, v))])
        return probe.call(SetParameters, f'{node}/set_parameters', req).results[0]

    def get(name):
        req = GetParameters.Request(names=[name])
        return probe.call(GetParameters, f'{node}/get_parameters', req).values[0]
    return set_param, get
