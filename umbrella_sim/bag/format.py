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
What an umbrella_sim recording holds: the names and constants its writer and readers share.

A recording is a rosbag2 bag directory ``NAME/`` holding ``NAME_0.mcap`` and
``metadata.yaml``; the .mcap also stands alone (profile ``ros2``).  Besides the messages it
carries metadata records, each named here once (msg_docs/recording.md describes them).
"""

#: the MCAP file's magic bytes (its first and last eight)
MCAP_MAGIC = b'\x89MCAP0\r\n'
#: uncompressed bytes a chunk holds before it is compressed and written
CHUNK_SIZE = 64 * 1024
#: every parameter of the run (JSON values), including the physics step used
PARAMETERS_RECORD = 'umbrella_sim.parameters'
#: version, git revision, kernel, floating-point environment
BUILD_RECORD = 'umbrella_sim.build'
#: model, lock, mesh: coordinate labels and node positions
MESH_RECORD = 'umbrella_sim.mesh'
#: + ".K": a ~/reset started segment K (its log-time offset and parameters)
SEGMENT_RECORD = 'umbrella_sim.segment'
#: the exact lock instant and the fault of the (last) segment; + ".K" for an earlier one
EVENTS_RECORD = 'umbrella_sim.events'
#: messages published and recorded per topic, commands accepted and refused
COUNTS_RECORD = 'umbrella_sim.counts'
#: the run's summary figures of every physics step and its warnings, of the (last)
#: segment; + ".K" for an earlier one
SUMMARY_RECORD = 'umbrella_sim.summary'
#: the node's own topic name (joint_states, sleeve_force/applied...) -> the name recorded,
#: which a remapping (-r joint_states:=js, a namespace) may have changed
TOPICS_RECORD = 'umbrella_sim.topics'
#: a recording stopped by a write error says so in this record
ENDED_EARLY_RECORD = 'umbrella_sim.recording_error'
#: + ".K" (K from 1): a runtime set of marker_magnification; the markers recorded after its
#: log_time_ns are drawn at its value (before it: the segment's parameter)
MAGNIFICATION_RECORD = 'umbrella_sim.marker_magnification'
#: the command topic's records beside it: each value as applied, and refused commands
APPLIED_SUFFIX = '/applied'
REFUSED_SUFFIX = '/refused'


def segment_record(name: str, index: int | None) -> str:
    """
    Return the name of a run record (EVENTS_RECORD, SUMMARY_RECORD) of one segment.

    index None: the last segment's, written at close under the record's own name; a segment
    a ~/reset ended (index K): ``name.K``, written at that reset.
    """
    return name if index is None else f'{name}.{index}'
