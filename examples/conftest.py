# The fixtures of the public test API: ros_domain_id (UMBRELLA_TEST_DOMAIN_ID, else one per
# session), probe, and antenna_factory (starts umbrella_node, stops it after the test).
from umbrella_sim.testing import antenna_factory, probe, ros_domain_id  # noqa: F401
