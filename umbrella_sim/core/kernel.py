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
The binding of the compiled step: libumbrella_kernel.so, its interface read from _kernel.h.

_kernel.h declares once everything that crosses between the library and Python: the structs,
the status codes, the per-step output fields and the Sample-vector fields (X-macro lists)
and the API functions.  This module reads it at import (the header is installed with the
package) into

  * ctypes Structures of its structs (``ModelStruct``, ``AdvanceCall``, ``SampleCall``,
    ``ElasticData``) and the result and argument types of its functions;
  * the names of its lists: ``STEP_FIELDS`` (a per-step output row), ``SAMPLE_VECTOR`` (a
    Sample vector), ``STATUS`` (status codes),

so nothing is mirrored by hand, and the names need no library: the numpy reference path
(outputs.py) takes them from here too.  The parser reads the few statement forms the header
keeps to (listed at its top) and raises ``HeaderError`` naming the line of anything else.

``load_kernel`` loads exactly ``libumbrella_kernel.so`` beside this file (setup.py builds it
as a plain shared library exporting only the API) and asks it for its ABI version, struct
sizes and list lengths (``umbrella_abi``): a library whose figures differ from the header's,
e.g. one left from an older build, is refused with a message naming it and what differs,
printed once on stderr, and the simulator steps on the numpy path.

Why ctypes generated from the header, not cffi: cffi's ABI mode would read the same
declarations with its own C parser, a dependency for what a few regular expressions do on a
header written for it; its API mode builds a CPython extension module of its own at build
time, tied to the interpreter, beside setup.py's library.  ctypes is in the standard
library, and ``umbrella_abi`` checks what ctypes cannot: that the library was built from this
header.

``CompiledKernel`` holds one model handed to the library and every buffer the calls use;
``DynamicState`` is the state it advances (integrators.py steps the same states in numpy).

Why one module: the parser, the loader and ``CompiledKernel`` are the three sides of one
file, the header: what it declares, the library built from it, and the buffers laid out as it
says; apart, each would import the others' reading of it.
"""
from __future__ import annotations

import ctypes
from dataclasses import dataclass
import math
import os
import re
import sys

import numpy as np

from .model import ConstraintSet, UmbrellaModel

HERE = os.path.dirname(os.path.abspath(__file__))
#: the interface, installed with the package
HEADER = os.path.join(HERE, '_kernel.h')
#: the compiled step, built by setup.py (plain C, no Python module init)
LIBRARY = os.path.join(HERE, 'libumbrella_kernel.so')


class HeaderError(ValueError):
    """The header holds something the parser does not read (or lacks what it needs)."""


# ------------------------------------------------------------------ header parser
_SCALARS = {'int': ctypes.c_int, 'long': ctypes.c_long, 'double': ctypes.c_double}
_IDENT = r'[A-Za-z_]\w*'
_PY = r'[a-z_][a-z0-9_]*'        # a Python name of a list entry
#: the export attribute the library's API is marked with (setup.py: -fvisibility=hidden)
_EXPORT = '__attribute__((visibility("default")))'
_GUARD = 'UMBRELLA_KERNEL_H'


@dataclass(frozen=True)
class Interface:
    """What the header declares, as ctypes types and Python names."""

    version: int
    structs: dict          # C name -> ctypes.Structure subclass, in the header's order
    opaque: frozenset      # types Python holds only pointers to
    lists: dict            # X-macro list -> ((C name, Python name), ...)
    counts: dict           # enum count (N_FIELDS ...) -> the list it counts
    functions: dict        # API function -> (restype, argtypes)

    def names(self, name: str) -> tuple[str, ...]:
        """Return the Python names of the X-macro list name."""
        if name not in self.lists:
            raise HeaderError(f'{HEADER}: no list {name}')
        return tuple(py for _, py in self.lists[name])

    def abi_figures(self) -> list[int]:
        """Return what umbrella_abi must report after the version (_kernel.h)."""
        figures = [ctypes.sizeof(self.structs[c]) for c, _ in self.lists['UMBRELLA_ABI_STRUCTS']]
        return figures + [len(self.lists[self.counts[c]])
                          for c, _ in self.lists['UMBRELLA_ABI_COUNTS']]

    def abi_labels(self) -> list[str]:
        """Return a reader's name for each of abi_figures."""
        return ([f'sizeof({c})' for c, _ in self.lists['UMBRELLA_ABI_STRUCTS']]
                + [f"{c} (the {py.replace('_', ' ')})"
                   for c, py in self.lists['UMBRELLA_ABI_COUNTS']])


