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
The interface of the compiled step: _kernel.h, its parser (kernel.py), the library's ABI.

The header is the one declaration of what crosses between the library and Python; kernel.py
reads it strictly; load_kernel takes only a library built from it; the library exports
exactly the header's API.
"""
import ctypes
import os
import re
import shutil
import subprocess
import sys

import pytest

from umbrella_sim.core import kernel
from umbrella_sim.core.integrators import MidpointDAE
from umbrella_sim.core.kernel import HeaderError, parse_header
from umbrella_sim.core.model import UmbrellaModel
from umbrella_sim.core.outputs import STEP_FIELDS
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.tools.csv_output import CSV_COLUMNS

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
HEADER_TEXT = open(kernel.HEADER, encoding='utf-8').read()
VERSION = kernel.INTERFACE.version
CC = shutil.which(os.environ.get('CC', 'cc')) or shutil.which('gcc')
needs_kernel = pytest.mark.skipif(kernel.load_kernel() is None, reason='compiled kernel not built')
needs_cc = pytest.mark.skipif(CC is None, reason='no C compiler')

#: the per-step row as the offline CSV and the summary need it: the first 17 as they always
#: were (an 18th, the earlier stage-2 phase correction's energy term, went with it), then the 9
#: that spare building a Sample per step
STEP_ROW = ('time', 'stage', 'alpha1', 'alpha1_rate', 'sleeve_position', 'sleeve_velocity',
            'sleeve_force', 'tip_axial', 'tip_transverse', 'peak_stress_leaf',
            'peak_stress_leaf_x', 'peak_stress_link', 'peak_stress_link_x', 'kinetic_energy',
            'strain_energy', 'work', 'lock_energy_loss', 'alpha2', 'alpha2_rate',
            'alpha1_accel', 'stress_leaf_joint', 'stress_link_mid',
            'sleeve_reaction_x', 'sleeve_reaction_y', 'constraint_residual',
            'damping_dissipation', 'axial_stress')


def test_the_step_row_is_the_headers_list():
    assert STEP_FIELDS == kernel.STEP_FIELDS == STEP_ROW
    assert set(CSV_COLUMNS) == set(STEP_FIELDS)       # a CSV row needs no Sample
    assert kernel.SAMPLE_VECTOR[:4] == ('alpha1', 'alpha2', 'alpha1_rate', 'alpha2_rate')
    assert kernel.STATUS['ok'] == 0 and kernel.ADVANCE_DONE == 0
    # the structs the header declares, with the members Python sets
    assert {'n', 'stress_x', 'ref_link_frac'} <= {f for f, _ in kernel.ModelStruct._fields_}
    assert dict(kernel.AdvanceCall._fields_)['states'] is ctypes.POINTER(ctypes.c_double)


def test_the_parser_reads_the_header_and_its_spellings():
    again = parse_header(HEADER_TEXT.replace('double *q, *v', 'double*q,* v')
                         .replace('X(TIME, time)', 'X( TIME , time )'))
    assert again.names('UMBRELLA_STEP_FIELDS') == STEP_FIELDS
    assert again.abi_figures() == kernel.INTERFACE.abi_figures()
    assert set(again.functions) == set(kernel.INTERFACE.functions)


@pytest.mark.parametrize('change, why', [
    (('#endif', 'int global_counter;\n#endif'), 'a statement the parser does not read'),
    (('    int n_done, iterations;', '    float n_done, iterations;'), 'float'),
    (('    double residual; ', '    double residual[2]; '), 'declarator'),
    (('    X(STAGE, stage) \\', '    X(STAGE) \\'), 'a statement the parser does not read'),
    (('    X(STAGE, stage) \\', '    X(STAGE, Stage) \\'), 'a statement the parser does not read'),
    (('    X(STAGE, stage) \\', '    X(STAGE, time) \\'), 'a name twice in one list'),
    ((f'#define UMBRELLA_ABI_VERSION {VERSION}', '#define UMBRELLA_ABI_VERSION one'),
     'a statement the parser does not read'),
    ((f'#define UMBRELLA_ABI_VERSION {VERSION}\n', ''), 'no UMBRELLA_ABI_VERSION'),
    (('UMBRELLA_API void umbrella_free(Ctx *x);', 'void umbrella_free(Ctx *x);'),
     'a statement the parser does not read'),
    (('UMBRELLA_API void umbrella_free(Ctx *x);', 'UMBRELLA_API void umbrella_free(Ctx x);'),
     'a type the parser does not read'),
    (('UMBRELLA_API void umbrella_free(Ctx *x);', 'UMBRELLA_API void umbrella_new(Ctx *x);'),
     'declared twice'),
    (('typedef struct ElasticLaw ElasticLaw;', 'typedef struct ElasticLaw ElasticLaw'),
     "without its ';'"),
    (('#endif', '/* never closed\n#endif'), 'an unterminated comment'),
    (('X(Model, model)', 'X(Modell, model)'), 'not a struct declared'),
    (('#define UMBRELLA_API __attribute__((visibility("default")))', '#define UMBRELLA_API'),
     'a statement the parser does not read'),
])
def test_the_parser_refuses_what_it_cannot_read(change, why):
    old, new = change
    assert old in HEADER_TEXT
    with pytest.raises(HeaderError) as err:
        parse_header(HEADER_TEXT.replace(old, new, 1), 'the.h')
    assert 'the.h' in str(err.value)
    assert why in str(err.value)


@needs_kernel
def test_the_library_exports_only_the_headers_api():
    nm = shutil.which('nm')
    if nm is None:
        pytest.skip('no nm')
    out = subprocess.run([nm, '-D', '--defined-only', kernel.LIBRARY], capture_output=True,
                         text=True, check=True).stdout
    symbols = {line.split()[-1]: line.split()[-2] for line in out.splitlines()}
    symbols = {name: kind for name, kind in symbols.items() if name not in ('_init', '_fini')}
    assert set(symbols) == set(kernel.INTERFACE.functions), out
    assert set(symbols.values()) == {'T'}, out          # functions, no data


@needs_kernel
def test_the_library_reports_the_headers_abi():
    lib = kernel.load_kernel()
    n = len(kernel.INTERFACE.abi_figures())
    figures = (ctypes.c_int * n)()
    assert lib.umbrella_abi(figures, n) == kernel.INTERFACE.version
    assert list(figures) == kernel.INTERFACE.abi_figures()
    assert kernel.kernel_refusal() is None


def _build(tmp_path, name, source):
    src = tmp_path / f'{name}.c'
    src.write_text(source)
    lib = tmp_path / f'lib{name}.so'
    subprocess.run([CC, '-shared', '-fPIC', '-I', os.path.dirname(kernel.HEADER), '-o',
                    str(lib), str(src)], check=True, capture_output=True)
    return str(lib)


def _refused_once(path, capfd, *want):
    assert kernel.load_kernel(path) is None
    why = kernel.kernel_refusal(path)
    assert why is not None and path in why and all(w in why for w in want), why
    err = capfd.readouterr().err
    assert err.count(path) == 1 and 'numpy' in err
    assert kernel.load_kernel(path) is None      # refused once: no second warning
    assert path not in capfd.readouterr().err
    return why


@needs_cc
def test_a_library_of_another_abi_version_is_refused(tmp_path, capfd):
    path = _build(tmp_path, 'version', """
        #include "_kernel.h"
        #define SIZE(name, py) (int)sizeof(name),
        #define COUNT(name, py) name,
        int umbrella_abi(int *figures, int n) {
            const int all[] = {UMBRELLA_ABI_STRUCTS(SIZE) UMBRELLA_ABI_COUNTS(COUNT)};
            for (int k = 0; k < n && k < (int)(sizeof(all) / sizeof(all[0])); k++)
                figures[k] = all[k];
            return UMBRELLA_ABI_VERSION + 1;
        }""")
    _refused_once(path, capfd, f"ABI version {VERSION + 1}, the header's {VERSION}")


@needs_cc
def test_a_library_with_another_struct_size_is_refused(tmp_path, capfd):
    path = _build(tmp_path, 'sizes', """
        #include "_kernel.h"
        #define SIZE(name, py) (int)sizeof(name),
        #define COUNT(name, py) name,
        int umbrella_abi(int *figures, int n) {
            /* a Model of one int more, a step row of one field less (N_FIELDS: the
             * count after N_STATUS, which follows the structs' sizes) */
            const int all[] = {UMBRELLA_ABI_STRUCTS(SIZE) UMBRELLA_ABI_COUNTS(COUNT)};
            const int structs[] = {UMBRELLA_ABI_STRUCTS(SIZE)};
            const int fields = (int)(sizeof(structs) / sizeof(structs[0])) + 1;
            for (int k = 0; k < n && k < (int)(sizeof(all) / sizeof(all[0])); k++)
                figures[k] = all[k] - (k == fields) + 8 * (k == 0);
            return UMBRELLA_ABI_VERSION;
        }""")
    model = ctypes.sizeof(kernel.ModelStruct)
    _refused_once(path, capfd, f"sizeof(Model) {model + 8}, the header's {model}",
                  f"N_FIELDS (the step fields) {len(STEP_FIELDS) - 1}, the header's "
                  f'{len(STEP_FIELDS)}')


@needs_cc
def test_a_library_without_the_abi_query_is_refused(tmp_path, capfd):
    path = _build(tmp_path, 'old', 'int umbrella_step(void) { return 0; }\n')
    _refused_once(path, capfd, 'umbrella_abi')


@needs_kernel
def test_the_built_library_is_refused_if_the_header_says_otherwise(tmp_path, monkeypatch,
                                                                   capfd):
    """The header changed after the build (simulated): its figures no longer match."""
    copy = str(tmp_path / 'libumbrella_kernel.so')
    shutil.copy(kernel.LIBRARY, copy)
    figures = kernel.INTERFACE.abi_figures()
    figures[1] += 8                                  # AdvanceCall grew by a pointer
    monkeypatch.setattr(type(kernel.INTERFACE), 'abi_figures', lambda self: list(figures))
    size = ctypes.sizeof(kernel.AdvanceCall)
    _refused_once(copy, capfd, f"sizeof(AdvanceCall) {size}, the header's {size + 8}")


@needs_cc
def test_a_refused_library_leaves_the_numpy_path(tmp_path, monkeypatch, capfd):
    """UMBRELLA_SIM_KERNEL=auto steps in numpy (with the warning); compiled names the file."""
    path = _build(tmp_path, 'refused', 'int umbrella_abi(int *f, int n) { return -1; }\n')
    monkeypatch.setattr(kernel, 'LIBRARY', path)
    model = UmbrellaModel(UmbrellaParams())
    assert MidpointDAE(model, kernel='auto').backend == 'numpy'
    assert 'ABI version -1' in capfd.readouterr().err
    with pytest.raises(RuntimeError, match=re.escape(path)):
        MidpointDAE(model, kernel='compiled')
    monkeypatch.setattr(kernel, 'LIBRARY', str(tmp_path / 'absent.so'))
    with pytest.raises(RuntimeError, match='not built'):   # (absent: an install defect)
        MidpointDAE(model, kernel='auto')


@pytest.mark.slow      # a build of the kernel, ~6 s
@needs_cc
def test_a_regular_build_has_the_library_and_its_header_and_loads_them(tmp_path):
    """
    setup.py build (what a normal pip install packs) and the package loaded from there.

    libumbrella_kernel.so next to kernel.py, no CPython-tagged extension module, the header
    as package data; the kernel loads from the built tree.
    """
    src = tmp_path / 'src'
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(
        '.git', '.venv', 'build', '*.egg-info', '*.so', '__pycache__', '.pytest_cache',
        'tests', 'docs', 'bench'))
    lib = tmp_path / 'lib'
    subprocess.run([sys.executable, 'setup.py', '-q', 'build', '--build-base',
                    str(tmp_path / 'build'), '--build-lib', str(lib)], cwd=src, check=True,
                   capture_output=True, timeout=600)
    core = lib / 'umbrella_sim' / 'core'
    assert sorted(p.name for p in core.glob('*.so')) == ['libumbrella_kernel.so']
    assert (core / '_kernel.h').read_text() == HEADER_TEXT
    probe = ('from umbrella_sim.core import kernel; print(kernel.__file__); '
             'print(kernel.load_kernel() is not None)')
    run = subprocess.run([sys.executable, '-c', probe], cwd=tmp_path, capture_output=True,
                         text=True, env=dict(os.environ, PYTHONPATH=str(lib)), timeout=120)
    assert run.stdout.split() == [str(core / 'kernel.py'), 'True'], run.stdout + run.stderr
