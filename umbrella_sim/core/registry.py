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
Parameters: one registry from which everything else is derived.

``REGISTRY`` holds every parameter once: name, type, default, unit, range, when a change
applies, and what it means.  From it come the ``UmbrellaParams`` and ``ControllerConfig``
records and their checks (params.py), the nodes' ROS parameter descriptors
(ros/parameters.py), ``umbrella_node --help``, the CLI's ``--set``, and the tables of
msg_docs/parameters.md, node_parameters.md and deploy_controller.md (tools/param_docs.py).
Every value is SI (m, kg, s, N, Pa, rad).  The same names are the ROS parameters of
``umbrella_node`` and the keys of ``config/umbrella.yaml`` (a ROS 2 params file).
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import numbers
import re
from typing import Any, Mapping


MODELS = ('flexible', 'flexible-nonlinear', 'rigid-fe', 'rigid')
#: smallest physics step (s): the finest step of the convergence studies is 3.125e-7 s; at
#: 1e-9 s a 1 kHz publication period took 10^6 steps and their outputs' memory
MIN_PHYSICS_STEP = 1e-7
#: smallest yield strain yield_strength / youngs_modulus accepted: the softest metals yield at
#: ~1.4e-4 (annealed pure aluminium, 10 MPa / 69 GPa) to 3e-4 (lead); a yield strength typed
#: in MPa (500 for Al 7075-T6) is 7e-9 of the modulus in Pa
MIN_YIELD_STRAIN = 1e-5
LOCKS = ('auto', 'energy', 'plastic')

# when a change made at runtime (ros2 param set) takes effect
RESET = 'reset'            # on ~/reset (the model or the initial state changes)
NOW = 'now'                # at the next publication
START = 'start'            # read-only: fixed for the life of the node

# which part of the program a parameter belongs to
MODEL = 'model'            # the physics (UmbrellaParams), also the offline CLI
INPUT = 'input'            # the physics' input, also in UmbrellaParams
NODE = 'node'              # umbrella_node only
CONTROLLER = 'controller'  # deploy_controller only (it also takes the model's geometry)