def _statements(text: str, path: str):
    """Yield (line, statement) of C text: a directive, or a declaration ending in ';'."""
    def blank(match):       # a comment becomes spaces, its newlines kept (line numbers)
        return re.sub(r'[^\n]', ' ', match.group())

    text = re.sub(r'/\*.*?\*/|//[^\n]*', blank, text, flags=re.S)
    if '/*' in text or '*/' in text:
        raise HeaderError(f'{path}: an unterminated comment')
    lines = text.split('\n')
    buf, start, depth, i = '', 0, 0, 0
    while i < len(lines):
        line = lines[i]
        i += 1
        if line.strip().startswith('#'):
            if buf.strip():
                raise HeaderError(f"{path}:{start}: a declaration without its ';': "
                                  f"{' '.join(buf.split())[:60]!r}")
            first = i
            while line.rstrip().endswith('\\'):          # a continued directive
                if i == len(lines):
                    raise HeaderError(f'{path}:{first}: a directive continued past the end')
                line = line.rstrip()[:-1] + ' ' + lines[i]
                i += 1
            yield first, ' '.join(line.split())
            continue
        for ch in line + '\n':
            if not buf.strip():
                start = i
            buf += ch
            depth += (ch == '{') - (ch == '}')
            if depth < 0:
                raise HeaderError(f"{path}:{i}: an unbalanced '}}'")
            if ch == ';' and depth == 0:
                yield start, ' '.join(buf.split())
                buf = ''
    if buf.strip():
        raise HeaderError(f"{path}:{start}: a declaration without its ';': {buf.strip()[:60]!r}")


