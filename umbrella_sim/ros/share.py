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
Where the package's data files are (config/, msg_docs/, launch/, urdf/, rviz/): one rule.

In order: the source checkout this module runs from (an editable install: the files being
edited), the package's share directory in the ament index (a colcon install, with its
``setup.bash`` sourced), the share directory of the prefix this module is installed under
(PREFIX/lib/pythonX.Y/site-packages/umbrella_sim -> PREFIX/share/umbrella_sim), and that of
the interpreter's prefix (a pip install into a virtualenv).
"""
from __future__ import annotations

import os
import sys

PACKAGE = 'umbrella_sim'
#: the directory above the umbrella_sim package (a source checkout's root holds package.xml)
_ABOVE_PACKAGE = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def share_dir(package: str = PACKAGE) -> str | None:
    """Return a package's share directory from the ament index, or None if not installed."""
    try:
        from ament_index_python.packages import (get_package_share_directory,
                                                 PackageNotFoundError)
    except ImportError:
        return None
    try:
        return get_package_share_directory(package)
    except (PackageNotFoundError, LookupError, OSError, ValueError):
        return None


def _roots() -> list[str]:
    roots = []
    if os.path.isfile(os.path.join(_ABOVE_PACKAGE, 'package.xml')):
        roots.append(_ABOVE_PACKAGE)
    indexed = share_dir()
    if indexed:
        roots.append(indexed)
    roots.append(os.path.join(_ABOVE_PACKAGE, '..', '..', '..', 'share', PACKAGE))
    roots.append(os.path.join(sys.prefix, 'share', PACKAGE))
    return roots


def package_path(*parts: str) -> str | None:
    """Return the first existing path of the package data (config/umbrella.yaml...), or None."""
    for root in _roots():
        path = os.path.join(root, *parts)
        if os.path.exists(path):
            return os.path.normpath(path)
    return None
