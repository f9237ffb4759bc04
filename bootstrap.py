#!/usr/bin/env python3

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
Set up a local virtualenv (.venv) with every dependency, then run the main job or the tests.

    python3 bootstrap.py run      # umbrella_node on config/umbrella.yaml, recording MCAP to
                                  # runs/umbrella_YYYY_MM_DD-HH_MM_SS/, the node's own name
                                  # (Ctrl-C stops and finalises it)
    python3 bootstrap.py test     # the test suite and examples/
    python3 bootstrap.py setup    # the venv alone

Arguments after run go to the node, which runs in the runs directory; a relative path they
give (--params-file FILE, -p record_path:=DIR; a leading ~ the home directory) is the
working directory's, as a user means it (a record_path written inside a params file is the
node's own: relative, it is under the runs directory):
python3 bootstrap.py run -p v0:=-0.5 --params-file my.yaml
Arguments after test go to pytest; test files or directories among them (tests/test_modes.py,
tests/test_node.py::test_x, the working directory's) are what it runs, else tests/ and examples/:
python3 bootstrap.py test tests/test_modes.py -q
ROS_AUTOMATIC_DISCOVERY_RANGE is LOCALHOST unless the environment sets it (a node on another
host sees nothing then: export ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET for that).
Environment: UMBRELLA_VENV (default ./.venv), UMBRELLA_RUNS_DIR (default ./runs).

Needs only python3 (3.11); everything else comes from PyPI.  Idempotent: a venv whose
requirements are unchanged is reused.
"""
import glob
import hashlib
import os
import signal
import subprocess
import sys

ROOT = os.path.dirname(os.path.abspath(__file__))
# (relative to the working directory the command was given in, as a user means them)
VENV = os.path.abspath(os.environ.get('UMBRELLA_VENV', os.path.join(ROOT, '.venv')))
PY = os.path.join(VENV, 'bin', 'python')
STAMP_NAME = '.umbrella_sim-installed'    # in the venv: digest of what it was installed from


def run(cmd, **kw):
    print('+', ' '.join(cmd), flush=True)
    subprocess.run(cmd, check=True, **kw)


def setup() -> None:
    req = os.path.join(ROOT, 'requirements.txt')
    # what the install depends on: a change to any of these reinstalls (and rebuilds the kernel)
    inputs = [req, os.path.join(ROOT, 'setup.py'),
              *sorted(glob.glob(os.path.join(ROOT, 'umbrella_sim', 'core', '_kernel*.[ch]')))]
    digest = hashlib.sha256()
    for path in inputs:
        with open(path, 'rb') as fh:
            digest.update(fh.read())
    digest = digest.hexdigest()
    stamp = os.path.join(VENV, STAMP_NAME)
    if os.path.exists(stamp) and open(stamp).read() == digest and os.path.exists(PY):
        return
    if not os.path.exists(PY):
        run([sys.executable, '-m', 'venv', VENV])
    run([PY, '-m', 'pip', 'install', '--disable-pip-version-check', '-q', '--upgrade', 'pip'])
    run([PY, '-m', 'pip', 'install', '--disable-pip-version-check', '-q', '-r', req])
    run([PY, '-m', 'pip', 'install', '--disable-pip-version-check', '-q', '--no-deps', '-e', ROOT])
    with open(stamp, 'w') as fh:
        fh.write(digest)


def main(argv) -> int:
    if len(argv) < 1 or argv[0] not in ('run', 'test', 'setup'):
        print(__doc__, file=sys.stderr)
        said = f'unknown command {argv[0]!r}' if argv else 'no command'
        print(f'bootstrap.py: {said}: give run, test or setup', file=sys.stderr)
        return 2
    setup()
    env = dict(os.environ, AMENT_PREFIX_PATH=VENV)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    if argv[0] == 'run':
        runs = os.path.abspath(os.environ.get('UMBRELLA_RUNS_DIR', os.path.join(ROOT, 'runs')))
        os.makedirs(runs, exist_ok=True)
        # the node records into its working directory under its one naming rule
        # (umbrella[_ns]_YYYY_MM_DD-HH_MM_SS, rosbag2's; never overwriting), so: there
        cwd = runs
        cmd = [PY, '-m', 'umbrella_sim.node', '--ros-args', '--params-file',
               os.path.join(ROOT, 'config', 'umbrella.yaml')] + node_paths(argv[1:])
    elif argv[0] == 'test':
        # the test suite and the user-facing actuation examples (they must keep working)
        cwd = ROOT
        paths = [os.path.join(ROOT, 'tests'), os.path.join(ROOT, 'examples')]
        if argv[1:]:
            args, given = given_test_paths(argv[1:])
            return run_tests([[PY, '-m', 'pytest', '-q'] + ([] if given else paths) + args],
                             cwd, env)
        print('the whole suite: ~9 min on a quiet 2-core machine, in two parts: what starts no '
              'ROS node, then what talks over DDS, each on two processes (pytest-xdist, each '
              'file on one; each process its own ROS domain); the fast subset (no ROS node, '
              'nothing slow): python3 bootstrap.py test -m "not ros and not slow" -n 2',
              flush=True)
        return run_tests([[PY, '-m', 'pytest', '-q'] + paths + list(OFFLINE_PART),
                          [PY, '-m', 'pytest', '-q'] + paths + list(ROS_PART)], cwd, env)
    else:
        return 0
    return run_child(cmd, cwd, env)


def node_paths(args):
    """
    Return the node's arguments with their relative paths made the working directory's.

    A leading ~ is the home directory first, as the node takes it (a shell leaves the ~ of
    record_path:=~/bags as it is): the node, run elsewhere, would otherwise get a path under
    a directory named '~' of this one.
    """
    def callers(path):
        path = os.path.expanduser(path)
        return path if os.path.isabs(path) else os.path.abspath(path)

    out = list(args)
    for i, arg in enumerate(out):
        if i > 0 and out[i - 1] == '--params-file':
            out[i] = callers(arg)
        name, sep, value = arg.partition(':=')
        if sep and name == 'record_path' and value:
            out[i] = f'{name}:={callers(value)}'
    return out


#: pytest's options whose value is the next argument and may name an existing file or
#: directory that is not a test to run
PYTEST_PATH_VALUED = ('--ignore', '--ignore-glob', '--deselect', '--basetemp', '--rootdir',
                      '-c', '--confcutdir', '--junitxml', '--junit-xml', '--log-file',
                      '--result-log', '-p', '-k', '-m', '-o', '--override-ini')


def given_test_paths(args):
    """
    Return pytest's arguments with the test paths among them made absolute, and whether any.

    A test path is an argument that names an existing .py file or a directory, as given from
    the working directory (with a ::node id after a file), and is not the value of an option:
    pytest runs in the repository, and with one it runs that and not the whole suite.
    """
    out, given = list(args), False
    for i, arg in enumerate(out):
        if arg.startswith('-') or (i > 0 and out[i - 1] in PYTEST_PATH_VALUED):
            continue
        path, sep, node = arg.partition('::')
        path = os.path.expanduser(path)
        if (path.endswith('.py') and os.path.isfile(path)) or (not sep and os.path.isdir(path)):
            out[i] = os.path.abspath(path) + sep + node
            given = True
    return out, given


#: the suite in two parts: the tests that start no ROS node (CPU-bound physics, formats, tools)
#: on two worker processes, each test file on one (its module fixtures made once), and then
#: the ones that talk over DDS, apart from them (a node beside a busy physics test is a loaded
#: machine; their waits are on conditions), on two worker processes too, each in a ROS domain
#: of its own (umbrella_sim.testing.default_domain_id): their time is mostly a node's start-up
#: and its run in real time (one at a time: 5:18 of the suite's 11 min, at ~1 core)
OFFLINE_PART = ('-m', 'not ros', '-n', '2', '--dist', 'loadfile')
ROS_PART = ('-m', 'ros', '-n', '2', '--dist', 'loadfile')


#: the stop signals forwarded to a child so far
STOPPED = []


def run_tests(commands, cwd, env) -> int:
    """Run each pytest command (all of them, whatever the earlier ones gave); 0 if all pass."""
    codes = []
    for cmd in commands:
        code = run_child(cmd, cwd, env)
        if STOPPED:                     # a stop signal was forwarded: not the next part
            return code
        codes.append(code)
    return next((c for c in codes if c != 0), 0)


def run_child(cmd, cwd, env) -> int:
    """Run cmd in its own session, forwarding our stop signals to it; its exit status."""
    print('+', ' '.join(cmd), flush=True)
    # the child has its own session, so a signal reaches it exactly once, from here, whether it
    # came from the terminal (Ctrl-C) or was sent to this process (kill, timeout, a supervisor);
    # the child stops and finalises its recording while this process waits for it
    child = subprocess.Popen(cmd, cwd=cwd, env=env, start_new_session=True)

    def forward(signum, frame):
        STOPPED.append(signum)
        if child.poll() is None:
            child.send_signal(signum)

    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, forward)
    return child.wait()


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
