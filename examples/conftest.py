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

# The fixtures of the public test API: ros_domain_id (UMBRELLA_TEST_DOMAIN_ID, else one per
# session), probe, and antenna_factory (starts umbrella_node, stops it after the test).
from pathlib import Path

import pytest

from umbrella_sim.testing import antenna_factory, probe, ros_domain_id  # noqa: F401

HERE = Path(__file__).resolve().parent
# The suite's markers (setup.cfg): every example here talks to a real umbrella_node over DDS
# (ros); this one takes more than ~3 s on a quiet machine (slow).  `pytest -m "not ros"` leaves
# them out; the umbrella of N ribs waits for its lock at real time (0.67 s simulated).
SLOW = {'test_the_deploy_controller_latches_softly',
        'test_a_sticking_hinge_holds_its_rib_then_the_umbrella_deploys'}


def pytest_collection_modifyitems(config, items):
    for item in items:
        if Path(item.path).resolve().parent == HERE:
            item.add_marker(pytest.mark.ros)
            if item.originalname in SLOW:
                item.add_marker(pytest.mark.slow)
