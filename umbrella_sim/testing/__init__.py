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
Topic-driven actuation tests against a real ``umbrella_node``: the public test API.

Start the simulated antenna in a child process on a private ROS domain, command the sleeve
over ``sleeve_force``, wait for what comes back, and assert on the run's summary::

    from umbrella_sim.testing import SimulatedAntenna

    def test_twenty_newtons_deploy_the_frame(tmp_path):
        with SimulatedAntenna({"v0": 0.0}) as antenna:
            antenna.wait_for_phase("deploying")
            antenna.publish_force(20.0)
            antenna.wait_for_phase("locked", timeout=30)
            summary = antenna.summary(after_lock=0.3)
        assert summary.deploy_time < 0.5

Everything here talks over real DDS, so:

* **Isolation.**  Each process runs with ``ROS_DOMAIN_ID`` = :func:`default_domain_id` (the
  ``UMBRELLA_TEST_DOMAIN_ID`` environment variable, else a domain of 10..99 that no other
  test session on the machine holds; under pytest-xdist's ``-n``, worker k takes the set
  domain plus k, or a free one of its own) and
  ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``; pass ``domain_id=`` to choose another.
  :class:`Probe` (the test's own rclpy node) sets the same two variables in this process.
* **Waiting.**  Every wait polls what has been received, up to a timeout, and fails with an
  ``AssertionError`` that says what was awaited and what was seen: no fixed sleeps.
  Messages on different topics have no mutual order in DDS, and a transient-local sample
  reaches a late reader only after the handshake: wait for what you assert on.
* **Cleanup.**  ``stop()`` (also on leaving a ``with`` block) sends SIGTERM, waits, then
  SIGKILLs the process group; Fast DDS shared-memory segments (``/dev/shm/fastrtps_*``) that
  the process had open and no live process still uses are removed, so even a killed node
  leaves nothing behind.  Its log file is deleted.  A test process killed with no cleanup
  of its own (a CI timeout's SIGTERM or SIGKILL) leaves no node running either: each node
  it started stops by itself within ~0.2 s of its end (``UMBRELLA_STOP_WITH_PID``,
  ros.signals.stop_with; its temporary log file stays).
* **Summaries.**  :meth:`SimulatedAntenna.summary` computes the deploy time, the stage-2 peak
  stress and tip amplitude from the node's topics and log; :func:`summary_from_recording`
  computes the same figures, exactly on sim time, from an MCAP recording (``record_path``).
* **The umbrella of N ribs.**  ``SimulatedAntenna({"ribs": 3, "rib.stick_until": [0.0,
  0.05, 0.0]})`` runs it (a rib's own values as ``rib.<name>`` lists, one per rib):
  :meth:`SimulatedAntenna.rib_states` (per-rib joint angles and rates),
  :meth:`~SimulatedAntenna.rib_arrays` (``rib_tip_deflection``, ``rib_peak_stress``),
  :meth:`~SimulatedAntenna.energy_balance` and :meth:`~SimulatedAntenna.umbrella_figures`
  (each rib's deployment instant, the lag of the latest, friction work...); see
  examples/test_umbrella_ribs.py.  :func:`summary_from_recording` of its recording returns a
  :class:`RibsRunSummary`: each rib's deployment instant, the lag, each rib's peak of every
  stress component, the largest tips, friction work and each rib's stage-2 figures, by the
  run summary's definitions applied to the publications (exactly the summary's with a
  publication every physics step; the peaks exact at any rate).

Pytest fixtures (import them into your ``conftest.py``): ``ros_domain_id``, ``probe`` and
``antenna_factory`` (starts :class:`SimulatedAntenna` objects and stops them at teardown).
Importing this module imports rclpy (the recordings' reader needs it), with an error saying
how to install it where it is missing: pip's install of umbrella_sim brings no ROS 2 package
(``pip install 'umbrella_sim[ros]'`` does, or a sourced ROS 2 install); the message packages
are imported when a probe or an antenna is created.
"""
from __future__ import annotations

# (first: a missing rclpy, which the API's own imports need, is said with how to install it)
from ..tools.entry import missing_dependency

try:
    import rclpy  # noqa: F401  (the bag reader's, the probe's)
except ModuleNotFoundError as _exc:
    raise ModuleNotFoundError(f'umbrella_sim.testing: {missing_dependency(_exc.name)}',
                              name=_exc.name) from None
from .antenna import SimulatedAntenna  # noqa: I100
from .processes import (default_domain_id, DOMAIN_ID, DOMAIN_ID_ENV, NodeProcess, poll, Probe,
                        remove_stale_shm, reserve_domain, ros_env)
from .summary import (RibsRunSummary, RunSummary, summarize_ribs, summarize_run,
                      SUMMARY_AFTER_LOCK, summary_from_recording)

__all__ = ['antenna_factory', 'default_domain_id', 'DOMAIN_ID', 'DOMAIN_ID_ENV', 'NodeProcess',
           'poll', 'Probe', 'probe', 'remove_stale_shm', 'reserve_domain',
           'RibsRunSummary', 'ros_domain_id', 'ros_env', 'RunSummary', 'SimulatedAntenna',
           'summarize_ribs', 'summarize_run', 'SUMMARY_AFTER_LOCK', 'summary_from_recording']


# ------------------------------------------------------------------ fixtures
try:
    import pytest
except ImportError:                                    # pragma: no cover
    pytest = None

if pytest is not None:
    @pytest.fixture(scope='session')
    def ros_domain_id() -> int:
        """Return the ROS domain of this session (UMBRELLA_TEST_DOMAIN_ID, else a free one)."""
        return DOMAIN_ID

    @pytest.fixture
    def probe(ros_domain_id):
        """Yield a Probe on the session's domain, closed after the test."""
        p = Probe(domain_id=ros_domain_id)
        yield p
        p.close()

    @pytest.fixture
    def antenna_factory(ros_domain_id):
        """Start SimulatedAntenna(**kwargs) objects; all are closed after the test."""
        started: list[SimulatedAntenna] = []

        def start(parameters: dict | None = None, **kwargs) -> SimulatedAntenna:
            kwargs.setdefault('domain_id', ros_domain_id)
            antenna = SimulatedAntenna(parameters, **kwargs)
            started.append(antenna)
            return antenna
        yield start
        for antenna in reversed(started):
            antenna.close()
