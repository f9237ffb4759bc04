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
Under the mcap Writer: the crash-safe file, the chunk index on disk, fast Message records.

``CommittedFile`` takes the writer's stream and writes it to the file between records only
(a failed write is truncated back to the last record boundary, so the file never holds a
torn record); ``SpilledChunkIndex`` keeps the writer's growing chunk index on disk while
recording (bounded memory); ``MessageAppender`` appends Message records to the open chunk
with one ``struct.pack`` each, byte for byte what ``Writer.add_message`` writes;
``ended_early_tail`` is the trailer that makes a recording stopped by a write error a
complete MCAP file again; ``keep_definitions_out_of_chunks`` leaves Schema and Channel
records to the recorder, which writes each once outside the chunks.
"""
from __future__ import annotations

import itertools
import os
import struct

from mcap.opcode import Opcode
from mcap.records import MessageIndex
from mcap.writer import Writer

from .format import ENDED_EARLY_RECORD, MCAP_MAGIC


def write_all(fd: int, data) -> None:
    """os.write until everything is written (the one place bytes reach the file)."""
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


class CommittedFile:
    """
    Write the MCAP writer's records to the file between records only.

    The MCAP writer's stream: buffers records in memory and writes them to the file only
    on commit(), which happens between records.  A failed commit (ENOSPC, EIO, EACCES...)
    truncates the file back to the last committed record boundary, so the file never holds
    a torn record and the space of the failed write is given back.
    """

    def __init__(self, path: str):
        self.fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self.committed = 0
        self._pending = bytearray()

    def write(self, data) -> int:
        self._pending += data
        return len(data)

    def tell(self) -> int:
        return self.committed + len(self._pending)

    def flush(self) -> None:           # the writer's flush(); commits happen explicitly
        pass

    def commit(self) -> bool:
        """Write what is pending; True if anything was written."""
        if not self._pending:
            return False
        # an immutable copy: a failed os.write leaves views of its buffer in the traceback,
        # and a bytearray with live views cannot be cleared (BufferError on a full tmpfs)
        data = bytes(self._pending)
        self._pending.clear()
        try:
            write_all(self.fd, data)
        except OSError:
            self.rollback()
            raise
        self.committed += len(data)
        return True

    def rollback(self) -> None:
        try:
            os.ftruncate(self.fd, self.committed)
            os.lseek(self.fd, self.committed, os.SEEK_SET)
        except OSError:
            pass

    def close(self, sync: bool = True) -> None:
        if self.fd < 0:
            return
        try:
            if sync:
                os.fsync(self.fd)
        finally:
            os.close(self.fd)
            self.fd = -1


def ended_early_tail(metadata: dict[str, str]) -> bytes:
    """
    Return the trailer of a recording stopped by a write error.

    A Metadata record, DataEnd and a Footer without summary: appended at the last record
    boundary, it makes a failed recording a complete MCAP again that says why it ended.
    """
    from mcap.data_stream import RecordBuilder
    from mcap.records import DataEnd, Footer, Metadata

    builder = RecordBuilder()
    Metadata(name=ENDED_EARLY_RECORD, metadata=metadata).write(builder)
    DataEnd(data_section_crc=0).write(builder)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    return bytes(builder.end()) + MCAP_MAGIC


class SpilledChunkIndex:
    """
    The MCAP writer's chunk index, kept on disk while recording (bounded memory).

    The writer keeps one ChunkIndex object per chunk until finish() writes the summary
    section (measured: ~1.2 kB of Python objects per 64 KiB chunk, 8 to 15 kB per simulated
    second at 1 kHz, growing without bound).  This list stand-in serialises each index to
    its MCAP record at once (~190 bytes) and moves the records to an anonymous temporary
    file next to the recording (unlinked from the start: nothing is left behind) every
    64 KiB; finish() reads them back in order into the summary, which therefore still holds
    every chunk index (readers seek by time as before).  If the temporary file cannot be
    written (disk full) the records stay in memory: the recording itself fails soon after.
    """

    SPILL_BYTES = 64 * 1024

    def __init__(self, directory: str):
        import tempfile

        self._records = bytearray()
        self.count = 0
        try:
            self._file = tempfile.TemporaryFile(dir=directory)
        except OSError:
            self._file = None

    def append(self, index) -> None:
        from mcap.data_stream import RecordBuilder

        builder = RecordBuilder()
        index.write(builder)
        self._records += builder.end()
        self.count += 1
        if self._file is not None and len(self._records) >= self.SPILL_BYTES:
            try:
                self._file.write(self._records)
                self._records.clear()
            except OSError:
                pass

    def __len__(self) -> int:
        return self.count

    def __iter__(self):
        """Yield the records in order, in pieces the writer copies into its summary."""
        if self._file is not None:
            self._file.flush()
            self._file.seek(0)
            while True:
                piece = self._file.read(1 << 20)
                if not piece:
                    break
                yield _RawRecords(piece)
        yield _RawRecords(bytes(self._records))

    def in_memory_bytes(self) -> int:
        return len(self._records)

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


def keep_definitions_out_of_chunks(writer: Writer) -> bool:
    """
    Make the writer leave Schema and Channel records out of its chunks.

    The recorder writes each once, in the data section outside the chunks, as it is
    registered: a recording cut short keeps its channels whatever became of its chunks,
    and no record is repeated (``mcap doctor`` warns of a repeated one; the writer still
    repeats them in the summary section, as MCAP asks).  False where this mcap version
    has no chunk builder to replace: its chunks then hold them, once.
    """
    try:
        from mcap._chunk_builder import ChunkBuilder
    except ImportError:
        return False
    if type(getattr(writer, '_Writer__chunk_builder', None)) is not ChunkBuilder:
        return False

    class MessagesOnly(ChunkBuilder):

        def add_schema(self, schema) -> None:
            pass

        def add_channel(self, channel) -> None:
            pass

    writer._Writer__chunk_builder = MessagesOnly()
    return True


class _RawRecords:
    """Already serialised MCAP records, written as they are."""

    def __init__(self, data: bytes):
        self.data = data

    def write(self, builder) -> None:
        builder.write(self.data)


#: a Message record up to its data: opcode, record length, channel id, sequence, log time,
#: publish time (the MCAP specification's Message record)
_MESSAGE_HEAD = struct.Struct('<BQHIQQ')


class _PackedMessageIndex(MessageIndex):
    """A chunk's MessageIndex record written in one struct.pack (the same bytes)."""

    def write(self, stream) -> None:
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write2(self.channel_id)
        stream.write4(len(self.records) * 16)
        stream.write(struct.pack(f'<{2 * len(self.records)}Q',
                                 *itertools.chain.from_iterable(self.records)))
        stream.finish_record()


