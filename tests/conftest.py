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

"""Session-wide checks shared by every test module."""
import os
import re
import signal

import pytest

# Tests import numpy before umbrella_sim: the package's one-BLAS-thread default
# (umbrella_sim/__init__.py) must be in place before numpy loads.
import umbrella_sim  # noqa: F401, I100

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# The tests that stop a tool with SIGINT model Ctrl-C in a terminal.  A runner started with
# SIGINT ignored (a background job of a non-interactive shell) passes that on to every child,
# and Python keeps an inherited SIG_IGN, so the tool would never see the signal: give the
# children the terminal's default disposition.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
# a bag the node names itself: umbrella[_ns]_YYYY_MM_DD-HH_MM_SS[_k]
_BAG = re.compile(r'^umbrella_(\w+_)?\d{4}_\d\d_\d\d-\d\d_\d\d_\d\d(_\d+)?$')


def _bags() -> set:
    return {n for n in os.listdir(ROOT) if _BAG.match(n)}


@pytest.fixture(scope='session', autouse=True)
def no_recordings_left_in_the_repository():
    """Nodes record by default into their working directory: tests must use temporary ones."""
    before = _bags()
    yield
    left = sorted(_bags() - before)
    assert not left, f'tests left recordings in {ROOT}: {left}'


# the public test API's fixtures (ros_domain_id, probe, antenna_factory) for our own tests
from umbrella_sim.testing import antenna_factory, probe, ros_domain_id  # noqa: E402, F401, I100
