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
Command-line parsing shared by the tools (umbrella_sim, umbrella_compare, umbrella_replay).

argparse takes an argument that starts with ``-`` for an option unless it looks like a
negative number, and its test for one knows no exponent: ``--v0 -5e-1`` failed with
"expected one argument".  This parser takes every float literal Python reads (``-5e-1``,
``-1E+3``, ``-.5``, ``-inf`` stays an option: no tool takes it) as a value.
"""
from __future__ import annotations

import argparse
import re

#: a negative decimal number, with an optional exponent
NEGATIVE_NUMBER = re.compile(r'^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$')


class ArgumentParser(argparse.ArgumentParser):
    """argparse.ArgumentParser that reads ``-5e-1`` as a value (its sub-parsers too)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER
