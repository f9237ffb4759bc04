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
"""What the benches read of a process and the machine: resident memory, load, counted commands."""
import os

PAGE = os.sysconf('SC_PAGE_SIZE')


def rss_mb(pid: int) -> float:
    """Return the resident memory of process pid (MB)."""
    with open(f'/proc/{pid}/statm') as fh:
        return int(fh.read().split()[1]) * PAGE / 2**20


def load() -> str:
    """Return the machine's load averages as text (the figures beside them are shared)."""
    return 'load ' + ', '.join(f'{x:.2f}' for x in os.getloadavg())


def counted_commands(probe) -> int:
    """Return the commands the node counted (accepted + refused) in its latest /diagnostics."""
    msgs = probe.messages('/diagnostics')
    if not msgs:
        return 0
    v = {kv.key: kv.value for kv in msgs[-1].status[0].values}
    return int(v['accepted_commands']) + int(v['refused_commands'])
