"""Output layer: one Sample per output instant, a RunResult of samples, and its summary."""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from functools import cached_property
import math
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class Sample:
    time: float
    stage: str                     # "deploying" | "locked"
    q: np.ndarray
    qd: np.ndarray
    alpha1: float
    alpha2: float
    alpha1_rate: float
    alpha2_rate: float
    alpha1_accel: float
    sleeve_position: float         # y_H (m)
    sleeve_velocity: float         # dy_H/dt (m/s)
    sleeve_force: float            # F_H applied during the step that ended here (N, along -Y)
    tip_axial: float               # u of G in the leaf frame (m)
    tip_transverse: float          # v of G in the leaf frame (m)
    leaf_stress: np.ndarray        # (2, n_points): top, bottom fibre at leaf_stress_x (Pa)
    link_stress: np.ndarray        # (2, n_points): top, bottom fibre at link_stress_x (Pa)
    peak_stress_leaf: float        # max |sigma| on the leaf (Pa)
    peak_stress_leaf_x: float      # where, m from O along the leaf
    peak_stress_link: float
    peak_stress_link_x: float      # m from O'' along the link
    stress_leaf_joint: float       # top-fibre stress on the leaf at O'' (Pa, Fig. 6.5)
    stress_link_mid: float         # top-fibre stress at mid-link (Pa, Fig. 6.6)
    multipliers: np.ndarray        # lambda (thesis sign: M q'' = ... + J^T lambda)
    sleeve_reaction: tuple         # force on the sleeve from axle (X) and stop (Y), N
    kinetic_energy: float
    strain_energy: float
    work: float                    # work done by F_H since t = 0 (J)
    lock_energy_loss: float        # energy removed by the lock so far (J)
    constraint_residual: float     # max(|Phi|, |J q'|)
    damping_dissipation: float = 0.0   # energy removed by structural damping so far (J)


CSV_COLUMNS = ["time", "stage", "alpha1", "alpha2", "alpha1_rate", "alpha2_rate", "alpha1_accel",
               "sleeve_position", "sleeve_velocity", "sleeve_force", "tip_axial",
               "tip_transverse", "peak_stress_leaf", "peak_stress_leaf_x", "peak_stress_link",
               "peak_stress_link_x", "stress_leaf_joint", "stress_link_mid",
               "sleeve_reaction_x", "sleeve_reaction_y",
               "kinetic_energy", "strain_energy", "work", "lock_energy_loss",
               "constraint_residual", "damping_dissipation"]


def sample_row(s: Sample) -> list:
    row = []
    for c in CSV_COLUMNS:
        if c == "sleeve_reaction_x":
            row.append(s.sleeve_reaction[0])
        elif c == "sleeve_reaction_y":
            row.append(s.sleeve_reaction[1])
        else:
            row.append(getattr(s, c))
    return row


#: per-physics-step outputs of ``UmbrellaSimulator.advance``, in the order the compiled kernel
#: writes them (_kernel.c, enum F_*); stage is the int code of model.Stage
STEP_FIELDS = ("time", "stage", "alpha1", "alpha1_rate", "sleeve_position", "sleeve_velocity",
               "sleeve_force", "tip_axial", "tip_transverse", "peak_stress_leaf",
               "peak_stress_leaf_x", "peak_stress_link", "peak_stress_link_x", "kinetic_energy",
               "strain_energy", "work", "lock_energy_loss")


def step_row(s: Sample) -> list[float]:
    """Return the STEP_FIELDS of one sample (the reference the compiled outputs are tested on)."""
    return [float(s.stage.code) if f == "stage" else float(getattr(s, f)) for f in STEP_FIELDS]


@dataclass
class LockEvent:
    time: float
    kind: str
    energy_before: float
    energy_after: float
    free_velocities: tuple = ()


