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
The console scripts: each takes SIGINT/SIGTERM before its heavy imports, then runs its tool.

The imports of a tool (numpy, scipy, rclpy and its messages, the model) take about a second
on a loaded machine.  Python's default SIGINT handler raises KeyboardInterrupt wherever the
interpreter happens to be, so a Ctrl-C then ended in a traceback from some import, and a tool
started with SIGINT ignored (a script's background job) lost it.  Every entry point therefore
installs the handlers of ``ros.signals`` first (that module imports only the standard
library): the nodes note a signal and stop cleanly at their next start-up phase; the offline
tools end with one line and exit 130.
"""
import importlib
import os
import sys
import threading

from ..ros import signals

#: what the package needs from PyPI (bootstrap.py installs it into .venv)
#: the ROS 2 Python packages the tools and the test API import (PyPI: the 'ros' extra)
ROS_DEPENDENCIES = frozenset({'rclpy', 'std_msgs', 'std_srvs', 'sensor_msgs', 'rosgraph_msgs',
                              'geometry_msgs', 'nav_msgs', 'visualization_msgs',
                              'diagnostic_msgs', 'rcl_interfaces', 'builtin_interfaces'})
DEPENDENCIES = ROS_DEPENDENCIES | {'numpy', 'scipy', 'mcap', 'yaml'}


#: the exit status of a tool whose dependency is missing (a usage error's, as argparse's)
EXIT_MISSING = 2


def _main_of(module: str, tool: str):
    """
    Return the module's main (its heavy imports); None if a dependency is missing, said.

    A python3 outside the venv bootstrap.py made (its tools in .venv/bin) has none of them:
    a bare ModuleNotFoundError told a newcomer nothing.  A module not among DEPENDENCIES
    (our own code broken) raises as it is.
    """
    try:
        return importlib.import_module(module).main
    except ModuleNotFoundError as exc:
        if (exc.name or '').split('.')[0] not in DEPENDENCIES:
            raise
        print(f'{tool}: error: {missing_dependency(exc.name, tool)}', file=sys.stderr)
        return None


def checkout() -> str | None:
    """Return the source checkout the package runs from (bootstrap.py beside it), else None."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    return root if os.path.exists(os.path.join(root, 'bootstrap.py')) else None


def missing_dependency(module: str, tool: str | None = None) -> str:
    """
    Say which dependency this Python lacks and how to get it (a tool's, or the test API's).

    From a source checkout (bootstrap.py beside the package): the venv bootstrap.py makes,
    where the tool is.  Installed elsewhere (pip install of the package into a user's own
    venv, which brings no ROS 2 package: they are no setup.py requirement, so that a ROS 2
    install's own are used): a ROS 2 module from the 'ros' extra or a sourced ROS 2 install,
    any other by installing the package again.
    """
    where = f'no module {module!r} in this Python ({sys.executable})'
    root = checkout()
    venv = (f'run it from the venv that `python3 bootstrap.py setup` makes ({root}/.venv/bin/'
            f'{tool or "python"}, or after `. .venv/bin/activate`), or ' if root else '')
    if module.split('.')[0] in ROS_DEPENDENCIES:
        return (f'{where}: {venv}install the ROS 2 Jazzy Python packages into this '
                "environment: pip install 'umbrella_sim[ros]' (their PyPI wheels; from a "
                "checkout: pip install '/path/to/umbrella_sim[ros]'), or source a ROS 2 Jazzy "
                'install (source /opt/ros/jazzy/setup.bash) before running it')
    return f'{where}: {venv}install umbrella_sim into this environment with pip, which brings it'


def _node(module: str, tool: str) -> int:
    """
    Run a node: the handlers first, then the heavy imports; ignore stop signals after.

    A process named by STOP_WITH_ENV (the test process that started the node) ending is a
    stop request too (signals.stop_with).
    """
    signals.install()
    try:
        signals.stop_with(os.environ.get(signals.STOP_WITH_ENV))
    except ValueError as exc:
        print(f'{tool}: error: {exc}', file=sys.stderr)
        return EXIT_MISSING
    try:
        main = _main_of(module, tool)
        return EXIT_MISSING if main is None else main()
    finally:        # (stopped and finalised: a second signal must not kill the exit)
        signals.ignore_from_now()


def node_main() -> int:
    """Run umbrella_node: the handlers first, then the heavy imports."""
    return _node('umbrella_sim.ros.node_main', 'umbrella_node')


def controller_main() -> int:
    """Run deploy_controller: the handlers first, then the heavy imports."""
    return _node('umbrella_sim.ros.deploy_controller', 'deploy_controller')


def _offline_tool(module: str, tool: str) -> int:
    """Run an offline tool: SIGINT/SIGTERM end it with one line (exit 130) from the start."""
    if threading.current_thread() is threading.main_thread():
        signals.interrupt_on_stop_signals()
    try:
        main = _main_of(f'umbrella_sim.tools.{module}', tool)
    except KeyboardInterrupt as exc:
        print(f"{tool}: interrupted by {str(exc) or 'SIGINT'} while starting; nothing was "
              'done', file=sys.stderr)
        return signals.EXIT_INTERRUPTED
    return EXIT_MISSING if main is None else main()


def cli_main() -> int:
    """Run ``umbrella_sim`` (simulate, sweep)."""
    return _offline_tool('cli', 'umbrella_sim')


def replay_main() -> int:
    """Run ``umbrella_replay``."""
    return _offline_tool('replay', 'umbrella_replay')


def compare_main() -> int:
    """Run ``umbrella_compare``."""
    return _offline_tool('compare', 'umbrella_compare')