class MessageAppender:
    """
    Append Message records to the open chunk of an mcap Writer, one struct.pack each.

    What ``Writer.add_message`` does for a chunked writer (the statistics, the chunk's time
    range and message index, the record, closing a full chunk) without building a Message
    object and writing its five fields one by one, and with each chunk's message indexes
    packed at once (_PackedMessageIndex).  ``create`` returns None where this mcap version
    lacks the members it uses; ``add_message`` serves then.  The files are byte for byte
    those of ``add_message`` (tests/test_recorder_background.py).
    """

    def __init__(self, stats, chunk, finish_full_chunk):
        self.stats = stats
        self.chunk = chunk
        self.finish_full_chunk = finish_full_chunk

    @classmethod
    def create(cls, writer: Writer) -> 'MessageAppender | None':
        stats = getattr(writer, '_Writer__statistics', None)
        chunk = getattr(writer, '_Writer__chunk_builder', None)
        finish = getattr(writer, '_Writer__maybe_finalize_chunk', None)
        needed = (hasattr(stats, 'channel_message_counts') and hasattr(chunk, 'message_indices')
                  and hasattr(getattr(chunk, 'record_writer', None), '_buffer')
                  and callable(finish))
        return cls(stats, chunk, finish) if needed else None

    def add(self, channel_id: int, sequence: int, t_ns: int, data: bytes) -> None:
        st = self.stats
        if st.message_count == 0 or t_ns < st.message_start_time:
            st.message_start_time = t_ns
        if t_ns > st.message_end_time:
            st.message_end_time = t_ns
        st.channel_message_counts[channel_id] += 1
        st.message_count += 1
        chunk = self.chunk
        if chunk.num_messages == 0 or t_ns < chunk.message_start_time:
            chunk.message_start_time = t_ns
        if t_ns > chunk.message_end_time:
            chunk.message_end_time = t_ns
        stream = chunk.record_writer._buffer      # a new one after every finished chunk
        index = chunk.message_indices.get(channel_id)
        if index is None:
            index = chunk.message_indices[channel_id] = _PackedMessageIndex(
                channel_id=channel_id, records=[])
        index.records.append((t_ns, stream.tell()))
        chunk.num_messages += 1
        stream.write(_MESSAGE_HEAD.pack(Opcode.MESSAGE, 22 + len(data), channel_id, sequence,
                                        t_ns, t_ns))
        stream.write(data)
        self.finish_full_chunk()