@dataclass(frozen=True)
class StepBlock:
    """
    Hold the outputs of every physics step of one advance call.

    What ``UmbrellaSimulator.advance(n_steps)`` returns: one entry per physics step taken
    (1-D arrays, field names STEP_FIELDS), the Sample of the final state (``last``, built on
    first use: stresses along the bodies, multipliers and residuals cost more than a step),
    the lock if it happened inside the block, and the fault that stopped the block early (the
    state is then the last good step, and the entries cover the steps taken before it).
    """

    time: np.ndarray
    stage: np.ndarray
    alpha1: np.ndarray
    alpha1_rate: np.ndarray
    sleeve_position: np.ndarray
    sleeve_velocity: np.ndarray
    sleeve_force: np.ndarray
    tip_axial: np.ndarray
    tip_transverse: np.ndarray
    peak_stress_leaf: np.ndarray
    peak_stress_leaf_x: np.ndarray
    peak_stress_link: np.ndarray
    peak_stress_link_x: np.ndarray
    kinetic_energy: np.ndarray
    strain_energy: np.ndarray
    work: np.ndarray
    lock_energy_loss: np.ndarray
    make_last: Callable[[], Sample] = field(repr=False)
    lock: LockEvent | None = None
    error: str | None = None

    @cached_property
    def last(self) -> Sample:
        return self.make_last()

    @classmethod
    def from_rows(cls, rows: np.ndarray, make_last: Callable[[], Sample], lock=None,
                  error=None) -> "StepBlock":
        """
        Build a block from its rows (len(STEP_FIELDS), steps).

        rows: (len(STEP_FIELDS), steps), owned by the block; make_last builds the Sample
        of the final state (a closure over that immutable state).
        """
        return cls(*rows, make_last=make_last, lock=lock, error=error)

    def __len__(self) -> int:
        return len(self.time)

    @classmethod
    def concatenate(cls, blocks: list["StepBlock"]) -> "StepBlock":
        """Return one block of consecutive blocks' steps (the last block's final state)."""
        if len(blocks) == 1:
            return blocks[0]
        rows = np.array([np.concatenate([getattr(b, f) for b in blocks]) for f in STEP_FIELDS])
        lock = next((b.lock for b in blocks if b.lock is not None), None)
        error = next((b.error for b in blocks if b.error is not None), None)
        return cls.from_rows(rows, blocks[-1].make_last, lock, error)

    def peaks(self) -> dict[str, tuple[float, float]]:
        """Return {body: (largest peak |sigma| over the block's steps, where)} ({} if empty)."""
        out = {}
        if not len(self):
            return out
        for body in ("leaf", "link"):
            peaks = getattr(self, f"peak_stress_{body}")
            i = int(np.argmax(peaks))
            out[body] = (float(peaks[i]), float(getattr(self, f"peak_stress_{body}_x")[i]))
        return out