def parse_header(text: str, path: str = '<header>') -> Interface:
    """
    Return the Interface that the header text declares.

    Raises HeaderError (naming path and line) on any statement not of the forms listed at
    the top of _kernel.h, an unknown type, a name declared twice, or a missing part.
    """
    version = export = None
    guard: list[str] = []
    structs: dict = {}
    opaque: set = set()
    lists: dict = {}
    entries: set = set()
    counts: dict = {}
    functions: dict = {}

    def fail(line, why, stmt):
        raise HeaderError(f'{path}:{line}: {why}: {stmt[:80]!r}')

    def new_name(line, name, stmt):
        if name in structs or name in opaque or name in lists or name in entries \
                or name in counts or name in functions:
            fail(line, f'{name} declared twice', stmt)

    def ctype(line, const, base, star, stmt, result=False):
        """Return the ctypes type of 'const? base *?'."""
        if base in _SCALARS:
            return ctypes.POINTER(_SCALARS[base]) if star else _SCALARS[base]
        if base == 'void' and result and not star and not const:
            return None
        if base in structs and star:
            return ctypes.POINTER(structs[base])
        if base in opaque and star:
            return ctypes.c_void_p
        fail(line, f"a type the parser does not read: {'const ' * bool(const)}{base}"
                   f"{' *' * bool(star)}", stmt)

    def declarators(line, decl, stmt):
        """[(name, ctypes type)] of 'const? base *?name, *?name...'."""
        m = re.fullmatch(rf'(const )?({_IDENT}) (.+)', decl)
        if not m:
            fail(line, f'not a declaration the parser reads ({decl!r})', stmt)
        out = []
        for part in m.group(3).split(','):
            d = re.fullmatch(rf'(\*?)({_IDENT})', part)
            if not d:
                fail(line, f'not a declarator the parser reads ({part.strip()!r})', stmt)
            out.append((d.group(2), ctype(line, m.group(1), m.group(2), d.group(1), stmt)))
        return out

    for line, text_ in _statements(text, path):
        # one spelling: no space next to ( ) { } , ; and '*' bound to what follows
        stmt = re.sub(r'\s*\*\s*', ' *', text_)
        stmt = re.sub(r'\s*([(){},;])\s*', r'\1', stmt)
        if stmt in (f'#ifndef {_GUARD}', f'#define {_GUARD}', '#endif'):
            guard.append(stmt)
        elif m := re.fullmatch(r'#define UMBRELLA_ABI_VERSION (\d+)', stmt):
            if version is not None:
                fail(line, 'UMBRELLA_ABI_VERSION declared twice', text_)
            version = int(m.group(1))
        elif stmt == f'#define UMBRELLA_API {_EXPORT}':
            export = True
        elif m := re.fullmatch(rf'#define (UMBRELLA_{_IDENT})\(X\)((?:X\({_IDENT},{_PY}\))+)',
                               stmt):
            pairs = tuple(re.findall(rf'X\(({_IDENT}),({_PY})\)', m.group(2)))
            for column in zip(*pairs):
                if len(set(column)) != len(column):
                    fail(line, 'a name twice in one list', text_)
            new_name(line, m.group(1), text_)
            lists[m.group(1)] = pairs
        elif m := re.fullmatch(rf'#define ({_IDENT})\(name,py\)(?:{_IDENT}##)?name,', stmt):
            new_name(line, m.group(1), text_)
            entries.add(m.group(1))
        elif m := re.fullmatch(rf'enum\{{({_IDENT})\(({_IDENT})\)({_IDENT})\}};', stmt):
            listed, entry, count = m.groups()
            if listed not in lists or entry not in entries:
                fail(line, 'an enum of a list or entry macro not declared before it', text_)
            new_name(line, count, text_)
            counts[count] = listed
        elif m := re.fullmatch(rf'typedef struct ({_IDENT}) \1;', stmt):
            new_name(line, m.group(1), text_)
            opaque.add(m.group(1))
        elif m := re.fullmatch(rf'typedef struct\{{(.+;)\}}({_IDENT});', stmt):
            name = m.group(2)
            new_name(line, name, text_)
            fields = [f for member in m.group(1).split(';')[:-1]
                      for f in declarators(line, member, text_)]
            if len({f for f, _ in fields}) != len(fields):
                fail(line, f'struct {name}: a member twice', text_)
            structs[name] = type(name, (ctypes.Structure,), {
                '_fields_': fields, '__doc__': f'{name} of _kernel.h (generated).'})
        elif m := re.fullmatch(rf'UMBRELLA_API (const )?({_IDENT}) (\*?)({_IDENT})\((.*)\);',
                               stmt):
            const, base, star, name, params = m.groups()
            new_name(line, name, text_)
            restype = ctype(line, const, base, star, text_, result=True)
            argtypes = [] if params == 'void' else [
                t for param in params.split(',') for _, t in declarators(line, param, text_)]
            functions[name] = (restype, argtypes)
        else:
            fail(line, 'a statement the parser does not read', text_)
    missing = [what for what, ok in (
        ('the include guard', guard == [f'#ifndef {_GUARD}', f'#define {_GUARD}', '#endif']),
        ('UMBRELLA_ABI_VERSION', version is not None), ('UMBRELLA_API', export),
        ('UMBRELLA_ABI_STRUCTS', 'UMBRELLA_ABI_STRUCTS' in lists),
        ('UMBRELLA_ABI_COUNTS', 'UMBRELLA_ABI_COUNTS' in lists),
        ('umbrella_abi', 'umbrella_abi' in functions)) if not ok]
    if missing:
        raise HeaderError(f"{path}: no {', no '.join(missing)}")
    for c, _ in lists['UMBRELLA_ABI_STRUCTS']:
        if c not in structs:
            raise HeaderError(f'{path}: UMBRELLA_ABI_STRUCTS names {c}, not a struct declared')
    for c, _ in lists['UMBRELLA_ABI_COUNTS']:
        if c not in counts:
            raise HeaderError(f'{path}: UMBRELLA_ABI_COUNTS names {c}, not an enum count')
    return Interface(version, structs, frozenset(opaque), lists, counts, functions)


def _read_header(path: str) -> Interface:
    with open(path, encoding='utf-8') as fh:
        return parse_header(fh.read(), path)