@dataclass(frozen=True)
class Param:
    """One parameter: everything any interface needs to know about it."""

    name: str
    type: type                      # noqa: A003 (float | int | str | bool)
    default: Any
    unit: str                       # SI unit; "-" for none
    doc: str                        # what it is, one or two sentences
    low: float | None = None        # range; None = unbounded on that side
    high: float | None = None
    low_open: bool = False          # True: value > low (else value >= low)
    high_open: bool = False         # True: value < high (else value <= high)
    choices: tuple = ()             # allowed values of a str parameter
    applies: str = RESET            # RESET | NOW | START
    group: str = MODEL              # MODEL | INPUT | NODE | CONTROLLER
    rule: str = ''                  # cross-parameter rule, checked in validate()
    default_text: str = ''          # how the docs show the default, when repr is unclear

    @property
    def default_str(self) -> str:
        if self.default_text:
            return self.default_text
        if self.type is float:
            return _num(self.default)
        if self.type is bool:
            return str(self.default).lower()
        return str(self.default)

    @property
    def type_name(self) -> str:
        return {float: 'double', int: 'integer', str: 'string', bool: 'bool'}[self.type]

    def range_text(self) -> str:
        """Return the range as docs and messages write it: '> 0', '1 … 64', '(0, π/2)'."""
        if self.choices:
            return ' | '.join(self.choices)
        lo, hi = self.low, self.high
        if lo is None and hi is None:
            return 'finite' if self.type is float else 'any'
        if hi is None:
            return f"{'>' if self.low_open else '>='} {_num(lo)}"
        if lo is None:
            return f"{'<' if self.high_open else '<='} {_num(hi)}"
        if not (self.low_open or self.high_open):
            return f'{_num(lo)} … {_num(hi)}'
        return (f"{'(' if self.low_open else '['}{_num(lo)}, {_num(hi)}"
                f"{')' if self.high_open else ']'}")

    def check(self, value: Any, what: str = '') -> None:
        """
        Raise ValueError naming the parameter unless value is in this parameter's range.

        what replaces 'parameter NAME' in the message (e.g. 'sleeve force command').
        """
        what = what or f'parameter {self.name}'
        if self.choices:
            if value not in self.choices:
                raise ValueError(f"{what}={value!r}: must be one of {', '.join(self.choices)}")
            return
        if self.type is not float and self.type is not int:
            return
        if not math.isfinite(value):
            raise ValueError(f'{what}={value}: must be a finite number')
        lo, hi = self.low, self.high
        below = lo is not None and (value <= lo if self.low_open else value < lo)
        above = hi is not None and (value >= hi if self.high_open else value > hi)
        if not (below or above):
            return
        if self.type is int and lo is not None and hi is not None:
            raise ValueError(f'{what}={value}: must be between {_num(lo)} and {_num(hi)}')
        if below:
            raise ValueError(f"{what}={value}: must be {'>' if self.low_open else '>='} "
                             f'{_num(lo)}{self._degrees_hint(value)}')
        raise ValueError(f"{what}={value}: must be {'<' if self.high_open else '<='} "
                         f'{_num(hi)}{self._degrees_hint(value)}')

    def _degrees_hint(self, value: float) -> str:
        """Say an angle is in rad when the value, read as degrees, is in range (else '')."""
        if self.unit != 'rad' or value == 0.0:
            return ''
        try:
            self.check(math.radians(value))
        except ValueError:
            return ''
        return f' (an angle in rad: {value:g} degrees is {math.radians(value):.7g} rad)'

    def exact(self, value: Any) -> Any:
        """
        Return a number as this parameter's numeric type where it converts exactly, else value.

        The one rule every interface follows: an int for a double is that double (``-p
        v0:=-1``, ``UmbrellaParams(v0=-1)``, ``v0: -1`` in a params file), a whole finite
        double for an integer that integer (``elements_per_segment: 2.0``).  Anything else is
        left as it is, for the type check to name.
        """
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return value
        if self.type is float and isinstance(value, int):
            return float(value)
        if (self.type is int and isinstance(value, float) and math.isfinite(value)
                and value.is_integer()):
            return int(value)
        return value

    def coerce(self, value: Any) -> Any:
        """Convert a CLI / YAML / ROS value to this type, naming the parameter on failure."""
        try:
            if self.type is str:
                if not isinstance(value, str):
                    raise ValueError('must be a string')
                return value
            if self.type is bool:
                if isinstance(value, bool):
                    return value
                text = str(value).strip().lower()
                if text in ('true', '1', 'yes', 'on'):
                    return True
                if text in ('false', '0', 'no', 'off'):
                    return False
                raise ValueError('must be true or false')
            if isinstance(value, bool):
                raise ValueError('must be a number')
            try:
                number = float(value) if isinstance(value, str) or self.type is float else value
            except (TypeError, ValueError):     # (float()'s words name no parameter type)
                raise ValueError('must be a number') from None
            if not isinstance(number, numbers.Real):    # (numpy's integers are, as int)
                raise ValueError('must be a number')
            if self.type is int:
                if isinstance(number, float) and not number.is_integer():
                    raise ValueError('must be a whole number')
                return int(number)
            return number
        except (TypeError, ValueError, OverflowError) as exc:
            raise ValueError(f'parameter {self.name}={value!r}: {exc}') from None


def _num(x: float) -> str:
    for v, text in ((math.pi / 2, 'π/2'), (math.pi, 'π')):
        if x == v:
            return text
    text = f'{x:g}' if float(f'{x:g}') == x else f'{x:.8g}'   # a bound shown is the bound
    return re.sub(r'e\+?(-?)0*(\d)', r'e\1\2', text)