@dataclass
class RunResult:
    params: dict
    samples: list = field(default_factory=list)
    lock: LockEvent | None = None
    steps: int = 0
    wall_time: float = 0.0
    error: str | None = None
    recording_error: str | None = None       # the MCAP recording stopped early (why)
    q_labels: list = field(default_factory=list)
    leaf_stress_x: list = field(default_factory=list)   # m from O, per stress point
    link_stress_x: list = field(default_factory=list)   # m from O''

    def column(self, name: str) -> np.ndarray:
        return np.array([getattr(s, name) for s in self.samples], dtype=float)

    def write_csv(self, path: str, with_state: bool = False) -> None:
        """
        Write the time series as CSV.

        with_state adds q, qd and the fibre stresses along both bodies
        (columns 'sigma_top[leaf@0.25]' = top-fibre stress at 0.25 m from O, Pa).
        """
        with open(path, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            header = list(CSV_COLUMNS)
            if with_state and self.samples:
                header += [f"q[{lab}]" for lab in self.q_labels]
                header += [f"qd[{lab}]" for lab in self.q_labels]
                for body, xs in (("leaf", self.leaf_stress_x), ("link", self.link_stress_x)):
                    for fibre in ("top", "bottom"):
                        header += [f"sigma_{fibre}[{body}@{x:.6g}]" for x in xs]
            w.writerow(header)
            for s in self.samples:
                row = sample_row(s)
                if with_state:
                    row += list(s.q) + list(s.qd)
                    row += list(s.leaf_stress.ravel()) + list(s.link_stress.ravel())
                w.writerow(row)

    def summary(self) -> dict:
        return summarize(self)


def _half_peak_to_peak(x: np.ndarray) -> float:
    return 0.5 * float(x.max() - x.min()) if len(x) else math.nan


def dominant_period(t: np.ndarray, x: np.ndarray) -> float:
    """Mean spacing of upward mean crossings, with hysteresis against ripple."""
    if len(x) < 8:
        return math.nan
    x = x - x.mean()
    amp = np.abs(x).max()
    if amp == 0.0:
        return math.nan
    low, crossings, armed = -0.3 * amp, [], False
    for i in range(1, len(x)):
        if x[i] < low:
            armed = True
        if armed and x[i - 1] < 0.0 <= x[i]:
            frac = -x[i - 1] / (x[i] - x[i - 1])
            crossings.append(t[i - 1] + frac * (t[i] - t[i - 1]))
            armed = False
    if len(crossings) < 2:
        return math.nan
    return float(np.mean(np.diff(crossings)))


def summarize(r: RunResult) -> dict:
    if not r.samples:
        return {"error": r.error, "steps": r.steps}
    t = r.column("time")
    v = r.column("tip_transverse")
    stage1 = np.array([s.stage == "deploying" for s in r.samples])
    stage2 = ~stage1
    out: dict = {}
    out["deploy_time"] = r.lock.time if r.lock else None
    if stage1.any():
        i = int(np.argmax(np.abs(v[stage1])))
        out["tip_deflection_max"] = float(abs(v[stage1][i]))
        out["tip_deflection_max_time"] = float(t[stage1][i])
    else:
        out["tip_deflection_max"] = out["tip_deflection_max_time"] = None
    if stage2.sum() > 8:
        out["stage2_tip_amplitude"] = _half_peak_to_peak(v[stage2])
        period = dominant_period(t[stage2], v[stage2])
        out["stage2_tip_period"] = None if math.isnan(period) else period
    else:
        out["stage2_tip_amplitude"] = out["stage2_tip_period"] = None
    for body in ("leaf", "link"):
        peaks = r.column(f"peak_stress_{body}")
        i = int(np.argmax(peaks))
        out[f"peak_stress_{body}"] = float(peaks[i])
        out[f"peak_stress_{body}_x"] = float(getattr(r.samples[i], f"peak_stress_{body}_x"))
        out[f"peak_stress_{body}_time"] = float(t[i])
    out["yield_strength"] = r.params.get("yield_strength")
    out["stress_ratio_max"] = max(out["peak_stress_leaf"], out["peak_stress_link"]) / \
        r.params["yield_strength"]
    out["energy_drift"] = energy_drift(r)
    if r.lock:
        out["lock"] = r.lock.kind
        out["lock_energy_before"] = r.lock.energy_before
        out["lock_energy_after"] = r.lock.energy_after
        out["lock_free_velocities"] = list(r.lock.free_velocities)
    out["constraint_residual_max"] = float(r.column("constraint_residual").max())
    out["final_time"] = float(t[-1])
    out["steps"] = r.steps
    out["wall_time"] = r.wall_time
    out["real_time_factor"] = float(t[-1] / r.wall_time) if r.wall_time > 0 else None
    if r.error:
        out["error"] = r.error
    return out


def energy_balance_error(r: RunResult) -> np.ndarray:
    """(T + V) - (T0 + V0) - W + lock losses + damping dissipation, per sample (J)."""
    e = r.column("kinetic_energy") + r.column("strain_energy")
    return (e - e[0] - r.column("work") + r.column("lock_energy_loss")
            + r.column("damping_dissipation"))


def energy_drift(r: RunResult) -> float:
    """Return max |energy balance error| relative to the largest mechanical energy."""
    e = r.column("kinetic_energy") + r.column("strain_energy")
    scale = max(float(np.abs(e).max()), float(np.abs(r.column("work")).max()), 1e-300)
    return float(np.abs(energy_balance_error(r)).max() / scale)
