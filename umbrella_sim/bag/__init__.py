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
The recording format: MCAP files in rosbag2 bag directories, written and read.

    format       the record names and constants writer and readers share
    cdr          messages as a recording stores them: definitions, exact CDR bytes, QoS
    writer, mcap_stream
                 BagRecorder: a crash-safe bag directory, never overwriting
    reader       read_log: a bag directory or a single .mcap, finalised, torn or ended early
    provenance   the run records that make a recording reproducible from the file alone
    paths        checks of input and output paths, made before any expensive work

It runs no node and handles no signal; it knows the core's records only through the
objects it is handed.
"""
