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
ament lint tests, as every ROS 2 Python package has them (ament_flake8, ament_pep257).

flake8 runs with ament_flake8's configuration (line length 99, the google import order,
flake8-builtins/-comprehensions/-class-newline/-docstrings/-quotes...) written out in
setup.cfg's [flake8] section with one change: this code base uses double quotes.  pep257 runs
with ament_pep257's own "ament" convention, unchanged.
"""
import os

from ament_flake8.main import main_with_errors as flake8_main
from ament_pep257.main import main as pep257_main
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# every Python file of the repository (ament's walk would also enter .venv and colcon's build/)
PATHS = ["umbrella_sim", "tests", "examples", "bench", "docs", "launch", "bootstrap.py",
         "setup.py"]


def _paths():
    return [os.path.join(ROOT, p) for p in PATHS if os.path.exists(os.path.join(ROOT, p))]


@pytest.mark.flake8
@pytest.mark.linter
@pytest.mark.slow
def test_flake8(monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)   # ament_flake8 walks the working directory for AMENT_IGNORE
    rc, errors = flake8_main(argv=["--config", os.path.join(ROOT, "setup.cfg"), *_paths()])
    assert rc == 0, f"Found {len(errors)} code style errors / warnings:\n" + "\n".join(errors)


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    rc = pep257_main(argv=_paths())
    assert rc == 0, "Found code style errors / warnings (see the captured output)"