_P = Param
REGISTRY: dict[str, Param] = {p.name: p for p in (
    # geometry (Fig. 3.4): leaf O-O''-G, link O''-H, sleeve H slides on the axle (Y axis)
    _P('l1', float, 0.5, 'm', "leaf length from the hinge O to the link joint O''",
       low=0.0, low_open=True, high=1e3),
    _P('l2', float, 0.5, 'm', "leaf length from the link joint O'' to the tip G",
       low=0.0, low_open=True, high=1e3),
    _P('l3', float, 0.5, 'm', "link length from O'' to the sleeve joint H",
       low=0.0, low_open=True, high=1e3),
    # cross section: a square of height b gives A = b^2, I = b^4/12; explicit A and I win
    _P('section_height', float, 0.01, 'm',
       'height b of the square cross-section (A = b², I = b⁴/12); also sets the outer '
       'fibre at b/2', low=0.0, high=10.0,
       rule='> 0 unless `area` and `second_moment_of_area` are given; with them, '
            '`second_moment_of_area` ≤ `area`·(b/2)²'),
    _P('area', float, 0.0, 'm²', 'cross-section area A; 0 = derive from `section_height`',
       low=0.0, high=100.0, rule='give with `second_moment_of_area`'),
    _P('second_moment_of_area', float, 0.0, 'm⁴',
       'second moment of area I; 0 = derive from `section_height`; without b the outer '
       'fibre is at √(3I/A)', low=0.0, high=100.0, rule='give with `area`'),
    # material: Al 7075-T6 (thesis ch. 6)
    _P('youngs_modulus', float, 72.0e9, 'Pa', "Young's modulus E of leaf and link",
       low=0.0, low_open=True, high=1e15),
    _P('density', float, 2770.0, 'kg/m³', 'mass density ρ of leaf and link',
       low=0.0, low_open=True, high=1e6),
    _P('yield_strength', float, 500.0e6, 'Pa',
       'yield strength, for the stress ratio peak |σ| / yield',
       low=0.0, low_open=True, high=1e15,
       rule='≥ 10⁻⁵·`youngs_modulus` (a yield strain of at least 10⁻⁵: in Pa, not MPa)'),
    # configuration
    # at α1 = π/2 the sleeve has no lever on the leaf (dy_H/dα1 = 0, the toggle): a v0 there
    # is an unbounded leaf rate (infinite energies within 1e-7 rad of it) and a force no torque
    _P('alpha0', float, 0.49 * math.pi, 'rad',
       'initial leaf angle α1 from +X (folded)', low=0.0, low_open=True,
       high=math.pi / 2 - 1e-3, default_text='0.49π = 1.5393804',
       rule='> `alpha_deployed`; l1·|cos alpha0| < l3; ≤ π/2 − 0.001, where the sleeve '
            'still has a lever on the leaf'),
    _P('alpha_deployed', float, math.pi / 12.0, 'rad',
       'leaf angle at full deployment; the stop S is at y = l1 sin α + √(l3² − l1² cos² α)',
       low=0.0, low_open=True, high=math.pi / 2, high_open=True,
       default_text='π/12 = 0.2617994', rule='l1·|cos alpha_deployed| < l3'),
    _P('v0', float, -0.2, 'm/s', 'initial sleeve velocity along +Y (negative deploys)',
       low=-1e3, high=1e3),
    _P('sleeve_force', float, 0.0, 'N',
       'sleeve force F_H at the start, along −Y (pushes toward deployment); at runtime '
       'command it on the `sleeve_force` topic', low=-1e9, high=1e9, group=INPUT,
       rule='≥ `sleeve_force_min`; ≤ the axial load the link can carry, min(π² E I / l3², '
            'A σ_yield): 2368.7 N for the thesis data (topic_sleeve_force.md)'),
    _P('sleeve_force_min', float, 0.0, 'N',
       'smallest sleeve force accepted (topic, force profile, `sleeve_force`): 0 = push-only, '
       "the thesis's sleeve; < 0 = a drive that can also hold the sleeve back (brake), "
       'which a soft closed-loop latch needs: pushing alone never takes kinetic energy out '
       'before the lock', low=-1e9, high=0.0,
       rule="≥ −`area`·`yield_strength`, the link's load in tension"),
    # model and numerics
    _P('model', str, 'flexible', '-',
       'flexible: Case 1 then Case 2; flexible-nonlinear: the same with geometrically exact '
       'beams (co-rotational Euler–Bernoulli elements in the floating frames: large '
       'rotations, small strains, thesis §7.2; a fibre may turn up to 90° from its body '
       'frame, the run stops there and warns past 80°; compiled, 1.3–2× the cost of a '
       "flexible step; docs/validation_nonlinear.md; with `ribs` ≥ 2 every rib's beams "
       "co-rotational in the rib's plane with out-of-plane bending and torsion as small "
       'rotations in the co-rotated frame, warned past 0.1 rad, compiled, '
       "1.2–1.8× the linear ribs' cost a step: docs/umbrella3d_nonlinear.md); "
       'rigid-fe: Case 3 (elastic coordinates constrained); rigid: closed-form two-angle '
       'model', choices=MODELS),
    _P('elements_per_segment', int, 1, '-',
       "beam elements N on each of O–O'', O''–G and O''–H (1 = the thesis's 3-element "
       'model, 2 = 6-element)', low=1, high=64),
    _P('lock', str, 'auto', '-',
       'velocity redistribution at the lock: energy (thesis 5.2.2: keeps the kinetic '
       'energy), plastic (a perfectly inelastic stop), or auto = the one that applies to '
       'the model: energy for flexible and flexible-nonlinear, plastic for the rigid models '
       '(a rigid mechanism stopped at a point keeps no energy to redistribute)',
       choices=LOCKS),
    _P('time_step', float, 0.0, 's',
       'physics step of the integrator; 0 = chosen for the run. Stage 2 (flexible) '
       "takes the mesh's step: the largest 0.1 ms / k "
       "(k = 1 .. 64) at which the locked frame's modes that carry all but 1 % of the "
       "stage-2 stress crest of the mesh's lock are resolved (ωh ≤ 1.5 with "
       "`phase_correction`, 0.35 without): with the thesis's frame, at N = 1 / 2 / 4 / 8 "
       'elements a segment, 0.1 ms / 33.3 / 20 / 7.7 µs with the energy lock (the '
       'default), 0.1 ms / 25 / 16.7 / 7.7 µs with the plastic lock. Stage 1 (the '
       'deployment), whose figures do not need the stage-2 step, takes 0.2 ms at N = 1 and '
       "2 (finer meshes: the mesh's step), the grid's step (inputs and outputs), stage 2 then "
       'k physics steps a grid step. '
       'Measured against '
       'converged runs (docs/validation.md, step convergence): the deploy time, stage-1 '
       'and stage-2 peak stresses, stage-2 period and amplitude and the stage-2 tip series '
       'within 1 mm of every studied case (N = 1-8, V0 = -0.2 and -0.5 m/s, both locks). '
       'Past a stage-2 tip deflection of 7 % of the leaf (V0 = -0.5: 12-16 %) the modes '
       "couple and stage 2 of flexible (the umbrella of N ribs too: its worst rib's lock) "
       'takes the step its lock needs, k physics steps a grid step (every mode '
       'carrying stage-2 stress resolved, and at most 0.1 ms (7 % / deflection)^1.5: 25 µs '
       'at N = 1, V0 = -0.5); the grid, inputs and outputs stay at the grid step. '
       'flexible-nonlinear: 0 = 0.1 ms at every mesh, its real-time step (its own rule, '
       'ωh ≤ 0.35, would take 4 µs at N = 4: `step_follows_mesh` takes it), at which its '
       "stage-2 period and amplitude meet an independent geometrically exact model's "
       '(docs/validation_nonlinear.md) and its stage-2 peak stresses are not resolved '
       "('coarse step' says so)",
       low=0.0, high=0.01, rule=f'0, or >= {MIN_PHYSICS_STEP:g} s'),
    _P('step_follows_mesh', bool, False, '-',
       "with a `time_step` > 0 (or flexible-nonlinear's 0, which stands for 0.1 ms): true = "
       "flexible: stage 1 at `time_step` (the grid; coarser than 0.25 ms: 'coarse stage-1 "
       "step') and stage 2 in the substeps its lock "
       "needs, the largest `time_step` / k the mesh's stage-2 stresses need or finer (the "
       'rule of `time_step` 0, below this ceiling); flexible-nonlinear: the physics step '
       "is the largest `time_step` / k the mesh's stage-2 stresses need, in both stages "
       "(a lock that needs a finer one says so: 'coarse step'); "
       'false = `time_step` as it is (a run whose step leaves more than 1 % of its '
       "stage-2 stress crest to unresolved modes says so: 'coarse step'). The node still "
       'takes the largest step ≤ it that divides 1/`publish_rate`'),
    _P('phase_correction', bool, True, '-',
       "stage 2 of flexible (also damped; not flexible-nonlinear): the locked frame's "
       'modes with ω·h ≤ 1.5 are integrated exactly in period, amplitude and damping ratio '
       '(a velocity map per mode, S = I + Φ diag(s − 1) Uᵀ, inside the energy-consistent '
       'midpoint step; the physical energy T + V is conserved to round-off); the plain '
       "midpoint rule lengthens a mode's period by (ωh)²/12, which puts the 1–10·10³ rad/s "
       'modes out of phase within 0.5 s (tip series off by 4–13 mm at 0.1 ms); false = '
       'the plain energy-consistent midpoint rule (docs/validation.md)'),
    _P('damping_ratio', float, 0.0, '-',
       'structural damping ratio ζ of the first stage-2 mode: strain-rate (Kelvin–Voigt, '
       'stiffness-proportional Rayleigh) damping β = 2ζ/ω1, ω1 the first mode of the locked '
       'frame linearised at full deployment, mode i gets ζω_i/ω1; the dissipated energy is '
       'reported (`energy` topic); 0 = undamped (the thesis); no effect on rigid-fe and '
       'rigid; the umbrella of N ribs (ribs ≥ 2, model flexible) damps its 3D beams alike '
       '(axial, both bendings and torsion: C = βK with the β of its planar rib, so each '
       "rib's first in-plane mode has ζ, its out-of-plane modes ζω_i/ω1; the `energy` topic's "
       '`damping_dissipation_J`); its co-rotational ribs (flexible-nonlinear) damp their '
       'co-rotated strain rates with the same β (C(q) = βBᵀDB, as the planar flexible-nonlinear '
       'model)',
       low=0.0, high=1.0, high_open=True),
    # the node
    _P('publish_rate', float, 100.0, 'Hz',
       'publication rate (sim time) of joint_states, tip_deflection, peak_stress, energy, '
       'markers and clock; the physics step is the largest step ≤ `time_step` that '
       'divides 1/`publish_rate`, so publications fall on steps', low=1.0, high=5000.0,
       group=NODE),
    _P('real_time_factor', float, 1.0, '-',
       'sim seconds per wall second: 1 = wall-clock pace, 0 = as fast as possible',
       low=0.0, high=1000.0, applies=NOW, group=NODE),
    _P('start_paused', bool, False, '-',
       'true = start paused at t = 0 (the first state published, the physics held) until '
       "`~/pause` false, as a simulator's paused start: a test or a controller can connect "
       'and then start the run', applies=START, group=NODE),
    _P('lockstep', bool, False, '-',
       'true = the simulation waits for its controller: from the first `sleeve_force` '
       'command on, while deploying, each publication period starts only once a command '
       '(accepted or refused) has arrived since the previous joint_states, and acts from '
       "that period's first step; a closed loop's result then does not depend on process "
       'scheduling, and `real_time_factor` is the fastest pace (the wait for a command '
       'counts toward the period it lets run: a controller that answers within the period '
       'costs no wall time). Locked or faulted (the '
       'sleeve force no longer moves the frame) and after ~/reset until a command, the '
       'node runs on its own. false = real time, a command acts from the next period '
       'boundary after it arrives', applies=NOW, group=NODE),
    _P('duration', float, 0.0, 's',
       'sim time at which the node exits (code 0): at the first publication at or after it '
       '(0.255 s at publish_rate 100 Hz: 0.26 s); 0 = run until stopped',
       low=0.0, high=1e9, applies=NOW, group=NODE),
    _P('record', bool, True, '-',
       'record every topic, command and the parameters to an MCAP bag (see recording.md); '
       'false = no recording', applies=START, group=NODE),
    _P('record_path', str, '', '-',
       'bag directory to record to (NAME/NAME_0.mcap + metadata.yaml; a leading ~ is the '
       'home directory); must not exist; '
       "'' = a new directory umbrella_<namespace>_YYYY_MM_DD-HH_MM_SS in the working "
       'directory, as ros2 bag record does', applies=START, group=NODE,
       default_text='""'),
    _P('marker_magnification', float, 1.0, '-',
       'deformation magnification of the markers', low=0.0, high=1e6, applies=NOW,
       group=NODE),
    _P('marker_rate', float, 30.0, 'Hz',
       'publication rate (sim time) of markers: every k-th publication, k = '
       'round(`publish_rate` / `marker_rate`) ≥ 1, t = 0 included; RViz draws at 30–60 Hz '
       'and a MarkerArray costs more than all other topics together',
       low=0.1, high=5000.0, group=NODE),
    _P('frame_prefix', str, '', '-',
       'prefix of the frame ids of joint_states, tip_deflection and markers (umbrella_base, '
       "tip); 'a1/' matches robot_state_publisher's frame_prefix when several antennas "
       'share one TF tree', applies=START, group=NODE, default_text='""'),
    # deploy_controller (msg_docs/deploy_controller.md): read once, at start
    _P('target_time', float, 1.0, 's',
       'deploy time to reach, from the first push to the lock (sim time)',
       low=0.0, low_open=True, high=1e4, applies=START, group=CONTROLLER),
    _P('max_force', float, 20.0, 'N',
       'largest sleeve force commanded (pushes along -Y); the plan starts with it',
       low=0.0, low_open=True, high=1e9, applies=START, group=CONTROLLER),
    _P('min_force', float, 0.0, 'N',
       'smallest sleeve force commanded; < 0 lets the controller hold the sleeve back (the '
       'node must accept it: its `sleeve_force_min` <= `min_force`); 0 = push-only',
       low=-1e9, high=0.0, applies=START, group=CONTROLLER),
    _P('lock_rate', float, 0.0, 'rad/s',
       "leaf angular speed |alpha1'| at the stop; 0 = a quarter of the mean rate "
       '(alpha0 - alpha_deployed) / `target_time`', low=0.0, applies=START, group=CONTROLLER),
    _P('creep_angle', float, 0.0, 'rad',
       'last stretch of alpha1 before the stop planned at `lock_rate` (< alpha0 - '
       'alpha_deployed); 0 = brake right up to the stop, which keeps the needed force steady '
       'there: a command held through a stall of the loop then stays right',
       low=0.0, applies=START, group=CONTROLLER),
    _P('deceleration', float, 0.0, 'rad/s²',
       'planned leaf deceleration before the creep; 0 = 4 (alpha0 - alpha_deployed) / '
       '`target_time`², capped at half of what `min_force` can do near the stop (the rest is '
       'kept for feedback)', low=0.0, applies=START, group=CONTROLLER),
    _P('velocity_gain', float, 8.0, '1/s', 'feedback gain on the leaf rate error',
       low=0.0, applies=START, group=CONTROLLER),
    _P('position_gain', float, 36.0, '1/s²',
       'feedback gain on the leaf angle error; it keeps the deploy time',
       low=0.0, applies=START, group=CONTROLLER),
)}


