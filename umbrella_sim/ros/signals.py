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
SIGINT and SIGTERM as a stop request, from the first instant of a process.

The node's imports (rclpy, numpy, scipy, the model) and ``rclpy.init`` take about a second
(more on a loaded machine).  Python's default SIGINT handler raises KeyboardInterrupt wherever
the interpreter happens to be, so a Ctrl-C during that second used to end in a traceback from
some import.  The node's entry points (the ``umbrella_node`` console script and ``python -m
umbrella_sim.node``) therefore install these handlers *before* importing anything heavy: a
signal is only noted here, and ``node.main`` looks at it between its start-up phases and stops
cleanly (exit code 0, nothing started or left behind), or asks a running node to stop.
``deploy_controller`` does the same (``controller_main``): it spins until a stop is noted.

This module imports nothing but the standard library, so that installing the handlers is the
first thing a process does (a signal in the ~50 ms the interpreter itself needs to start is
Python's default behaviour).
"""
import contextlib
import functools
import os
import signal
import sys
import threading
import time

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)

#: the stop signals received so far, in order
received: list[int] = []
_listeners: list = []


def _on_signal(signum, frame) -> None:
    received.append(signum)
    for listener in list(_listeners):
        listener(signum)


def install() -> None:
    """Take SIGINT and SIGTERM as stop requests from now on (idempotent)."""
    for signum in STOP_SIGNALS:
        signal.signal(signum, _on_signal)


def ignore_from_now() -> None:
    """
    Ignore SIGINT and SIGTERM from now on: the node's run is over, the process only exits.

    CPython's teardown puts the default handlers back (those it set), and a second stop
    signal then (a second Ctrl-C, a supervisor's SIGTERM after its SIGINT) killed a node
    whose recording was already finalised: exit 130 or 143 for a clean stop.  An ignored
    signal stays ignored through the teardown.  Outside the main thread: nothing to do.
    """
    if threading.current_thread() is threading.main_thread():
        for signum in STOP_SIGNALS:
            signal.signal(signum, signal.SIG_IGN)


#: environment variable naming a process (its pid) whose end is a stop request to a node:
#: the test API (umbrella_sim.testing) sets it to the test process for every node it starts
STOP_WITH_ENV = 'UMBRELLA_STOP_WITH_PID'
#: s between two looks at that process; s a stop may take before the node is killed
WATCH_PERIOD = 0.2
STOP_GRACE = 10.0


def process_alive(pid: int) -> bool:
    """Return whether process pid runs (a zombie, ended but not yet reaped, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:         # another user's: it exists
        return True
    try:
        with open(f'/proc/{pid}/stat', encoding='ascii', errors='replace') as fh:
            return fh.read().rpartition(')')[2].split()[0] != 'Z'
    except (OSError, IndexError):   # no /proc (macOS): kill(pid, 0) said it exists
        return True


def stop_with(pid: int | str | None) -> threading.Thread | None:
    """
    Take the end of process pid as a stop request (SIGTERM to this process), from now on.

    A test runner killed by a CI timeout or ``timeout`` (SIGTERM, SIGKILL) runs no cleanup,
    and a node it started in a session of its own (testing.NodeProcess) ran on for ever,
    reparented to init.  A daemon thread looks every WATCH_PERIOD s; once pid has gone it
    sends this process SIGTERM (the node stops and finalises its recording as on any
    SIGTERM) and, if the process still runs STOP_GRACE s later, SIGKILL.  None or '' (the
    variable unset): nothing to watch.
    """
    if pid in (None, ''):
        return None
    try:
        pid = int(pid)
    except ValueError:
        raise ValueError(f'{STOP_WITH_ENV}={pid!r}: must be a process id (an integer)') \
            from None

    def watch():
        while process_alive(pid):
            time.sleep(WATCH_PERIOD)
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(STOP_GRACE)
        os.kill(os.getpid(), signal.SIGKILL)
    thread = threading.Thread(target=watch, name=f'stop-with-{pid}', daemon=True)
    thread.start()
    return thread


def add_listener(listener) -> None:
    """Call listener(signum) on every later stop signal (from the main thread)."""
    _listeners.append(listener)


def remove_listener(listener) -> None:
    if listener in _listeners:
        _listeners.remove(listener)


def name(signum: int) -> str:
    return signal.Signals(signum).name


#: exit status of a command-line tool stopped by SIGINT or SIGTERM (the shell's 128 + SIGINT)
EXIT_INTERRUPTED = 130
#: exit status of a tool whose standard output was closed by its reader (``... | head``):
#: 128 + SIGPIPE, as a shell reports a program the signal ended
EXIT_READER_GONE = 141


def stdout_reader_gone() -> None:
    """
    Send the rest of standard output nowhere: its reader closed the pipe.

    Called on BrokenPipeError, so that nothing more (nor the interpreter's flush at exit)
    fails on it; the tool goes on with what is not printing (files it writes).
    """
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)


def print_for_reader(write) -> bool:
    """
    Run write() (it prints to standard output) and flush; False if the reader went away.

    Then standard output goes nowhere (stdout_reader_gone) and the tool goes on with what
    is not printing: ``umbrella_sim simulate | head`` still writes its files.
    """
    try:
        write()
        sys.stdout.flush()
        return True
    except BrokenPipeError:
        stdout_reader_gone()
        return False


@contextlib.contextmanager
def deferred():
    """
    Hold SIGINT and SIGTERM until the block has finished, then act on them as before.

    For a short write that must be whole (a table of results already computed): a stop
    signal during it is noted, the block completes, and the handler in place before it then
    runs (raising KeyboardInterrupt, say).  Outside the main thread, where handlers cannot be
    set, the block just runs.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    previous = {s: signal.signal(s, lambda signum, frame: held.append(signum))
                for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if held:
            handler = previous[held[0]]
            if callable(handler):
                handler(held[0], None)
            elif handler == signal.SIG_DFL:
                os.kill(os.getpid(), held[0])


def interrupt_on_stop_signals() -> None:
    """Make SIGINT and SIGTERM raise KeyboardInterrupt (an offline tool's, from its start)."""
    for signum in STOP_SIGNALS:
        signal.signal(signum, _interrupt)


def _interrupt(signum, frame):
    received.append(signum)     # (a C extension may turn the exception into its own error)
    raise KeyboardInterrupt(name(signum))


#: len(received) when the running tool's main began (interruptible)
_received_at_start = [0]


@contextlib.contextmanager
def waking(wake):
    """
    Within the block, a stop signal calls wake(signum) instead of raising KeyboardInterrupt.

    For a wait inside a library that must not be interrupted at an arbitrary instant: the
    block waits on something wake feeds (a queue.SimpleQueue's put, which may be called from
    a signal handler) and raises KeyboardInterrupt itself, where that is safe.  distributed
    is such a library: a KeyboardInterrupt inside its ``sync`` can reach its event loop before
    the awaited future exists, and its loop logged a NameError traceback after our own
    'interrupted' line.  Outside the main thread, where handlers cannot be set, the block
    just runs.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, lambda signum, frame: wake(signum)) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def raise_if_stopped() -> None:
    """
    Raise KeyboardInterrupt if a stop signal came since the tool's main began.

    For an error that a stop signal may have caused: the signal's KeyboardInterrupt,
    raised inside a C extension (rclpy's message conversion), comes back as that
    extension's own error, which would read as a bad input.
    """
    if len(received) > _received_at_start[0]:
        raise KeyboardInterrupt(name(received[-1]))


def interruptible(tool: str, kept: str):
    """
    Make a tool's main end on SIGINT/SIGTERM with one line and exit 130, not a traceback.

    SIGTERM raises KeyboardInterrupt like SIGINT, so the same ``finally`` blocks run (an
    offline recording is finalised); kept says what the user still has.  SIGINT is taken
    even when the tool was started with it ignored (a background job of a script), as the
    nodes take it.  A standard output closed by its reader ends it with EXIT_READER_GONE,
    not a traceback.
    """
    def wrap(main):
        @functools.wraps(main)
        def run(argv=None):
            in_main = threading.current_thread() is threading.main_thread()
            previous = ({s: signal.signal(s, _interrupt) for s in STOP_SIGNALS} if in_main
                        else {})
            _received_at_start[0] = len(received)
            try:
                return main(argv)
            except KeyboardInterrupt as exc:
                how = str(exc) or 'SIGINT'
                print(f'{tool}: interrupted by {how}; {kept}', file=sys.stderr)
                return EXIT_INTERRUPTED
            except BrokenPipeError:
                stdout_reader_gone()
                return EXIT_READER_GONE
            finally:
                for signum, handler in previous.items():
                    signal.signal(signum, handler)
        return run
    return wrap
