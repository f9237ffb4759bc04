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

"""The one parameter registry: every interface derived from it, docs current."""
import math
import pickle

import pytest

from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.registry import (coerce, defaults, MODEL, NODE_PARAMETERS, parameter_help,
                                        REGISTRY, SPECS)
from umbrella_sim.ros.params_file import load_params_file
from umbrella_sim.tools import param_docs
from umbrella_sim.tools.cli import make_parser


def test_msg_docs_parameter_tables_are_current():
    """Regenerate: .venv/bin/python -m umbrella_sim.tools.param_docs."""
    assert param_docs.main(['--check']) == 0


def test_docs_list_every_parameter_with_its_default():
    import os
    pages = ''.join(open(os.path.join(param_docs.msg_docs_dir(), p), encoding='utf-8').read()
                    for p in param_docs.PAGES)
    for p in REGISTRY.values():
        assert f'| `{p.name}` | {p.type_name} | {p.unit} | {p.default_str} |' in pages


def test_dataclass_fields_and_defaults_are_the_registry():
    p = UmbrellaParams()
    assert list(p.as_dict()) == list(SPECS)
    assert p.as_dict() == {n: s.default for n, s in SPECS.items()}
    assert defaults(MODEL).items() <= p.as_dict().items()
    assert pickle.loads(pickle.dumps(p)) == p          # a sweep ships it to other processes
    with pytest.raises(Exception):
        p.l1 = 1.0                                      # frozen


def test_config_file_holds_every_model_parameter_at_its_default():
    import os
    cfg = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                       'config', 'umbrella.yaml')
    values = load_params_file(cfg)
    assert set(values) == set(SPECS)
    assert UmbrellaParams.from_mapping(values) == UmbrellaParams()


@pytest.mark.parametrize('name', list(REGISTRY))
def test_every_range_is_enforced_at_its_bounds(name):
    """Just outside each finite bound is refused, naming the parameter; the default passes."""
    p = REGISTRY[name]
    p.check(p.default)
    for bound, open_, outward in ((p.low, p.low_open, -1.0), (p.high, p.high_open, 1.0)):
        if bound is None:
            continue
        outside = bound if open_ else bound + outward * (1 if p.type is int else
                                                         max(abs(bound), 1.0) * 1e-9)
        with pytest.raises(ValueError, match=f'parameter {name}='):
            p.check(p.type(outside))
    if p.choices:
        with pytest.raises(ValueError, match='one of'):
            p.check('nonsense')
    if p.type is float:
        with pytest.raises(ValueError, match='finite'):
            p.check(math.nan)


def test_coercion_names_the_parameter_and_keeps_types():
    assert coerce('v0', '-1') == -1.0 and isinstance(coerce('v0', 1), float)
    assert coerce('elements_per_segment', '2') == 2
    assert coerce('elements_per_segment', 3.0) == 3
    assert coerce('record', 'false') is False
    for name, value in (('elements_per_segment', 2.5), ('v0', True), ('v0', 'fast'),
                        ('model', 3), ('record', 'maybe')):
        with pytest.raises(ValueError, match=f'parameter {name}='):
            coerce(name, value)


@pytest.mark.parametrize('name, value', [('v0', 'fast'), ('v0', '-0.2x'),
                                         ('elements_per_segment', 'two'),
                                         ('v0', None), ('elements_per_segment', None)])
def test_a_value_that_is_no_number_is_told_so_in_the_parameters_words(name, value):
    """--set v0=fast, robot_description v0=fast: the node's words, not float()'s."""
    with pytest.raises(ValueError) as err:
        coerce(name, value)
    assert str(err.value) == f'parameter {name}={value!r}: must be a number'


def test_help_texts_come_from_the_registry():
    node_help = '\n'.join(parameter_help(REGISTRY.values()))
    for p in REGISTRY.values():
        assert f'  {p.name} ' in node_help and p.range_text() in node_help
    sim = make_parser()._subparsers._group_actions[0].choices['simulate']
    text = sim.format_help().split('parameters (--set NAME=VALUE')[1]
    for name in SPECS:
        assert f'  {name} ' in text
    for name in NODE_PARAMETERS:
        assert f'  {name} ' not in text
    model = next(a for a in sim._actions if a.dest == 'model')
    assert tuple(model.choices) == SPECS['model'].choices


@pytest.mark.parametrize('given, meant', [
    ('youngs_modulous', 'youngs_modulus'), ('v_0', 'v0'), ('durration', 'duration'),
    ('yield', 'yield_strength'), ('elements', 'elements_per_segment'),   # shortened
    ('l4', 'l3'),                                   # (of l1, l2, l3: difflib's tie)
    ('lenght', None), ('length', None),            # (was 'yield_strength', which no one meant)
])
def test_an_unknown_name_is_answered_with_the_name_meant_or_none(given, meant):
    from umbrella_sim.core.registry import closest_name, REGISTRY, unknown_names
    assert closest_name(given, REGISTRY) == meant
    said = unknown_names([given], REGISTRY)[0]
    assert said == (f'{given!r} (did you mean {meant!r}?)' if meant else repr(given))


def test_numpy_numbers_are_numbers():
    """A sweep's or a script's numpy values: np.int64(2) is the integer 2, np.float64 a double."""
    import numpy as np

    assert coerce('elements_per_segment', np.int64(2)) == 2
    assert type(coerce('elements_per_segment', np.int64(2))) is int
    assert coerce('v0', np.float64(-0.2)) == -0.2 and coerce('v0', np.int32(0)) == 0.0
    with pytest.raises(ValueError, match='must be a whole number'):
        coerce('elements_per_segment', np.float64(2.5))
    with pytest.raises(ValueError, match='must be a number'):
        coerce('v0', np.bool_(True).tolist())


def test_regenerating_up_to_date_pages_says_so(capsys, tmp_path):
    """param_docs on pages already up to date says so, instead of printing nothing."""
    import shutil

    pages = tmp_path / 'msg_docs'
    shutil.copytree(param_docs.msg_docs_dir(), pages)
    assert param_docs.main(['--dir', str(pages)]) == 0
    out = capsys.readouterr().out
    assert out.startswith('up to date: ') and all(p in out for p in param_docs.PAGES)
