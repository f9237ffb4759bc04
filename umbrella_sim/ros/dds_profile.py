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
umbrella_node's Fast DDS profile: set by default, only where nobody set one.

config/fastdds_node.xml holds one setting of the node's own DataWriters (a 5 ms NACK
suppression instead of 0: its comment says why and what it changes; no QoS policy, no
discovery or transport setting).  Fast DDS 2.x reads its XML profiles from
``FASTRTPS_DEFAULT_PROFILES_FILE`` (3.x from ``FASTDDS_DEFAULT_PROFILES_FILE``) when the
process's first participant is made (and then ``DEFAULT_FASTRTPS_PROFILES.xml`` of the working
directory unless ``SKIP_DEFAULT_XML`` is 1), so the node sets it before rclpy.init, and only
when the RMW is Fast DDS's, the user has given no profile (neither variable set, no
``DEFAULT_FASTRTPS_PROFILES.xml`` Fast DDS would read: theirs, whatever it holds, is theirs to
keep) and the file is found; else nothing changes and the node runs as it would without it.
"""
from __future__ import annotations

import os

from .share import package_path

#: the profile file, in the package's config/
PROFILE = ('config', 'fastdds_node.xml')
#: the variable Fast DDS 2.x (Jazzy) reads, and the ones that say a user chose a profile
PROFILE_ENV = 'FASTRTPS_DEFAULT_PROFILES_FILE'
USER_ENV = (PROFILE_ENV, 'FASTDDS_DEFAULT_PROFILES_FILE')
#: the profile file Fast DDS reads from the working directory (unless SKIP_DEFAULT_XML=1)
WORKING_DIR_PROFILE = 'DEFAULT_FASTRTPS_PROFILES.xml'
#: the RMW implementations that read it (RMW_IMPLEMENTATION unset: Jazzy's default, Fast DDS)
FAST_DDS_RMWS = ('', 'rmw_fastrtps_cpp', 'rmw_fastrtps_dynamic_cpp')


def use_node_profile(environ=os.environ, cwd: str = '.') -> str | None:
    """
    Set the node's Fast DDS profile in environ unless the user chose one; return its path.

    None (environ unchanged): another RMW, a profile of the user's (a variable, or the
    working directory cwd's file that Fast DDS reads), or the file not found (an incomplete
    install: Fast DDS's defaults, as before).
    """
    if environ.get('RMW_IMPLEMENTATION', '') not in FAST_DDS_RMWS:
        return None
    if any(environ.get(name) for name in USER_ENV):
        return None
    if (environ.get('SKIP_DEFAULT_XML') != '1'
            and os.path.exists(os.path.join(cwd, WORKING_DIR_PROFILE))):
        return None
    path = package_path(*PROFILE)
    if path is None:
        return None
    environ[PROFILE_ENV] = path
    return path