#: the interface of _kernel.h
INTERFACE = _read_header(HEADER)
ModelStruct = INTERFACE.structs['Model']
AdvanceCall = INTERFACE.structs['AdvanceCall']
SampleCall = INTERFACE.structs['SampleCall']
ElasticData = INTERFACE.structs['ElasticData']
#: the fields of one physics step's output row, in the order the compiled loop writes them
STEP_FIELDS = INTERFACE.names('UMBRELLA_STEP_FIELDS')
#: what a compiled Sample vector holds (sample_vector), then the fibre stress at every
#: stress point (top of every point, then bottom; leaf points first); the names are the
#: Sample's, but the sleeve reaction's two components
SAMPLE_VECTOR = INTERFACE.names('UMBRELLA_SAMPLE_FIELDS')
#: status code of each name (ok = 0)
STATUS = {name: code for code, name in enumerate(INTERFACE.names('UMBRELLA_STATUS_CODES'))}

# ------------------------------------------------------------------ status texts
#: the leaf angle at which the leaf lies along the axle: a stage-1 state there is a fault
#: (_kernel.c step_taken, UmbrellaSimulator._checked, RigidEngine._check)
ALPHA1_AXLE = math.pi / 2
AXLE_REASON = ('the leaf reached the axle (alpha1 = pi/2): the frame folded back past its '
               'start (v0 > 0 or a sleeve force below 0 drove it there), where the model has '
               'no stop')
_ERRORS = {'no_convergence': 'Newton did not converge',
           'non_finite': 'Newton iterate became non-finite',
           'singular': 'singular iteration matrix',
           'not_positive_definite': 'mass matrix not positive definite',
           'no_memory': 'out of memory', 'axle': AXLE_REASON}
#: the failure each status code stands for
KERNEL_ERRORS = {STATUS[name]: text for name, text in _ERRORS.items()}
#: umbrella_advance_call's codes that are not failures
ADVANCE_DONE, ADVANCE_CROSSING, ADVANCE_DIVERGED = (STATUS[k] for k in
                                                    ('ok', 'crossing', 'diverged'))


def kernel_error(status: int, t: float) -> str:
    """Return the text of a failed compiled step at t."""
    return f"{KERNEL_ERRORS.get(status, f'kernel status {status}')} at t = {t:.9g} s"


class ConvergenceError(RuntimeError):
    pass


@dataclass(frozen=True)
class DynamicState:
    t: float
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    multipliers: np.ndarray
    momentum: np.ndarray | None = None   # M(q) qd, carried to the next step when known
    dissipation: float = 0.0    # energy removed by structural damping since t = 0 (J)


# ------------------------------------------------------------------------ loading
_loaded: dict = {}      # path -> library, or None
_refused: dict = {}     # path -> why it was refused


def load_kernel(path: str | None = None):
    """
    Return the compiled step (a ctypes library, its functions typed), or None.

    path: the library (LIBRARY, the one setup.py built next to this file, if None).  None
    when it is not there, or when it does not match the header (``kernel_refusal`` says
    why; the reason is printed on stderr once).  The result is kept for the path.
    """
    path = LIBRARY if path is None else os.path.abspath(path)
    if path not in _loaded:
        lib, why = _open(path)
        _loaded[path] = lib
        if why is not None:
            _refused[path] = why
            print(f'umbrella_sim: {why}; stepping on the numpy reference path (slow) instead: '
                  'rebuild the kernel (python3 bootstrap.py setup, or pip install -e .)',
                  file=sys.stderr, flush=True)
    return _loaded[path]


def kernel_refusal(path: str | None = None) -> str | None:
    """Return why load_kernel refused the library at path (None: loaded, absent or not tried)."""
    return _refused.get(LIBRARY if path is None else os.path.abspath(path))


