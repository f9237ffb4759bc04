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
The binding of the whole umbrella's compiled step (_kernel3d.c, declared in _kernel.h).

``CompiledStep3D`` hands an ``UmbrellaModel3D`` to the library once (``Model3D``: indices,
the bodies' points, weights and shapes, stiffness and constant mass; with a moving base the
rib frames, the hub radius, the bus inertia and the total mass) and keeps every buffer a
call uses: the state advanced in place, the rows of the steps taken (``Advance3DCall``)
and, with a driven base, the drive's bus coordinates and rates at the steps' ends
(integrator3d.BaseDrive.profile: the drive's one rule, evaluated here for a run of steps).
``step`` is ``MidpointUmbrella.step`` (the numpy reference) in one call; ``advance`` takes up
to n grid steps of ``UmbrellaSimulator3D.step`` in one call, stopping before the step in
which the sleeve reaches the stop (the lock is Python's); its rows end with each step's
stress figures (``figures``, _kernel3d_figures.h: Record3D's rule, which Record3D then takes
as they are; the co-rotational ribs' components from their elements' strains,
umbrella3d_set_corotational_stress).  The library is the planar kernel's
(kernel.load_kernel: ABI-checked against the header).
"""
from __future__ import annotations

import ctypes

import numpy as np

from .model3d import N_RIB_ROWS, UmbrellaModel3D
from .state3d import ConvergenceError3D, State3D, StepWork
from ..kernel import INTERFACE, kernel_error, STATUS

Model3DStruct = INTERFACE.structs['Model3D']
Advance3DCall = INTERFACE.structs['Advance3DCall']
_dp = ctypes.POINTER(ctypes.c_double)
#: the channels of the rows' stress figures (outputs3d.STRESS_NAMES)
FIGURE_CHANNELS = 5


def _ptr(a: np.ndarray):
    return a.ctypes.data_as(_dp)


def row_layout(model: UmbrellaModel3D, figures: bool = False) -> dict:
    """
    Return name -> (slice of an output row, shape of a step's value) (Advance3DCall).

    figures: the rows end with each rib's stress figures (umbrella3d_set_stress):
    stress_top (ribs, 5: the largest of each channel of outputs3d.STRESS_NAMES over the
    step) and stress_at (ribs, 5, 2: where, body code and x).
    """
    nr, n = model.n_ribs, model.n_rib
    parts = (('t', ()), ('qr', (nr, n)), ('qs', (model.n_shared,)), ('vr', (nr, n)),
             ('vs', (model.n_shared,)), ('lam_r', (nr, N_RIB_ROWS)),
             ('lam_s', (model.n_shared_rows,)), ('stuck', (nr,)), ('kinetic', ()),
             ('strain', ()), ('work_force', ()), ('work_friction', (nr,)), ('iterations', ()),
             ('factorisations', ()), ('work_damping', ()), ('work_drive', ()))
    if model.params.base == 'free':
        parts += (('linear_momentum', (3,)), ('angular_momentum', (3,)))
    if figures:
        parts += (('stress_top', (nr, FIGURE_CHANNELS)), ('stress_at', (nr, FIGURE_CHANNELS, 2)))
    out, k = {}, 0
    for name, shape in parts:
        size = int(np.prod(shape)) if shape else 1
        out[name] = (slice(k, k + size), shape)
        k += size
    return out


class CompiledStep3D:
    """The compiled step of one model (drive: its BaseDrive); see the module docstring."""

    def __init__(self, lib, model: UmbrellaModel3D, tolerance: float, phi_tolerance: float,
                 max_iterations: int, carry_steps: int = 1, drive=None, figures: bool = True,
                 damping_beta: float = 0.0):
        if (drive is None) != (model.params.base != 'prescribed'):
            raise ValueError('the compiled 3D step: a drive is for a prescribed base only')
        self.lib, self.model, self.drive = lib, model, drive
        self.tolerance, self.phi_tolerance = tolerance, phi_tolerance
        self.max_iterations = max_iterations
        m = model
        nr, n = m.n_ribs, m.n_rib
        # what of M does not move: the twist's inertia, each body's elastic block
        const_mass = np.zeros((nr, n, n))
        for b in m.bodies:
            e = slice(b.offset + b.n_trans + 1, b.offset + b.n)
            const_mass[:, b.slice, b.slice] = b.twist_mass
            const_mass[:, e, e] += np.einsum('rp,rpie,rpif->ref', b.w, b.shape, b.shape)
        leaf, link = m.leaf, m.link
        arrays = {
            'l1': m.l1, 'l3': m.l3,
            'coulomb': np.array([r.hinge_coulomb for r in m.ribs], dtype=float),
            'viscous': np.array([r.hinge_viscous for r in m.ribs], dtype=float),
            'stick_until': np.array([r.stick_until for r in m.ribs], dtype=float),
            'stick_torque': np.array([r.stick_torque for r in m.ribs], dtype=float),
            'stiffness': m.stiffness, 'const_mass': const_mass,
            'leaf_x': leaf.x, 'leaf_w': leaf.w, 'leaf_shape': leaf.shape,
            'link_x': link.x, 'link_w': link.w, 'link_shape': link.shape,
            'bus_inertia': m.bus_inertia, 'rib_frames': m.psi}
        self._arrays = {k: np.ascontiguousarray(v, dtype=float) for k, v in arrays.items()}
        self.struct = Model3DStruct(
            n_ribs=nr, n_rib=n, n_shared=m.n_shared, n_shared_rows=m.n_shared_rows,
            **{f'i_{k}': getattr(m, f'i_{k}') for k in (
                'a1', 'rx', 'ry', 'rz', 'a2', 'u1', 'w1', 's1', 'p1', 's2', 'p2', 'uh', 'wh',
                't0')},
            i_tip_v=m.i_tip[1], i_tip_w=m.i_tip[2],
            leaf_points=leaf.x.shape[1], leaf_elastic=leaf.shape.shape[-1],
            link_points=link.x.shape[1], link_elastic=link.shape.shape[-1],
            link_offset=link.offset, sleeve_mass=m.sleeve_mass, y_stop=m.y_stop,
            regularisation=m.params.hinge_regularisation, carry_steps=carry_steps,
            hub_radius=m.hub_radius, total_mass=m.total_mass, damping_beta=damping_beta,
            **{k: _ptr(v) for k, v in self._arrays.items()})
        law = model.compiled_law()
        if law is not None:      # the co-rotational ribs (_kernel3d_nonlinear.h)
            self._law = {k: np.ascontiguousarray(v, dtype=np.intc if k == 'nl_places' else float)
                         for k, v in law.items() if isinstance(v, np.ndarray)}
            for k, v in law.items():
                if isinstance(v, np.ndarray):
                    v = self._law[k]
                    v = v.ctypes.data_as(ctypes.POINTER(ctypes.c_int)) if k == 'nl_places' \
                        else _ptr(v)
                setattr(self.struct, k, v)
        ctx = lib.umbrella3d_new(ctypes.byref(self.struct))
        if not ctx:
            raise MemoryError('the compiled 3D step could not be set up: out of memory')
        self._ctx = ctypes.c_void_p(ctx)
        self._free = lib.umbrella3d_free
        self.buf = {'qr': np.zeros((nr, n)), 'qs': np.zeros(m.n_shared),
                    'vr': np.zeros((nr, n)), 'vs': np.zeros(m.n_shared),
                    'lam_r': np.zeros((nr, N_RIB_ROWS)), 'lam_s': np.zeros(m.n_shared_rows),
                    'pr': np.zeros((nr, n)), 'ps': np.zeros(m.n_shared),
                    'stuck': np.zeros(nr)}
        #: the buffers of a State3D's arrays, in its fields' order (reached)
        self._state_buffers = [self.buf[k] for k in ('qr', 'qs', 'vr', 'vs', 'lam_r', 'lam_s',
                                                     'stuck', 'pr', 'ps')]
        #: the State3D the buffers hold (the last call's, as reached returned it), else None
        self._in_buffers = None
        self.call = Advance3DCall(max_iter=max_iterations, tol=tolerance,
                                  phi_tol=phi_tolerance,
                                  **{k: _ptr(v) for k, v in self.buf.items()})
        self._call_ref = ctypes.byref(self.call)
        self._drive = (np.zeros((1, 6)), np.zeros((1, 6)))
        #: the mode fit's arrays (set_mode_fit; None: no fit), and the step its Newton
        #: shrinks are those of (_shrink_at)
        self._fit, self._shrink_step = None, None
        self.set_figures(figures)

    def __del__(self):
        ctx = getattr(self, '_ctx', None)
        if ctx is not None and ctx.value:
            self._free(ctx)
            self._ctx = None

    def set_figures(self, on: bool) -> None:
        """
        Say whether advance's rows carry the steps' stress figures (``figures``).

        On: the library computes them (umbrella3d_set_stress: Record3D's rule), if it can;
        off: Record3D computes them from the rows' states.
        """
        if on:
            on = self._set_stress()
        else:
            self.lib.umbrella3d_set_stress(self._ctx, 0, 0, None, None, None)
        #: advance's rows carry the steps' stress figures (stress_top, stress_at)
        self.figures = on
        self.layout = row_layout(self.model, on)
        self.row_len = self.call.row_len = max(s.stop for s, _ in self.layout.values())
        self._set_capacity(1)

    def _set_stress(self) -> bool:
        """Hand the stress recovery to the library (umbrella3d_set_stress); True if taken."""
        m = self.model
        x = np.ascontiguousarray(np.concatenate([m.leaf_bodies[0].stress_x,
                                                 m.link_bodies[0].stress_x]), dtype=float)
        if m.compiled_law() is not None:
            return self._set_corotational_stress(x)
        blocks = []
        for bodies in (m.leaf_bodies, m.link_bodies):       # (model3d.stress_blocks' rows)
            blocks.append(np.ascontiguousarray(np.stack([np.stack([
                getattr(b, name) for name in ('stress_axial', 'stress_bend_z', 'stress_bend_y',
                                              'stress_shear')]) for b in bodies]), dtype=float))
        status = self.lib.umbrella3d_set_stress(self._ctx, blocks[0].shape[2], blocks[1].shape[2],
                                                _ptr(blocks[0]), _ptr(blocks[1]), _ptr(x))
        return status == STATUS['ok']

    def _set_corotational_stress(self, x: np.ndarray) -> bool:
        """
        Hand the co-rotational ribs' stress recovery to the library; True if taken.

        umbrella3d_set_corotational_stress: the components from the elements' co-rotated
        strains (corotational3d.RibCorotationalStrain.stress_blocks' rule) with each rib's
        E, E c and G c_t, at both ends of every element (x: each point's, leaf then link).
        """
        m = self.model
        sec = m.strain.section                          # (each (ribs, 1))
        moduli = np.ascontiguousarray(np.concatenate([
            sec['youngs'], sec['youngs'] * sec['fibre'], sec['shear'] * sec['torsion_fibre']],
            1), dtype=float)
        leaf = 2 * m.strain.n_leaf
        status = self.lib.umbrella3d_set_corotational_stress(
            self._ctx, leaf, len(x) - leaf, _ptr(moduli), _ptr(x))
        return status == STATUS['ok']

    def set_mode_fit(self, fit) -> None:
        """
        Fit the locked steps' modes from now on: a stage2fit.RibFits, BusFit or WholeFit.

        The call keeps pointers to the arrays (Advance3DCall.fit_*, bus_*): each rib's
        LockedModeFit padded to the most modes a rib has (s = 1, shrink 0: no change), with
        a free bus's correction (BusFit: its rows a, b, c over every coordinate, and its
        damping share's), or the whole free system's (fit_whole: rows over every
        coordinate); a damped fit's damping changes (fit_damping, the damped beams':
        damping3d.py).  Each mode's Newton shrink is the step's a call takes (_shrink_at).
        """
        c = self.call
        bus = getattr(fit, 'bus', None)
        if bus is None and fit.whole:
            f = fit.fit
            self._fit = tuple(np.ascontiguousarray(a) for a in (
                f.modes, f.shapes, f.scale, f.newton_shrink(f.step), f.damping_change))
            c.fit_whole, r = 1, len(f.scale)
            self._shrink_fits = [f]
        else:
            ribs = fit if bus is None else fit.ribs
            nr, n = self.model.n_ribs, self.model.n_rib
            r = max(len(f.scale) for f in ribs.fits)
            u, phi = np.zeros((nr, r, n)), np.zeros((nr, r, n))
            scale, shrink, damping = np.ones((nr, r)), np.zeros((nr, r)), np.zeros((nr, r))
            for k, f in enumerate(ribs.fits):
                m = len(f.scale)
                u[k, :m], phi[k, :m] = f.modes, f.shapes
                scale[k, :m], shrink[k, :m] = f.scale, f.newton_shrink(f.step)
                damping[k, :m] = f.damping_change
            self._fit = (u, phi, scale, shrink, damping)
            c.fit_whole = 0
            self._shrink_fits = ribs.fits
        self._shrink_step = self._shrink_fits[0].step
        # (u and phi with each rib's or the whole fit's rows transposed: modal_correction's)
        self._fit_t = tuple(np.ascontiguousarray(np.swapaxes(a, -1, -2)) for a in self._fit[:2])
        c.fit_u, c.fit_phi, c.fit_scale, c.fit_shrink = (_ptr(a) for a in self._fit[:4])
        c.fit_ut, c.fit_phit = (_ptr(a) for a in self._fit_t)
        # (a damped fit's damping change: the damped beams' only, damping3d.py)
        c.fit_damping = _ptr(self._fit[4]) if self.struct.damping_beta else None
        c.fit_modes = r
        # (a free bus's correction: rows and their transposes, modal_correction's in_t)
        self._bus = () if bus is None else tuple(
            np.ascontiguousarray(a) for a in (bus.a, bus.b, bus.c, bus.a.T, bus.b.T, bus.c.T))
        c.bus_rank = len(bus.a) if bus is not None else 0
        if bus is not None:
            c.bus_a, c.bus_b, c.bus_c, c.bus_at, c.bus_bt, c.bus_ct = (_ptr(a) for a in self._bus)
        newton = getattr(fit, 'newton', None)
        self._bus_newton = () if newton is None else (newton.a, np.ascontiguousarray(newton.b.T))
        c.bus_newton_rank = len(newton.a) if newton is not None else 0
        if newton is not None:
            c.bus_newton_a, c.bus_newton_bt = (_ptr(a) for a in self._bus_newton)
        damp = getattr(fit, 'damping', None)
        self._bus_damp = () if damp is None else (damp.a, damp.b)
        c.bus_damp_rank = len(damp.a) if damp is not None else 0
        if damp is not None:
            c.bus_damp_a, c.bus_damp_b = (_ptr(a) for a in self._bus_damp)

    def _shrink_at(self, h: float) -> None:
        """
        Set the fit's Newton shrinks (the array the call points at) to those of a step h.

        (Nothing to do without a fit, or where they are already h's.)

        LockedModeFit.newton_shrink(h), as the numpy step's newton_update takes them: each
        mode's d / (block + d) for the step taken (its block 1 + (omega h)^2 / 4 and the
        damping's share h (c_w - c) / 2 are the step's), not the fit's own step, which a
        step differs from where the run takes a part of one (the lock's) or a caller another
        (a stage-2 fit of substeps stepped at the grid's step: there the fit's step's
        shrinks took 4.7 to 5.7 Newton iterations a step against 2.2 to 3.0).
        """
        if self._fit is None or h == self._shrink_step:
            return
        shrink = self._fit[3]
        if shrink.ndim == 1:
            shrink[...] = self._shrink_fits[0].newton_shrink(h)
        else:
            for k, f in enumerate(self._shrink_fits):
                shrink[k, :len(f.scale)] = f.newton_shrink(h)
        self._shrink_step = h

    # ---------------------------------------------------- stage-2 substeps (substeps3d.py)
    def set_tolerance(self, tolerance: float) -> None:
        """Set Newton's increment tolerance of the steps from now on (a stage-2 substep's)."""
        self.tolerance = self.call.tol = tolerance

    def _set_capacity(self, cap: int) -> None:
        self.out = np.zeros((cap, self.row_len))
        self.call.out = _ptr(self.out)
        #: every physics step's tips of a folded call (Advance3DCall.tips: physics_tips)
        self.tips_out = np.zeros((cap, self.model.n_ribs, 2))
        self._tips_ptr = _ptr(self.tips_out)
        self.capacity = cap
        self._views: dict = {}          # rows' views of out, by count

    def _set_drive(self, times: np.ndarray) -> None:
        """Hand the drive's bus coordinates and rates at the steps' ends to the call."""
        if self.drive is None:
            return
        g, gd, _ = self.drive.profile(times)
        self._drive = (np.ascontiguousarray(g), np.ascontiguousarray(gd))
        self.call.drive_q, self.call.drive_v = (_ptr(a) for a in self._drive)

    def _load(self, s: State3D, force: float, locked: bool, h: float) -> None:
        b = self.buf
        if s is not self._in_buffers:     # (the state the last call reached: there already)
            for k in ('qr', 'qs', 'vr', 'vs', 'lam_r', 'lam_s', 'stuck'):
                b[k][...] = getattr(s, k)
            if s.pr is not None:
                b['pr'][...], b['ps'][...] = s.pr, s.ps
        self._in_buffers = None     # (the call moves the buffers on)
        self._shrink_at(h)
        c = self.call
        c.have_p, c.t, c.h, c.force, c.locked = int(s.pr is not None), s.t, h, force, int(locked)

    def reached(self, t: float | None = None) -> State3D:
        """
        Return the state the buffers hold after a call (copies; a next call starts there).

        t: its time (the grid's, of a call's substeps: UmbrellaSimulator3D.advance); None:
        the call's own.
        """
        self._in_buffers = state = State3D(self.call.t if t is None else t,
                                           *[a.copy() for a in self._state_buffers])
        return state

    def rows(self, count: int) -> dict:
        """Return the last call's first count rows by name (views of out: steps first)."""
        views = self._views.get(count)
        if views is None:       # (made once a count: out is the same buffer every call)
            views = self._views[count] = {}
            for name, (sl, shape) in self.layout.items():
                view = self.out[:count, sl]
                view.shape = (count,) + shape           # (a view, never a copy)
                views[name] = view
        return dict(views)

    def step(self, s: State3D, h: float, force: float, locked: bool):
        """Return (State3D, StepWork) of one step of length h (MidpointUmbrella.step's)."""
        self._load(s, force, locked, h)
        self._set_drive(np.array([s.t + h]))
        self.call.single = 1
        status = self.lib.umbrella3d_advance(self._ctx, self._call_ref)
        if status != STATUS['ok']:
            raise status_error(status, s.t + h)
        row = self.rows(1)
        work = StepWork(float(row['work_force'][0]), row['work_friction'][0].copy(),
                        float(row['work_drive'][0]),
                        int(row['iterations'][0]), int(row['factorisations'][0]),
                        float(row['work_damping'][0]))
        return self.reached(), work

    def advance(self, s: State3D, k0: int, h: float, n_steps: int, force: float,
                locked: bool, crest_from_state: bool = False, fold: int = 1):
        """
        Take up to n_steps grid steps t_k -> (k + 1) h from s at t_k0 (``advance_rows``).

        Return (status, steps done, rows (dict of the steps' figures), the state reached).
        """
        status, done, rows = self.advance_rows(s, k0, h, n_steps, force, locked,
                                               crest_from_state, fold)
        return status, done, rows, (self.reached() if done else s)

    def advance_rows(self, s: State3D, k0: int, h: float, n_steps: int, force: float,
                     locked: bool, crest_from_state: bool = False, fold: int = 1):
        """
        Take up to n_steps grid steps t_k -> (k + 1) h from s at t_k0; the state: ``reached``.

        crest_from_state: the first step's stress figures take their crests from s (the
        record continues in the same stage: Record3D.crest_continues), else its own values.
        fold: the rows of each run of fold steps folded into one (Advance3DCall.fold:
        substeps3d.fold_substeps3d's rule, in the kernel), a last shorter run its own; every
        step's tips then kept apart (``physics_tips``).

        Return (status, steps done, rows (dict of the steps' figures)).  Status 'ok',
        'crossing' (the next step reaches the stop unlocked: not taken), or a failure code
        (kernel.STATUS) of the step not taken.
        """
        if n_steps > self.capacity:
            self._set_capacity(max(n_steps, 2 * self.capacity))
        self._load(s, force, locked, h)
        if self.drive is not None:
            self._set_drive(np.arange(k0 + 1, k0 + n_steps + 1) * h)
        c = self.call
        c.single, c.k0, c.n_steps = 0, k0, n_steps
        c.crest_from_state, c.fold = int(crest_from_state), fold
        c.tips = self._tips_ptr if fold > 1 else None
        status = self.lib.umbrella3d_advance(self._ctx, self._call_ref)
        done = c.n_done
        return status, done, self.rows(-(-done // fold))

    def physics_tips(self, count: int) -> np.ndarray:
        """
        Return the last folded call's first count physics steps' tips (a view of tips_out).

        (steps, ribs, 2): each rib's in-plane v and out-of-plane w of its leaf tip (the
        rows' qr[..., i_tip[1:]]) at the end of every step, which the folded rows keep of
        their grid steps' last only.
        """
        return self.tips_out[:count]


def status_error(status: int, t: float) -> ArithmeticError:
    """Return the error of a failed compiled step (state3d.ConvergenceError3D)."""
    return ConvergenceError3D(kernel_error(status, t))
