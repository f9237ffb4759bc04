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
A disk that fills up, for recording tests (no ROS imports, no side effects).

``python -m tests.disk_faults LIMIT ERRNO --ros-args ...`` runs umbrella_node on such a disk.
"""
import os
import stat
import sys


def full_disk_write(limit: int, code: int, real=os.write):
    """
    Return an os.write for a disk that holds `limit` bytes per regular file.

    Like a full tmpfs: the write that reaches the limit is partial, the next one fails
    with `code` (ENOSPC, EIO, ...); pipes and terminals are not affected.
    """
    def write(fd, data):
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            return real(fd, data)
        room = limit - os.lseek(fd, 0, os.SEEK_CUR)
        if room <= 0:
            raise OSError(code, os.strerror(code))
        return real(fd, data[:room])
    return write


if __name__ == '__main__':
    from umbrella_sim.ros.node_main import main
    limit, code = int(sys.argv.pop(1)), int(sys.argv.pop(1))
    os.write = full_disk_write(limit, code)
    sys.exit(main())
