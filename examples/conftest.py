# The fixtures of the public test API: ros_domain_id (UMBRELLA_TEST_DOMAIN_ID, else one per
# session), probe, and antenna_factory (starts umbrella_node, stops it after the test).
from pathlib import Path

import pytest

from umbrella_sim.testing import antenna_factory, probe, ros_domain_id  # noqa: F401

HERE = Path(__file__).resolve().parent
# The suite's markers (setup.cfg): every example here talks to a real umbrella_node over DDS
# (ros); this one takes more than ~3 s on a quiet machine (slow).  `pytest -m "not ros"` leaves
# them out.
SLOW = {"test_the_deploy_controller_latches_softly"}


def pytest_collection_modifyitems(config, items):
    for item in items:
        if Path(item.path).resolve().parent == HERE:
            item.add_marker(pytest.mark.ros)
            if item.originalname in SLOW:
                item.add_marker(pytest.mark.slow)