def _open(path: str):
    """Return (library, None), (None, None) if there is no file, or (None, why refused)."""
    if not os.path.exists(path):
        return None, None
    try:
        lib = ctypes.CDLL(path)
    except OSError as exc:
        return None, f'the compiled kernel {path} does not load ({exc})'
    try:
        abi = lib.umbrella_abi
    except AttributeError:
        return None, (f'the compiled kernel {path} is not of this interface: it has no '
                      f'umbrella_abi (ABI version {INTERFACE.version} of {HEADER} expected)')
    abi.restype, abi.argtypes = INTERFACE.functions['umbrella_abi']
    expected = INTERFACE.abi_figures()
    figures = (ctypes.c_int * (len(expected) + 1))(*([-1] * (len(expected) + 1)))
    version = abi(figures, len(figures))
    got = list(figures)
    differs = [f"ABI version {version}, the header's {INTERFACE.version}"] \
        if version != INTERFACE.version else []
    differs += [f"{label} {g}, the header's {e}"
                for label, g, e in zip(INTERFACE.abi_labels(), got, expected) if g != e]
    if not differs and got[-1] != -1:
        differs.append(f"more ABI figures than the header's {len(expected)}")
    if differs:
        return None, (f'the compiled kernel {path} does not match {HEADER}: '
                      + '; '.join(differs))
    for name, (restype, argtypes) in INTERFACE.functions.items():
        try:
            fn = getattr(lib, name)
        except AttributeError:
            return None, f'the compiled kernel {path} lacks {name} (declared in {HEADER})'
        fn.restype, fn.argtypes = restype, argtypes
    return lib, None


# ------------------------------------------------------------------ compiled kernel
_dp, _ip = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int)


def _dptr(a: np.ndarray):
    return a.ctypes.data_as(_dp)


