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
The recording format: what rosbag2 (Jazzy) writes, and an MCAP file ``mcap doctor`` passes.

``mcap doctor`` (the Go CLI; not on PyPI) warns of a Schema or Channel record repeated in
the data section, in or out of chunks, and fails a file whose summary section repeats a
record the data section lacks, whose chunk messages use a channel not defined before them,
or whose statistics disagree with the messages.  ``doctor`` below makes those checks with
the mcap library's stream reader.  Type hashes are checked against rosbags' own RIHS01
computation from the message definitions (an independent implementation of REP 2011).
"""
from collections import Counter
import os
import subprocess
import sys

from mcap.records import Channel, Chunk, DataEnd, Header, Message, Schema, Statistics
from mcap.stream_reader import breakup_chunk, StreamReader
import pytest
from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy
from rosbags.typesys import get_typestore, Stores
from umbrella_sim.bag.cdr import BAG_FORMAT_VERSION, type_description_hash
from umbrella_sim.bag.reader import qos_from_yaml, read_log, resolve_path
import yaml

pytestmark = pytest.mark.slow


def doctor(path: str) -> tuple[list[str], list[str]]:
    """Return (errors, warnings) of mcap doctor's record checks on an MCAP file."""
    errors, warnings = [], []
    data_schemas, data_channels = Counter(), {}
    summary_schemas, summary_channels = set(), set()
    messages, per_channel, stats = 0, Counter(), None
    in_summary = False

    def examine(record, in_chunk: bool):
        nonlocal messages
        if isinstance(record, Schema):
            if in_summary:
                summary_schemas.add(record.id)
                if record.id not in data_schemas:
                    errors.append(f'schema {record.id} in the summary only')
            else:
                data_schemas[record.id] += 1
                if data_schemas[record.id] > 1:
                    warnings.append(f'Duplicate schema records in data section with ID '
                                    f'{record.id}')
        elif isinstance(record, Channel):
            if in_summary:
                summary_channels.add(record.id)
                if record.id not in data_channels:
                    errors.append(f'channel {record.id} in the summary only')
            else:
                if record.id in data_channels:
                    warnings.append(f'Duplicate channel records in data section with ID '
                                    f'{record.id}')
                data_channels[record.id] = record
                if record.schema_id and record.schema_id not in data_schemas:
                    errors.append(f'channel {record.id} before its schema {record.schema_id}')
        elif isinstance(record, Message):
            if record.channel_id not in data_channels:
                errors.append(f'message of channel {record.channel_id} before the channel')
            messages += 1
            per_channel[record.channel_id] += 1
            if not in_chunk:
                warnings.append('message outside chunks')

    with open(path, 'rb') as fh:
        for record in StreamReader(fh, skip_magic=False, emit_chunks=True).records:
            if isinstance(record, Header):
                if not record.library:
                    warnings.append('empty Header.library')
                if record.profile != 'ros2':
                    errors.append(f'profile {record.profile!r}')
            elif isinstance(record, Chunk):
                for inner in breakup_chunk(record, validate_crc=True):
                    examine(inner, True)
            elif isinstance(record, DataEnd):
                in_summary = True
            elif isinstance(record, Statistics):
                stats = record
            else:
                examine(record, False)
    if stats is None:
        errors.append('no Statistics record')
    else:
        if stats.message_count != messages:
            errors.append(f'statistics: {stats.message_count} messages, {messages} read')
        if dict(stats.channel_message_counts) != dict(per_channel):
            errors.append('statistics: per-channel counts differ')
    errors += [f'channel {c} of a message not in the summary'
               for c in per_channel if c not in summary_channels]
    errors += [f'schema {s} not in the summary' for s in data_schemas if s not in summary_schemas]
    return errors, warnings