#: the physics' parameters (the fields of UmbrellaParams), in registry order
SPECS: dict[str, Param] = {n: p for n, p in REGISTRY.items() if p.group in (MODEL, INPUT)}
#: parameters of umbrella_node only
NODE_PARAMETERS: dict[str, Param] = {n: p for n, p in REGISTRY.items() if p.group == NODE}
#: parameters of deploy_controller only (it also takes the model's geometry: SPECS)
CONTROLLER_PARAMETERS: dict[str, Param] = {n: p for n, p in REGISTRY.items()
                                           if p.group == CONTROLLER}
#: keys of a params file that belong to the node, not the model: the offline CLI skips them
NODE_ONLY_PARAMS = tuple(NODE_PARAMETERS) + ('use_sim_time',)


def defaults(group: str | None = None) -> dict:
    """Name -> default of every parameter of umbrella_node (or of one group)."""
    if group is None:
        return {n: p.default for n, p in REGISTRY.items() if p.group != CONTROLLER}
    return {n: p.default for n, p in REGISTRY.items() if p.group == group}


def node_defaults() -> dict:
    return {n: p.default for n, p in NODE_PARAMETERS.items()}


def parameter_help(params, width: int = 99) -> list[str]:
    """Return --help lines: name, default, unit, range and when it applies, then the doc."""
    import textwrap

    when = {RESET: 'on reset', NOW: 'at once', START: 'read-only'}
    out = []
    for p in params:
        out.append(f'  {p.name:<22} {p.type_name:<7} default {p.default_str}, {p.unit}, '
                   f'{p.range_text()}' + (f"; {p.rule.replace('`', '')}" if p.rule else '')
                   + f'; applies {when[p.applies]}')
        out += textwrap.wrap(p.doc.replace('`', ''), width, initial_indent=' ' * 6,
                             subsequent_indent=' ' * 6)
    return out


