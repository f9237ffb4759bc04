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

A tool of commands (``umbrella_sim simulate``, ``umbrella_sim sweep``) wants its command
first; argparse, given ``umbrella_sim --v0 -0.3``, named ``-0.3`` an invalid command.  This
parser names what is wrong: the option before its command (and the command that takes it), or
a command misspelt (with the one meant: registry.closest_name, the parameters' rule).
"""
from __future__ import annotations

import argparse
import re
import sys

from ..core.registry import closest_name, SPECS

#: a negative decimal number, with an optional exponent
NEGATIVE_NUMBER = re.compile(r'^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$')


class ArgumentParser(argparse.ArgumentParser):
    """argparse.ArgumentParser that reads ``-5e-1`` as a value (its sub-parsers too)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER

    def parse_known_args(self, args=None, namespace=None):
        args = sys.argv[1:] if args is None else list(args)
        commands = self._commands()
        if commands and args and args[0] not in commands:
            self._command_expected(args, commands)
        return super().parse_known_args(args, namespace)

    def _commands(self) -> dict:
        """Return this parser's commands (name -> its parser), {} for a tool of none."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                return dict(action.choices)
        return {}

    def _command_expected(self, args: list, commands: dict) -> None:
        """Refuse a first argument that is neither a command nor this parser's option."""
        first = args[0]
        names = ', '.join(commands)
        if not first.startswith('-') or NEGATIVE_NUMBER.match(first):
            meant = closest_name(first, commands)
            hint = f": did you mean '{meant}'?" if meant else ''
            self.error(f"'{first}' is not a command (commands: {names}){hint}")
        option = first.split('=', 1)[0]
        if option in self._option_string_actions:
            return
        takers = [name for name, parser in commands.items()
                  if option in parser._option_string_actions]
        if takers:
            self.error(f'the command comes first: {self.prog} {takers[0]} {" ".join(args)} '
                       f'({option} is an option of {" and ".join(takers)})')
        self.error(f'{option}: not an option of {self.prog}; the command comes first '
                   f'(commands: {names}; {self.prog} COMMAND --help lists its options)')


class GivenOnce(argparse.Action):
    """An option that gives a parameter: given twice is an error, not the last one winning."""

    def __call__(self, parser, namespace, values, option_string=None):
        if getattr(namespace, self.dest) is not None:
            parser.error(f'{option_string} given twice (give each parameter once)')
        setattr(namespace, self.dest, values)


def add_parameter_options(sp: argparse.ArgumentParser, models=None) -> None:
    """
    Add the options that give the model's parameters (inputs.build_params reads them).

    models: the models --model offers (default: every one).
    """
    sp.add_argument('--params', metavar='FILE',
                    help='ROS 2 params YAML (default: config/umbrella.yaml)')
    sp.add_argument('--set', action='append', metavar='NAME=VALUE',
                    help='override one parameter (repeatable; each parameter once, here or '
                         'by its own option)')
    sp.add_argument('--model', choices=models or SPECS['model'].choices, action=GivenOnce)
    sp.add_argument('--elements-per-segment', type=int, dest='elements_per_segment',
                    action=GivenOnce)
