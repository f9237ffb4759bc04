"""
Simulation parameters: one flat, validated record shared by the CLI and the node.

Every field is SI (m, kg, s, N, Pa, rad).  The same names are the ROS parameters of
``umbrella_node`` and the keys of ``config/umbrella.yaml`` (a ROS 2 params file).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, fields
import math
from typing import Any, Mapping

MODELS = ("flexible", "rigid-fe", "rigid")
LOCKS = ("energy", "plastic")


@dataclass(frozen=True)
class ParamSpec:
    """What a parameter means: description with units, and whether a reset is needed."""

    description: str
    units: str
    structural: bool = True  # changes the model or initial state: applies on reset


@dataclass(frozen=True)
class UmbrellaParams:
    # geometry (Fig. 3.4): leaf O-O''-G, link O''-H, sleeve H slides on the axle (Y axis)
    l1: float = 0.5
    l2: float = 0.5
    l3: float = 0.5
    # cross section: a square of height b gives A = b^2, I = b^4/12; explicit A and I win
    section_height: float = 0.01
    area: float = 0.0
    second_moment_of_area: float = 0.0
    # material: Al 7075-T6 (thesis ch. 6)
    youngs_modulus: float = 72.0e9
    density: float = 2770.0
    yield_strength: float = 500.0e6
    # configuration
    alpha0: float = 0.49 * math.pi
    alpha_deployed: float = math.pi / 12.0
    v0: float = -0.2
    sleeve_force: float = 0.0
    # model and numerics
    model: str = "flexible"
    elements_per_segment: int = 1
    lock: str = "energy"
    time_step: float = 2.0e-3

    # ------------------------------------------------------------------ derived
    @property
    def cross_section_area(self) -> float:
        return self.area if self.area > 0.0 else self.section_height ** 2

    @property
    def cross_section_inertia(self) -> float:
        if self.second_moment_of_area > 0.0:
            return self.second_moment_of_area
        return self.section_height ** 4 / 12.0

    @property
    def fibre_distance(self) -> float:
        """Distance from the neutral axis to the outer fibre (b/2, Eq. 5.44)."""
        if self.section_height > 0.0:
            return 0.5 * self.section_height
        # rectangle of the same A and I: I = A h^2 / 12
        return math.sqrt(3.0 * self.cross_section_inertia / self.cross_section_area)

    @property
    def mass_per_length(self) -> float:
        return self.density * self.cross_section_area

    @property
    def sleeve_stop_height(self) -> float:
        """Height of the stop S on the axle: the rigid geometry at alpha_deployed."""
        return _sleeve_height(self.l1, self.l3, self.alpha_deployed)

    @property
    def sleeve_start_height(self) -> float:
        return _sleeve_height(self.l1, self.l3, self.alpha0)

    # ---------------------------------------------------------------- building
    def replace(self, **changes: Any) -> "UmbrellaParams":
        return dataclasses.replace(self, **{k: coerce(k, v) for k, v in changes.items()})

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], base: "UmbrellaParams | None" = None,
                     ignore_unknown: bool = False) -> "UmbrellaParams":
        base = base or cls()
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown and not ignore_unknown:
            raise ValueError(f"unknown parameter(s) {', '.join(unknown)}; "
                             f"known: {', '.join(sorted(known))}")
        return base.replace(**{k: v for k, v in values.items() if k in known})

    def validated(self) -> "UmbrellaParams":
        validate(self)
        return self


def _sleeve_height(l1: float, l3: float, alpha: float) -> float:
    """y_H of the rigid mechanism at leaf angle alpha (H on the axle above O'')."""
    return l1 * math.sin(alpha) + math.sqrt(max(l3 ** 2 - (l1 * math.cos(alpha)) ** 2, 0.0))


SPECS: dict[str, ParamSpec] = {
    "l1": ParamSpec("leaf length from the hinge O to the link joint O''", "m"),
    "l2": ParamSpec("leaf length from the link joint O'' to the tip G", "m"),
    "l3": ParamSpec("link length from O'' to the sleeve joint H", "m"),
    "section_height": ParamSpec("height b of the square cross-section (A = b^2, I = b^4/12); "
                                "also sets the outer fibre at b/2", "m"),
    "area": ParamSpec("cross-section area A; 0 = derive from section_height", "m^2"),
    "second_moment_of_area": ParamSpec("second moment of area I; 0 = derive from section_height",
                                       "m^4"),
    "youngs_modulus": ParamSpec("Young's modulus E of leaf and link", "Pa"),
    "density": ParamSpec("mass density of leaf and link", "kg/m^3"),
    "yield_strength": ParamSpec("yield strength, for the stress ratio peak |sigma| / yield", "Pa"),
    "alpha0": ParamSpec("initial leaf angle alpha1 from the X axis (folded)", "rad"),
    "alpha_deployed": ParamSpec("leaf angle at full deployment; the stop S is derived from it",
                                "rad"),
    "v0": ParamSpec("initial sleeve velocity along Y (negative deploys)", "m/s"),
    "sleeve_force": ParamSpec("sleeve force F_H at start, >= 0, pushes the sleeve along -Y",
                              "N", structural=False),
    "model": ParamSpec("flexible | rigid-fe | rigid", "-"),
    "elements_per_segment": ParamSpec("beam elements on each of O-O'', O''-G and O''-H "
                                      "(1 = thesis 3-element model, 2 = 6-element)", "-"),
    "lock": ParamSpec("velocity redistribution at the lock: energy (thesis 5.2.2) | plastic", "-"),
    "time_step": ParamSpec("fixed physics step of the integrator", "s"),
}

#: node-only parameters: name -> (default, description with units, (low, high) or None, read_only)
NODE_PARAMETERS = {
    "publish_rate": (100.0, "publication rate of joint_states, tip_deflection, peak_stress, "
                     "markers and clock (Hz, sim time); the physics step is time_step or "
                     "shorter so that publications fall on steps", (1.0, 5000.0), False),
    "real_time_factor": (1.0, "sim seconds per wall second: 1.0 = wall-clock pace, "
                         "0 = as fast as possible (-)", (0.0, 1000.0), False),
    "duration": (0.0, "simulated time after which the node exits (s); 0 = run until stopped",
                 (0.0, 1.0e9), False),
    "record_path": ("", "bag directory to record to (NAME/NAME_0.mcap + metadata.yaml), "
                    "must not exist; '' = no recording (fixed for the life of the node)",
                    None, True),
    "marker_magnification": (1.0, "deformation magnification of the markers (-)",
                             (0.0, 1.0e6), False),
}

#: keys of a params file that belong to the node, not the model: the offline CLI skips them
NODE_ONLY_PARAMS = tuple(NODE_PARAMETERS) + ("use_sim_time",)

_INT_FIELDS = {"elements_per_segment"}
_STR_FIELDS = {"model", "lock"}


def coerce(name: str, value: Any) -> Any:
    """Convert a CLI / YAML / ROS value to the field's type, naming the parameter on failure."""
    try:
        if name in _STR_FIELDS:
            return str(value)
        if name in _INT_FIELDS:
            if isinstance(value, float) and not value.is_integer():
                raise ValueError("must be a whole number")
            return int(value)
        if isinstance(value, bool):
            raise ValueError("must be a number")
        return float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"parameter {name}={value!r}: {exc}") from None