def coerce(name: str, value: Any) -> Any:
    """Convert a CLI / YAML / ROS value to the parameter's type, naming it on failure."""
    return REGISTRY[name].coerce(value)


def check_types(values: Mapping[str, Any], spec: 'Param | None' = None) -> None:
    """
    Refuse a typed value (YAML: a params file, a sweep SPEC) of another type than the node's.

    As the node takes a params file: a double takes a number (an int is that double), an
    integer a whole number (2.0 is 2, as the node takes it), a bool true/false, a string a
    string; "-0.5" in quotes is a string.  (Text from a command line, -p or --set, is
    parsed instead: Param.coerce.)  spec: every value's specification (else the registry's
    of its name; the umbrella's: params3d.check_umbrella_types).
    """
    for name, value in values.items():
        p = spec or REGISTRY.get(name)      # model and node parameters alike
        if p is None:
            continue
        if type(p.exact(value)) is not p.type:
            raise ValueError(f'parameter {name}={value!r}: must be of type {p.type_name}, '
                             f'got {_yaml_type(value)}')


def _yaml_type(value: Any) -> str:
    return {bool: 'bool', int: 'integer', float: 'double', str: 'string'}.get(
        type(value), type(value).__name__)


def check_node_parameters(values: Mapping[str, Any]) -> dict:
    """Coerce and range-check node parameters (name -> value); return them typed."""
    out = {}
    for name, value in values.items():
        spec = NODE_PARAMETERS[name]
        out[name] = spec.coerce(value)
        spec.check(out[name])
    return out


