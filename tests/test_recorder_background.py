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

"""The live node's recorder: compression and file writes on a writer thread of their own."""
import errno
import json
import os
import threading

from rclpy.qos import QoSProfile
from std_msgs.msg import Float64

from tests.disk_faults import full_disk_write
from umbrella_sim.bag import writer as recording
from umbrella_sim.bag.format import CHUNK_SIZE
from umbrella_sim.bag.reader import read_log


def _values(path, topic='/x'):
    return [m.data for _, m in read_log(path).decoded(topic)]


def test_background_writer_records_what_the_synchronous_one_does(tmp_path):
    logs = []
    for background in (False, True):
        rec = recording.BagRecorder(str(tmp_path / f'bag{background}'),
                                    {'umbrella_sim.parameters': {}}, background=background)
        rec.add_channel('/x', Float64, QoSProfile(depth=10))
        for i in range(5000):
            assert rec.write('/x', Float64(data=float(i)), i * 1000)
        k = rec.start_segment({'a': '1'}, gap_ns=1000)     # waits for the queue
        assert k == 1 and rec.offset_ns == 4999 * 1000 + 1000
        for i in range(10):
            assert rec.write('/x', Float64(data=-float(i)), i * 1000)
        rec.close()
        assert rec.error is None and rec.counts['/x'] == 5010
        logs.append(_values(rec.path))
    assert logs[0] == logs[1] == [float(i) for i in range(5000)] + [-float(i) for i in range(10)]


def test_background_write_error_stops_the_recording_cleanly(tmp_path, monkeypatch):
    monkeypatch.setattr(os, 'write', full_disk_write(100_000, errno.ENOSPC))
    errors, threads = [], []

    def on_error(reason):
        errors.append(reason)
        threads.append(threading.current_thread().name)

    rec = recording.BagRecorder(str(tmp_path / 'bag'), {'umbrella_sim.parameters': {}},
                                on_error=on_error, background=True)
    rec.add_channel('/x', Float64, QoSProfile(depth=10))
    n = 0
    while rec.write('/x', Float64(data=float(n)), n * 1_000_000):   # queued until it fails
        n += 1
        assert n < 10**6
    assert not rec.write('/x', Float64(data=-1.0), 0)          # stays stopped, no exception
    rec.close({'late': {'a': 'b'}})                             # no exception either
    assert len(errors) == 1 and os.strerror(errno.ENOSPC) in errors[0]
    assert threads == ['recorder']                              # not the publishing thread
    log = read_log(str(tmp_path / 'bag'))
    assert log.ended_early and os.strerror(errno.ENOSPC) in log.ended_early
    values = _values(log.path)
    assert values == [float(i) for i in range(len(values))] and len(values) > 1000
    assert log.count('/x') == rec.counts['/x'] == len(values) < n
    assert os.path.getsize(log.path) <= 100_000


def test_background_close_run_counts_every_queued_message(tmp_path):
    rec = recording.BagRecorder(str(tmp_path / 'bag'), {'umbrella_sim.parameters': {}},
                                background=True)
    rec.add_channel('/x', Float64, QoSProfile(depth=10))
    for i in range(300):
        rec.write('/x', Float64(data=float(i)), i)
    recorded = rec.drained_counts()         # what RunRecording.close writes as its counts
    rec.close({'umbrella_sim.counts': {'recorded': json.dumps(recorded)}})
    log = read_log(rec.path)
    assert log.count('/x') == 300
    assert '"/x": 300' in log.metadata['umbrella_sim.counts']['recorded']


def test_fast_message_records_are_byte_for_byte_those_of_mcap_add_message(tmp_path):
    """
    Write with the recorder's own Message records, and with mcap's Writer.add_message.

    MessageAppender and its packed message indexes give the same file, byte for byte:
    several channels, many chunks, a segment.
    """
    files = []
    for fast in (True, False):
        (tmp_path / str(fast)).mkdir()           # the same bag name: it is in the metadata
        rec = recording.BagRecorder(str(tmp_path / str(fast) / 'bag'),
                                    {'umbrella_sim.parameters': {}})
        assert rec._appender is not None        # this mcap version has what it needs
        if not fast:
            rec._appender = None
        for topic in ('/x', '/y', '/z'):
            rec.add_channel(topic, Float64, QoSProfile(depth=10))
        for i in range(20000):                  # ~30 chunks of 64 KiB
            for k, topic in enumerate(('/x', '/y', '/z')[:1 + i % 3]):
                assert rec.write(topic, Float64(data=float(i * 3 + k)), i * 1000 + k)
        rec.start_segment({'a': '1'}, gap_ns=1000)
        for i in range(10):
            assert rec.write('/y', Float64(data=-float(i)), i * 1000)
        rec.close()
        assert rec.error is None
        with open(rec.path, 'rb') as fh:
            files.append(fh.read())
    assert len(files[0]) > 20 * CHUNK_SIZE // 4
    assert files[0] == files[1]