class CompiledKernel:
    """
    Hold the model handed to _kernel.c once, and every buffer the calls use.

    Each buffer is allocated once and its ctypes pointer cached: a call converts only scalars.
    lib: load_kernel's; m: the UmbrellaModel; phi_tol: the constraint residual a Newton
    iteration must reach (integrators.PHI_TOLERANCE).
    """

    def __init__(self, lib, m: UmbrellaModel, phi_tol: float, capacity: int = 64):
        self.lib = lib
        self.phi_tol = phi_tol
        self.model = m
        n = m.n
        body = -np.ones(n, dtype=np.intc)
        body[m.s_leaf] = 0
        body[m.s_link] = 1
        bw, mff_band, k_band, w_band = m.banded_invariants()
        s_idx, s_top, s_bot, s_x, (n_leaf, n_link) = m.stress_rows()
        elastic = np.ascontiguousarray(m.elastic_indices, dtype=np.intc)
        link = m.link
        keep = {'c_full': np.zeros(n), 'g_full': np.zeros(n),
                'sbar': np.ascontiguousarray(link.s_bar),
                'isbar': np.ascontiguousarray([-link.s_bar[1], link.s_bar[0]]),
                'mff_band': np.ascontiguousarray(mff_band),
                'k_band': np.ascontiguousarray(k_band), 'w_band': np.ascontiguousarray(w_band),
                'stress_top': np.ascontiguousarray(s_top),
                'stress_bottom': np.ascontiguousarray(s_bot),
                'stress_x': np.ascontiguousarray(s_x)}
        keep['c_full'][m.s_leaf], keep['c_full'][m.s_link] = m.leaf.c, link.c
        keep['g_full'][m.s_leaf], keep['g_full'][m.s_link] = m.leaf.g, link.g
        ints = {'body': body, 'elastic_idx': elastic,
                'stress_idx': np.ascontiguousarray(s_idx)}
        self._keep = (keep, ints)  # the struct points into these arrays
        self.struct = ModelStruct(
            n=n, n_link=link.n_elastic, i_r2x=m.i_r2x, i_r2y=m.i_r2y, i_alpha2=m.i_alpha2,
            s_link=m.s_link.start, i_u_joint=m.i_u_joint, i_u_sleeve=m.i_u_sleeve,
            i_tip_u=m.i_tip_u, i_tip_v=m.i_tip_v, n_elastic=len(elastic), bw=bw,
            n_stress_leaf=n_leaf, n_stress_link=n_link, stress_width=s_idx.shape[1],
            l1=m.params.l1, l3=m.params.l3, y_stop=m.y_stop, j0_leaf=m.leaf.j0,
            j0_link=link.j0, pbar0=link.p_bar[0], link_mass=link.mass,
            **dict(zip(('ref_leaf_point', 'ref_link_element', 'ref_link_frac'),
                       m.reference_stress_points)),
            **{k: _dptr(v) for k, v in keep.items()},
            **{k: v.ctypes.data_as(_ip) for k, v in ints.items()})
        ctx = lib.umbrella_new(ctypes.byref(self.struct))
        if not ctx:
            # (umbrella_new: its buffers, or the LU of the constant elastic mass band)
            raise MemoryError('the compiled kernel could not be set up: out of memory, or a '
                              'singular elastic mass matrix')
        self._ctx = ctypes.c_void_p(ctx)
        self._free = lib.umbrella_free
        nc_max = 4 + len(elastic)
        # the state advanced in place, the last step's acceleration, then umbrella_sample_call of
        # the state each advance reaches (made by that call): views of one buffer, so that a
        # DynamicState of it and its Sample vector are one copy (state(), sample())
        self._points = len(m.leaf.stress_x) + len(m.link.stress_x)
        self._n, self._state_len = n, 4 * n + nc_max
        self._state_buf = np.zeros(self._state_len + len(SAMPLE_VECTOR) + 2 * self._points)
        self.q, self.v, self.p, self.accel = (self._state_buf[k * n:(k + 1) * n]
                                              for k in range(4))
        self.lam = self._state_buf[4 * n:self._state_len]
        self._final = self._state_buf[self._state_len:]
        self.acc = np.zeros(3)                     # work, lock loss, damping dissipation (J)
        self._ptr = {k: _dptr(getattr(self, k)) for k in ('q', 'v', 'p', 'lam', 'acc', 'accel')}
        self._its = ctypes.c_int(0)
        ptr = self._ptr
        # the state whose copy holds its Sample vector (the last advance's), that copy's
        # vector, and the constraint set it was made with
        self._final_cs = self._final_of = self._final_copy = None
        self._call = AdvanceCall(phi_tol=phi_tol, q=ptr['q'], v=ptr['v'], lam=ptr['lam'],
                                 p=ptr['p'], acc=ptr['acc'], accel=ptr['accel'],
                                 final=_dptr(self._final))
        self._call_ref = ctypes.byref(self._call)
        self._setting = None     # what _call holds besides the state and k0, n_steps
        #: stage 2's mode fit (set_mode_fit; None: none) and the step its shrinks are of
        self._fit, self._shrink_step = None, None
        self._set_capacity(capacity)
        self._made = None        # the DynamicState the buffers hold (see load)
        self._sample_buf = None
        # single-step outputs
        self._q1, self._v1, self._p1 = np.zeros(n), np.zeros(n), np.zeros(n)
        self._lam1 = np.zeros(nc_max)

    def __del__(self):
        ctx = getattr(self, '_ctx', None)
        if ctx is not None and ctx.value:
            self._free(ctx)
            self._ctx = None

    def set_mode_fit(self, fit) -> None:
        """Hand stage 2's mode fit (integrators.LockedModeFit) to the kernel."""
        # (the kernel keeps pointers to these arrays)
        damped = bool(np.any(fit.damping_change))
        arrays = [np.ascontiguousarray(a, dtype=float) for a in
                  (fit.modes, fit.shapes, fit.scale, fit.newton_shrink(fit.step),
                   fit.damping_change)]
        self._mode_fit = arrays
        self._fit, self._shrink_step = fit, fit.step
        ptrs = [_dptr(a) for a in arrays]
        if not damped:
            ptrs[4] = None
        if self.lib.umbrella_set_mode_fit(self._ctx, len(fit.scale), *ptrs):
            raise MemoryError("the compiled kernel could not allocate the stage-2 mode fit's "
                              'buffers')

    def _shrink_at(self, h: float) -> None:
        """
        Set the fit's Newton shrinks (the array the kernel points at) to a step h's.

        LockedModeFit.newton_shrink(h), as the numpy step's newton_update takes them (the
        step's, not the fit's own step's: a lock's part steps differ from it).
        """
        if self._fit is not None and h != self._shrink_step:
            self._mode_fit[3][...] = self._fit.newton_shrink(h)
            self._shrink_step = h

    def last_dissipation(self) -> float:
        """Return the damping dissipation of the last step taken (J; with the mode fit's)."""
        return float(self.lib.umbrella_dissipated(self._ctx))

    def set_elastic_law(self, law, law_ptr) -> None:
        """
        Step with the elastic law of _kernel_nonlinear.c at law_ptr (nonlinear.CompiledLaw).

        The context points at it: the law object is kept alive as ``elastic_law``.
        """
        self.lib.umbrella_set_law(self._ctx, law_ptr)
        self.elastic_law = law

    def _set_capacity(self, cap: int) -> None:
        self.out = np.zeros((len(STEP_FIELDS), cap))
        self._out_ptr = _dptr(self.out)
        self.capacity = cap
        self._call.out, self._call.cap = self._out_ptr, cap
        # the state rows (AdvanceCall.states: q, q', the fibre stresses), made when asked for
        self.states_out = None
        self._call.states, self._states_on = None, False

    def _want_states(self, states: bool) -> None:
        """Have the advance write its state rows into states_out, or not (NULL)."""
        if states and self.states_out is None:
            self.states_out = np.zeros((2 * self._n + 2 * self._points, self.capacity))
            self._states_ptr = _dptr(self.states_out)
        if states != self._states_on:
            self._call.states = self._states_ptr if states else None
            self._states_on = states

    def load(self, s: DynamicState, work: float, lock_loss: float) -> None:
        """Take s as the state to advance from (nothing to copy if it is the last one made)."""
        self.acc[0], self.acc[1] = work, lock_loss
        self.acc[2] = s.dissipation   # accumulated with a damped elastic law (nonlinear.py)
        if s is self._made:
            return
        self._made = None
        self.q[:] = s.q
        self.v[:] = s.qd
        self.lam[:len(s.multipliers)] = s.multipliers
        if s.momentum is not None:
            self.p[:] = s.momentum
        else:
            self.lib.umbrella_momentum(self._ctx, self._ptr['q'], self._ptr['v'], self._ptr['p'])

    def advance(self, cs: ConstraintSet, k0: int, h: float, n_steps: int, force: float,
                tol: float, max_iter: int, div_tol: float, states: bool = False):
        """
        Take n_steps grid steps from the loaded state.

        n_steps grid steps from the loaded state; returns (status, steps done, Newton
        iterations, residual of a diverged step).  Rows are in self.out[:, :steps], and with
        states the state rows in self.states_out[:, :steps] (AdvanceCall.states).
        """
        if n_steps > self.capacity:
            self._set_capacity(max(n_steps, 2 * self.capacity))
        if states or self._states_on:
            self._want_states(states)
        call = self._call
        call.k0, call.n_steps = k0, n_steps
        self._shrink_at(h)
        setting = (cs.locked, cs.rigid, h, force, tol, max_iter, div_tol)
        if setting != self._setting:    # usually the same as last time: no ctypes setattr
            self._setting = setting
            (call.locked, call.rigid, call.h, call.force, call.tol, call.max_iter,
             call.div_tol) = setting
        status = self.lib.umbrella_advance_call(self._ctx, self._call_ref)
        done = call.n_done
        if done:      # _final holds the Sample outputs of the state state() makes next
            self._final_cs, self._final_of, self._final_copy = cs, None, None
        return status, done, call.iterations, call.residual

    def state(self, t: float, nc: int) -> DynamicState:
        """Return the advanced state; advancing from it next time needs no load."""
        # a read-only copy (immutable: a Sample of it shares its arrays); via bytes: setting
        # a copy's writeable flag costs as much again as the copy
        b, n = np.frombuffer(self._state_buf.tobytes()), self._n
        # once per publication: the frozen dataclass's per-field __init__ costs 3 us, so its
        # __dict__ is set whole (outputs.build_frozen's way)
        self._made = made = object.__new__(DynamicState)
        object.__setattr__(made, '__dict__', {
            't': t, 'q': b[:n], 'qd': b[n:2 * n], 'qdd': b[3 * n:4 * n],
            'multipliers': b[4 * n:4 * n + nc], 'momentum': b[2 * n:3 * n],
            'dissipation': self.acc.item(2)})
        if self._final_cs is not None and self._final_of is None:
            self._final_of, self._final_copy = self._made, b[self._state_len:]
        return self._made

    def sample(self, s: DynamicState, cs: ConstraintSet) -> np.ndarray:
        """
        Return the Sample vector of a state with its momentum (_kernel.c umbrella_sample_call).

        A read-only array of its own: SAMPLE_VECTOR, then the top and bottom fibre stress at
        every stress point (leaf first).  The state an advance reached has it from that call
        (in the copy that holds the state's arrays).
        """
        if s is self._final_of and cs is self._final_cs:   # the advance that made s left it
            return self._final_copy
        if self._sample_buf is None:
            out = np.zeros(len(self._final))
            ptr = self._ptr
            # one call struct on the buffers (the state last made), one for any other state
            calls = [SampleCall(out=_dptr(out)) for _ in range(2)]
            calls[0].q, calls[0].v, calls[0].p, calls[0].lam = (ptr['q'], ptr['v'], ptr['p'],
                                                                ptr['lam'])
            self._sample_buf = (out, calls, [ctypes.byref(c) for c in calls], [None, None])
        out, calls, refs, flags = self._sample_buf
        which = 0 if s is self._made else 1          # the buffers hold it: no conversion
        call = calls[which]
        if which:
            lam = np.zeros(len(self.lam))
            lam[:len(s.multipliers)] = s.multipliers
            arrays = [np.ascontiguousarray(a, dtype=float) for a in (s.q, s.qd, s.momentum)]
            arrays.append(lam)
            call.q, call.v, call.p, call.lam = (_dptr(a) for a in arrays)
        if flags[which] is not cs:                   # (a ctypes setattr costs ~0.2 us)
            call.locked, call.rigid = cs.locked, cs.rigid
            flags[which] = cs
        self.lib.umbrella_sample_call(self._ctx, refs[which])
        out = out.copy()
        out.flags.writeable = False
        return out

    def find_crossing(self, s: DynamicState, h: float, force: float, cs: ConstraintSet,
                      tol: float, max_iter: int, div_tol: float, event_tol: float):
        """
        Return (status, state, step length, Newton iterations, residual) of the lock instant.

        The Illinois root find of y_H = y_stop over the step length in (0, h] from s (stage
        deploying), in compiled code (_kernel.c umbrella_find_crossing).  state is the best
        trial (status 0), else None and the step length / residual of the failing trial.
        """
        q0 = np.ascontiguousarray(s.q, dtype=float)
        v0 = np.ascontiguousarray(s.qd, dtype=float)
        lam0 = np.zeros(len(self.lam))
        lam0[:len(s.multipliers)] = s.multipliers
        p0 = np.empty(len(q0))
        if s.momentum is not None:
            p0[:] = s.momentum
        else:
            self.lib.umbrella_momentum(self._ctx, _dptr(q0), _dptr(v0), _dptr(p0))
        dt, res = ctypes.c_double(0.0), ctypes.c_double(0.0)
        status = self.lib.umbrella_find_crossing(
            self._ctx, int(cs.rigid), _dptr(q0), _dptr(v0), _dptr(lam0), _dptr(p0), h, force,
            tol, self.phi_tol, max_iter, div_tol, event_tol, _dptr(self._q1), _dptr(self._v1),
            _dptr(self._lam1), _dptr(self._p1), ctypes.byref(dt), ctypes.byref(res),
            ctypes.byref(self._its))
        if status != 0:
            return status, None, dt.value, self._its.value, res.value
        v = self._v1.copy()
        state = DynamicState(s.t + dt.value, self._q1.copy(), v, (v - v0) / dt.value,
                             self._lam1[:len(s.multipliers)].copy(), self._p1.copy())
        return status, state, dt.value, self._its.value, res.value

    def step(self, s: DynamicState, h, force, cs: ConstraintSet, tol, max_iter):
        q0 = np.ascontiguousarray(s.q, dtype=float)
        v0 = np.ascontiguousarray(s.qd, dtype=float)
        lam0 = np.ascontiguousarray(s.multipliers, dtype=float)
        p0 = None if s.momentum is None else np.ascontiguousarray(s.momentum, dtype=float)
        self._shrink_at(h)
        status = self.lib.umbrella_step(
            self._ctx, int(cs.locked), int(cs.rigid), _dptr(q0), _dptr(v0),
            _dptr(lam0), None if p0 is None else _dptr(p0), h, force, tol, self.phi_tol,
            max_iter, _dptr(self._q1), _dptr(self._v1), _dptr(self._lam1), _dptr(self._p1),
            ctypes.byref(self._its))
        if status != 0:
            raise ConvergenceError(kernel_error(status, s.t + h))
        v = self._v1.copy()
        return (DynamicState(s.t + h, self._q1.copy(), v, (v - v0) / h,
                             self._lam1[:len(lam0)].copy(), self._p1.copy()), self._its.value)
