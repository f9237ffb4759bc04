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
The physics: parameters -> model -> solver -> outputs, usable from a plain Python script.

No ROS, no file format, no command line, no signal handling (tests/test_architecture.py holds
it so).  The parts, in the order data flows through them:

    registry, params   every parameter once (type, default, unit, range); the records
    model, rigid       the leaf + link frame in floating frames; the closed-form rigid model
    kernel, integrators, nonlinear, engines
                       the compiled step (_kernel.h declares its interface) and the models'
                       time stepping
    solver             UmbrellaSimulator: the time grid, the force, the lock
    driver             RunDriver: one run in chunks of compiled steps, its force schedule,
                       summary and publications; simulate() the whole run
    umbrella3d         N flexible ribs in 3D around one sleeve (UmbrellaRibsParams,
                       UmbrellaSimulator3D); the planar model is its one-rib case
    outputs, summary   per-step rows, Samples, and the summary figures of every step

The names a script needs are importable from here::

    from umbrella_sim.core import UmbrellaParams, simulate
    result = simulate(UmbrellaParams(v0=-0.5), 1.0, stop_after_lock=0.3, keep_samples=False)
    print(result.summary()["deploy_time"])
"""
import importlib

#: the public names, by the module that defines them (imported on first use: importing a
#: module of this package does not import the whole physics)
_PUBLIC = {'UmbrellaParams': 'params', 'ControllerConfig': 'params', 'REGISTRY': 'registry',
           'UmbrellaModel': 'model', 'UmbrellaSimulator': 'solver', 'RunDriver': 'driver',
           'Chunk': 'driver', 'simulate': 'driver', 'Sample': 'outputs',
           'StepBlock': 'outputs', 'RunResult': 'summary', 'SummaryAccumulator': 'summary',
           'ForceSchedule': 'forcing', 'UmbrellaRibsParams': 'umbrella3d.params3d',
           'UmbrellaSimulator3D': 'umbrella3d.simulator3d'}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    if name not in _PUBLIC:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    return getattr(importlib.import_module(f'.{_PUBLIC[name]}', __name__), name)