#: where the node's parameters are listed, the umbrella of N ribs' too (an unknown name's
#: error says it: the node, simulate --set, a sweep and a params file alike)
NODE_PARAMETERS_LISTED = ('umbrella_node --help and in msg_docs/parameters.md (the umbrella '
                          "of N ribs': msg_docs/umbrella3d_parameters.md)")


def closest_name(name: str, known) -> str | None:
    """
    Return the known name a misspelt or shortened one most likely means, else None.

    A name the given one begins (the shortest: 'yield' is yield_strength), else the closest
    by difflib's ratio (at least 0.5: 'l4' is l3) among names of the same first letter: a
    match across letters named what no one meant ('lenght' is not yield_strength).  A known
    name with a prefix (rib.tip_mass, rib1.tip_mass) is also matched by what follows its
    first dot, and the shortest name of that ending answers: a rib's own value given
    without its prefix, 'tip_mass' or 'hinge_colomb', means rib.tip_mass, rib.hinge_coulomb.
    """
    import difflib

    known = sorted(known)
    longer = [k for k in known if k.startswith(name) and name]
    if longer:
        return min(longer, key=len)
    ending: dict = {}           # what follows a prefixed name's first dot -> its shortest name
    for k in known:
        tail = k.partition('.')[2]
        if tail and (tail not in ending or len(k) < len(ending[tail])):
            ending[tail] = k
    if name in ending:
        return ending[name]
    plain = [k for k in known if k[:1] == name[:1]]
    close = difflib.get_close_matches(
        name, plain + [t for t in ending if t[:1] == name[:1] and t not in plain], n=1,
        cutoff=0.5)
    if not close:
        return None
    return close[0] if close[0] in plain else ending[close[0]]


def unknown_names(names, known) -> list[str]:
    """Return "'name' (did you mean 'closest'?)" for each of names not in known, sorted."""
    known = set(known)
    out = []
    for name in sorted(set(names) - known):
        close = closest_name(name, known)
        out.append(f'{name!r}' + (f' (did you mean {close!r}?)' if close else ''))
    return out


def check_known_names(names, known, source: str,
                      listed: str = NODE_PARAMETERS_LISTED) -> None:
    """
    Refuse unknown parameter names, suggesting the closest known one.

    ValueError naming every name of `names` not in `known`, with a "did you mean"
    suggestion (difflib) for each; `source` says where the names came from (e.g. "params
    file config/x.yaml", "-p", "--set"); `listed` where the known ones are listed.
    """
    problems = unknown_names(names, known)
    if problems:
        raise ValueError(f"{source}: unknown parameter{'s' if len(problems) > 1 else ''} "
                         f"{', '.join(problems)}; known parameters are listed by {listed}")