def validate(p: UmbrellaParams) -> None:
    """Raise ValueError naming the parameter and the rule it breaks."""
    for f in fields(p):
        v = getattr(p, f.name)
        if isinstance(v, float) and not math.isfinite(v):
            raise ValueError(f"parameter {f.name}={v}: must be a finite number")
    for name in ("l1", "l2", "l3", "youngs_modulus", "density", "yield_strength", "time_step"):
        if getattr(p, name) <= 0.0:
            raise ValueError(f"parameter {name}={getattr(p, name)}: must be > 0")
    for name in ("section_height", "area", "second_moment_of_area"):
        if getattr(p, name) < 0.0:
            raise ValueError(f"parameter {name}={getattr(p, name)}: must be >= 0")
    if (p.area > 0.0) != (p.second_moment_of_area > 0.0):
        raise ValueError("parameters area and second_moment_of_area: give both or neither")
    if p.area == 0.0 and p.section_height <= 0.0:
        raise ValueError(f"parameter section_height={p.section_height}: must be > 0 "
                         "unless area and second_moment_of_area are given")
    if p.model not in MODELS:
        raise ValueError(f"parameter model={p.model!r}: must be one of {', '.join(MODELS)}")
    if p.lock not in LOCKS:
        raise ValueError(f"parameter lock={p.lock!r}: must be one of {', '.join(LOCKS)}")
    if not 1 <= p.elements_per_segment <= 64:
        raise ValueError(f"parameter elements_per_segment={p.elements_per_segment}: "
                         "must be between 1 and 64")
    if not 0.0 < p.alpha_deployed < math.pi / 2:
        raise ValueError(f"parameter alpha_deployed={p.alpha_deployed}: must be in (0, pi/2)")
    if not p.alpha_deployed < p.alpha0 < math.pi / 2:
        raise ValueError(f"parameter alpha0={p.alpha0}: must be above alpha_deployed="
                         f"{p.alpha_deployed} and below pi/2")
    for name in ("alpha0", "alpha_deployed"):
        reach = p.l1 * abs(math.cos(getattr(p, name)))
        if reach >= p.l3:
            raise ValueError(f"parameter {name}={getattr(p, name)}: geometry cannot close, "
                             f"l1*|cos({name})| = {reach:.6g} m must be < l3 = {p.l3} m")
    if p.sleeve_force < 0.0:
        raise ValueError(f"parameter sleeve_force={p.sleeve_force}: must be >= 0 "
                         "(F_H pushes the sleeve along -Y)")
    if p.time_step > 0.01:
        raise ValueError(f"parameter time_step={p.time_step}: must be <= 0.01 s")


def load_params_file(path: str, node_name: str = "umbrella_node") -> dict:
    """Read the ``ros__parameters`` of a ROS 2 params YAML (``/**`` or the node's name)."""
    import yaml  # local import: only the file path needs it

    try:
        with open(path, "r", encoding="utf-8") as fh:
            doc = yaml.safe_load(fh)
    except OSError as exc:
        raise ValueError(f"params file {path}: {exc.strerror}") from None
    except yaml.YAMLError as exc:
        raise ValueError(f"params file {path}: not valid YAML ({exc})") from None
    if not isinstance(doc, dict):
        raise ValueError(f"params file {path}: expected a mapping of node names")
    merged: dict = {}
    for key in ("/**", node_name, "/" + node_name):
        section = doc.get(key)
        if section is None:
            continue
        values = section.get("ros__parameters") if isinstance(section, dict) else None
        if not isinstance(values, dict):
            raise ValueError(f"params file {path}: section {key!r} has no ros__parameters mapping")
        merged.update(values)
    if not merged:
        raise ValueError(f"params file {path}: no '/**' or '{node_name}' section with "
                         "ros__parameters")
    return merged
