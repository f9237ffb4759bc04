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
The command lines: umbrella_sim (simulate, sweep), umbrella_replay, umbrella_compare.

    entry              the console scripts (signal handlers first, then the tool)
    cli, inputs, csv_output, progress
                       umbrella_sim simulate: its options, inputs, CSV, progress line
    sweep, sweep_spec, sweep_results
                       umbrella_sim sweep: the SPEC, the Dask run, the table and plots
    replay             republish a recording, or re-simulate and check it
    compare, runs, compare_plots
                       compare recorded runs: table, JSON, plots
    param_docs         the parameter tables of msg_docs/
"""