@pytest.fixture(scope='module')
def offline_bag(tmp_path_factory):
    """Record offline with a force profile (so /sleeve_force/applied is in it)."""
    root = tmp_path_factory.mktemp('format')
    profile = root / 'force.csv'
    profile.write_text('t,F\n0.0,2.0\n0.05,4.0\n')
    bag = root / 'bag'
    r = subprocess.run([sys.executable, '-m', 'umbrella_sim', 'simulate', '--duration', '0.2',
                        '--force-profile', str(profile), '--mcap', str(bag)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return bag


def test_a_recording_passes_mcap_doctor(offline_bag):
    errors, warnings = doctor(resolve_path(str(offline_bag)))
    assert errors == [] and warnings == []
    # and each Schema and Channel record is in the data section once
    with open(resolve_path(str(offline_bag)), 'rb') as fh:
        seen = Counter()
        for record in StreamReader(fh, emit_chunks=True).records:
            if isinstance(record, DataEnd):
                break
            inner = breakup_chunk(record) if isinstance(record, Chunk) else [record]
            seen.update((type(r).__name__, r.id) for r in inner
                        if isinstance(r, (Schema, Channel)))
    assert seen and set(seen.values()) == {1}, seen


def test_the_doctor_finds_a_repeated_channel(tmp_path):
    """The check above sees what mcap doctor warned of: records repeated outside chunks."""
    from mcap.data_stream import RecordBuilder
    from mcap.writer import Writer

    path = tmp_path / 'repeated.mcap'
    definition = b'float64 data\n'
    with open(path, 'wb') as fh:
        w = Writer(fh)
        w.start(profile='ros2', library='test')
        # outside the chunks first, as the old recorder did; then the writer's, in its chunk
        builder = RecordBuilder()
        Schema(id=1, name='std_msgs/msg/Float64', encoding='ros2msg',
               data=definition).write(builder)
        Channel(id=1, topic='/x', message_encoding='cdr', schema_id=1,
                metadata={}).write(builder)
        fh.write(builder.end())
        sid = w.register_schema('std_msgs/msg/Float64', 'ros2msg', definition)
        cid = w.register_channel('/x', 'cdr', sid)
        w.add_message(cid, 1, b'\x00\x01\x00\x00' + bytes(8), 1)
        w.finish()
    errors, warnings = doctor(str(path))
    assert errors == []
    assert warnings == ['Duplicate schema records in data section with ID 1',
                        'Duplicate channel records in data section with ID 1']


def test_bag_metadata_is_rosbag2_jazzy_s(offline_bag):
    """Metadata version 9: QoS profiles as lists with policy names, RIHS01 type hashes."""
    store = get_typestore(Stores.ROS2_JAZZY)
    info = yaml.safe_load((offline_bag / 'metadata.yaml').read_text())
    info = info['rosbag2_bagfile_information']
    assert info['version'] == BAG_FORMAT_VERSION == 9 and info['ros_distro'] == 'jazzy'
    topics = {t['topic_metadata']['name']: t['topic_metadata']
              for t in info['topics_with_message_count']}
    assert {'/joint_states', '/clock', '/sleeve_force/applied'} <= set(topics)
    for name, t in topics.items():
        # the wheels' hash (share/<pkg>/msg/<Type>.json) is rosbags' computation of it
        assert t['type_description_hash'] == store.hash_rihs01(t['type']), name
        assert t['type_description_hash'].startswith('RIHS01_')
        (profile,) = t['offered_qos_profiles']
        assert profile['history'] in ('keep_last', 'keep_all'), name
        assert profile['reliability'] in ('reliable', 'best_effort'), name
    assert topics['/clock']['offered_qos_profiles'][0]['reliability'] == 'best_effort'
    # the channels carry the same, as rosbag2's MCAP plugin writes them
    log = read_log(str(offline_bag))
    from mcap.reader import make_reader

    with open(log.path, 'rb') as fh:
        summary = make_reader(fh).get_summary()
    for ch in summary.channels.values():
        assert ch.metadata['topic_type_hash'] == topics[ch.topic]['type_description_hash']
        assert yaml.safe_load(ch.metadata['offered_qos_profiles']) == \
            topics[ch.topic]['offered_qos_profiles']
    # and rosbags reads the version-9 bag with those hashes
    from pathlib import Path

    from rosbags.highlevel import AnyReader

    with AnyReader([Path(offline_bag)], default_typestore=store) as rd:
        assert {c.topic: c.digest for c in rd.connections} == {
            n: t['type_description_hash'] for n, t in topics.items()}


def test_type_hash_of_a_type_without_its_description_is_empty():
    assert type_description_hash('std_msgs/msg/NoSuchType') == ''


def test_old_recordings_still_read(tmp_path):
    """A version-8 bag (integer QoS enums, no type hash) reads, its QoS as recorded."""
    from pathlib import Path

    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = get_typestore(Stores.ROS2_JAZZY)
    Float64 = store.types['std_msgs/msg/Float64']
    forever = QosTime(9223372036, 854775807)
    qos = Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
              forever, forever, QosLiveliness.AUTOMATIC, forever, False)
    bag = tmp_path / 'v8'
    with Writer(Path(bag), version=8, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection('/x', 'std_msgs/msg/Float64', typestore=store,
                                offered_qos_profiles=[qos])
        w.write(conn, 5, store.serialize_cdr(Float64(data=1.5), 'std_msgs/msg/Float64'))
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['version'] == 8
    log = read_log(str(bag), umbrella=False)
    text = log.channels['/x'][1]
    assert 'history: 1' in text.replace("'", '')          # the integer form
    q = qos_from_yaml(text)
    assert (q.history, q.depth, q.reliability, q.durability) == (
        HistoryPolicy.KEEP_LAST, 1, ReliabilityPolicy.RELIABLE,
        DurabilityPolicy.TRANSIENT_LOCAL)
    assert [m.data for _, m in log.decoded('/x')] == [1.5]
    assert os.path.isdir(bag)


def test_a_directory_of_runs_names_the_bags_it_holds(tmp_path, offline_bag):
    """
    A directory of bag directories (runs/) given for a bag: the error names some of them.

    'needs metadata.yaml or exactly one .mcap (found 0)' alone left the user to guess that a
    run inside was meant; the latest three are named (sorted: the runs' names are their start
    times), and how many more there are.  A directory of neither says nothing more.
    """
    import shutil

    from umbrella_sim.bag.reader import LogError

    runs = tmp_path / 'runs'
    for k in range(5):
        shutil.copytree(offline_bag, runs / f'umbrella_2026_11_28-12_0{k}_00')
    (runs / 'notes').mkdir()
    with pytest.raises(LogError) as info:
        resolve_path(str(runs))
    said = str(info.value)
    assert 'found 0' in said and 'and 2 more' in said and 'notes' not in said
    assert [k for k in range(5) if f'umbrella_2026_11_28-12_0{k}_00' in said] == [2, 3, 4]
    assert resolve_path(str(runs / 'umbrella_2026_11_28-12_04_00')).endswith('.mcap')
    with pytest.raises(LogError) as info:
        resolve_path(str(runs / 'notes'))
    assert str(info.value).endswith('(found 0)')
