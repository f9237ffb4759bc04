"""
Test-suite names for the public test API (umbrella_sim.testing): one helper, not two.

Importing this module also puts the session's domain and localhost discovery into this
process's environment, so in-process rclpy and subprocess calls with env=ros_env() agree.
"""
import os

from umbrella_sim.testing import (DOMAIN_ID, NodeProcess, poll, Probe,  # noqa: F401
                                  ros_env, SimulatedAntenna, summary_from_recording)

os.environ.update({k: v for k, v in ros_env().items()
                   if k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE",
                            "RMW_IMPLEMENTATION")})


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
