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
The closed-loop deployment law of deploy_controller, on the physics core.

Starting from rest it deploys the frame in ``target_time`` (sim seconds from
the first push to the lock) and brings the leaf to the stop slowly, at ``lock_rate``, within
the force limits [``min_force``, ``max_force``].

Why braking.  The speed at the lock sets the stage-2 vibration: the lock keeps the kinetic
energy (thesis 5.2.2) and turns it into vibration, so the tip amplitude and the stage-2
stress grow like |alpha1'| at the lock.  A push-only drive (F_H >= 0, the thesis's sleeve)
never takes kinetic energy out in stage 1, so for a given deploy time the softest push-only
lock is a coast at constant kinetic energy; with the thesis frame that lowers the stage-2
amplitude only ~3x below the constant force deploying in the same time.  A real deployment
drive (a lead screw, a motor) can also hold the sleeve back: ``min_force`` < 0 allows it, and
the node must then accept such commands (its ``sleeve_force_min`` parameter).  With
``min_force = 0`` the plan has no braking and ends in a coast.

The law, in the leaf angle alpha1 (the natural coordinate: the sleeve's lever dy_H/dalpha1
vanishes near the folded state, so a sleeve-position loop would be badly scaled):

* at the first push a reference alpha1_ref(t) is planned on the rigid two-angle model
  (rigid.py: same geometry and masses; of the umbrella of N ribs, rigid.RigidUmbrella: the N
  rigid ribs on the one sleeve, each its own inertia, lengths, tip mass and hinge friction,
  in the ribs' mean leaf angle): full push from rest, cruise, a constant
  deceleration down to ``lock_rate`` at the stop (optionally a last ``creep_angle`` at
  ``lock_rate``); the cruise rate is solved so that the whole plan takes ``target_time``;
* the force is the plan's inverse dynamics, m(a) a'' + 1/2 m'(a) a'^2 = -F_H y_H'(a) (the
  umbrella's: N y_H' and the hinges' friction), at the
  commanded acceleration a''_ref + kv (a'_ref - a') + kp (a_ref - a), clipped to the limits.
  The feed-forward carries the motion, so the gains stay low: the frame's bending modes
  (20-35 Hz, undamped in the model) sit inside the loop with a DDS round trip of 5-100 ms,
  and a stiff loop would pump them.  The position term keeps the deploy time.

The law itself (``DeployLaw``) is plain Python on the physics core's rigid model, tested
offline against the simulator (``simulate_closed_loop``) as well as over DDS; rclpy is
imported only by the node part.
"""
from __future__ import annotations

import math

import numpy as np

from .driver import RunDriver, simulate
from .params import ControllerConfig, UmbrellaParams
from .rigid import deployment_time_by_quadrature, mean_leaf_angle, RigidUmbrella
from .summary import RunResult
from .umbrella3d.params3d import UmbrellaRibsParams


class DeployLaw:
    """
    Sleeve force from (sim time, alpha1, alpha1'); see the module docstring.

    ``start(t)`` marks the sim time the first push acts from (the plan's t = 0);
    ``force(t, alpha1, rate)`` is the command for the state sampled at t.
    """

    GRID = 4000        # plan resolution in alpha1

    def __init__(self, params: UmbrellaParams | UmbrellaRibsParams, cfg: ControllerConfig):
        self.params = params.validated()
        self.cfg = cfg.validated()
        self.mech = RigidUmbrella(self.params)
        c = self.cfg
        # the ribs' mean leaf angle from the start to the stop (the planar frame's alpha1)
        self.alpha0, self.alpha_deployed = self.mech.alpha0, self.mech.alpha_deployed
        self.span = self.alpha0 - self.alpha_deployed
        if c.creep_angle >= self.span:
            raise ValueError(f'parameter creep_angle={c.creep_angle}: must be below '
                             f'alpha0 - alpha_deployed = {self.span:.6g} rad')
        self.lock_rate = c.lock_rate if c.lock_rate > 0 else 0.25 * self.span / c.target_time
        near_stop = self.alpha_deployed + self.span * np.linspace(0.0, 0.5, 21)
        self.braking_authority = min(-c.min_force * self.lever(a) / self.inertia(a)
                                     for a in near_stop)
        if c.min_force < 0:
            wanted = c.deceleration or 4.0 * self.span / c.target_time ** 2
            self.deceleration = min(wanted, 0.5 * self.braking_authority)
        else:
            self.deceleration = 0.0       # push-only: no braking, the plan ends in a coast
        self._plan()
        self.t_start: float | None = None

    # ------------------------------------------------------------ rigid model
    def inertia(self, a1: float) -> float:
        """Generalised mass M(alpha1) of the whole umbrella: T = 1/2 M alpha1'^2."""
        return self.mech.inertia(a1)

    def lever(self, a1: float) -> float:
        """N dy_H / d alpha1 (m/rad): F_H a rib's generalised force on alpha1 is -F_H times it."""
        return self.mech.lever(a1)

    def _inverse_dynamics(self, a1: float, rate: float, accel: float) -> float:
        h = 1e-6
        dm = (self.inertia(a1 + h) - self.inertia(a1 - h)) / (2 * h)
        return -(self.inertia(a1) * accel + 0.5 * dm * rate * rate
                 + self.mech.friction(a1, rate)) / self.lever(a1)

    # ------------------------------------------------------------------- plan
    def _plan(self) -> None:
        """
        Tabulate alpha1_ref(t) and the feed-forward force.

        s(d) = min(full push from rest, cruise, braking curve, creep) over the remaining
        angle d, the cruise rate bisected to take target_time.
        """
        c = self.cfg
        d = np.linspace(self.span, 0.0, self.GRID + 1)          # remaining angle, decreasing
        alpha = self.alpha_deployed + d
        y = np.array([self.mech.sleeve_height(a) for a in alpha])
        m = np.array([self.inertia(a) for a in alpha])
        push = self._full_push(alpha, y, m)
        s_e, d_c, dec = self.lock_rate, c.creep_angle, self.deceleration
        if dec > 0:
            brake = np.where(d > d_c, np.sqrt(s_e ** 2 + 2 * dec * np.maximum(d - d_c, 0.0)),
                             s_e)
        else:
            brake = np.full_like(d, np.inf)

        def profile(cruise):
            return np.minimum(np.minimum(push, brake), cruise)

        def duration(cruise):
            s = profile(cruise)
            mid = 0.5 * (s[1:] + s[:-1])
            return float(np.sum(np.diff(-d) / np.maximum(mid, 1e-300)))

        fastest = duration(np.inf)
        if fastest > c.target_time:
            raise ValueError(f'parameter target_time={c.target_time:g}: too short for '
                             f'max_force={c.max_force:g} N (and the braking at min_force='
                             f'{c.min_force:g} N): the fastest plan takes {fastest:.4g} s')
        lo, hi = 1e-6, float(np.max(np.minimum(push, brake)))
        if dec <= 0:
            lo = max(lo, s_e) if c.lock_rate > 0 else lo
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            if duration(mid) > c.target_time:
                lo = mid
            else:
                hi = mid
        self.cruise = hi
        s = profile(hi)
        mid = 0.5 * (s[1:] + s[:-1])
        t = np.concatenate([[0.0], np.cumsum(np.diff(-d) / np.maximum(mid, 1e-300))])
        rate = -s                                              # alpha1' < 0 deploys
        accel = np.gradient(rate, t, edge_order=1)
        self.plan_t, self.plan_alpha, self.plan_rate, self.plan_accel = t, alpha, rate, accel
        self.plan_force = np.array([self._inverse_dynamics(a, r, acc)
                                    for a, r, acc in zip(alpha, rate, accel)])

    def _full_push(self, alpha: np.ndarray, y: np.ndarray, m: np.ndarray) -> np.ndarray:
        """
        Return |alpha1'| of the full push from rest along the plan's grid: 1/2 M s^2 = W.

        W, the work of N max_force on the sleeve, less the hinges' friction: the Coulomb
        torques' at speed, and the viscous ones' along the push itself (step by step).
        """
        mech = self.mech
        work = self.cfg.max_force * mech.ribs * (y[0] - y)
        if mech.rubs:
            work = work - np.array([mech.friction_work(a) for a in alpha])
        if not any(mech.viscous):
            return np.sqrt(np.maximum(2.0 * work / m, 0.0))
        energy = np.zeros_like(work)
        for i in range(1, len(alpha)):
            speed = math.sqrt(max(2.0 * energy[i - 1] / m[i - 1], 0.0))
            loss = mech.viscous_coefficient(alpha[i - 1]) * speed * (alpha[i - 1] - alpha[i])
            energy[i] = max(energy[i - 1] + work[i] - work[i - 1] - loss, 0.0)
        return np.sqrt(2.0 * energy / m)

    def reference(self, t: float) -> tuple[float, float, float]:
        """
        Return (alpha1_ref, alpha1'_ref, alpha1''_ref) at sim time t.

        Past the plan's end the reference keeps creeping at lock_rate (a late frame is still
        brought in slowly).
        """
        tau = t - self.t_start
        end = self.plan_t[-1]
        if tau >= end:
            return self.alpha_deployed + self.plan_rate[-1] * (tau - end), \
                self.plan_rate[-1], 0.0
        tau = max(tau, 0.0)
        return (float(np.interp(tau, self.plan_t, self.plan_alpha)),
                float(np.interp(tau, self.plan_t, self.plan_rate)),
                float(np.interp(tau, self.plan_t, self.plan_accel)))

    def open_loop_profile(self, step: float) -> list[tuple[float, float]]:
        """
        Return the plan's force alone as a (t, F) profile on a grid of ``step`` seconds.

        Each step's value is the plan's force at its middle, within the limits, from the
        plan's t = 0 (the first push) to its end; then 0.  No feedback: what the plan alone
        does to a frame (RunDriver's force_profile, a --force-profile CSV).
        """
        times = np.arange(int(math.ceil(self.plan_t[-1] / step))) * step
        forces = np.clip(np.interp(times + 0.5 * step, self.plan_t, self.plan_force),
                         self.cfg.min_force, self.cfg.max_force)
        return [(float(t), float(f)) for t, f in zip(times, forces)] + \
            [(float(len(times) * step), 0.0)]

    # -------------------------------------------------------------------- law
    def start(self, t: float) -> None:
        self.t_start = t

    def force(self, t: float, a1: float, rate: float, lead: float = 0.0) -> float:
        """
        Return the command for the state (alpha1, alpha1') sampled at t.

        It acts about ``lead`` seconds later (the measured command delay): the state is
        predicted to then along the plan's acceleration, so the delay does not eat the
        loop's phase.
        """
        if self.t_start is None:
            self.start(t)
        a_ref, rate_ref, accel_ref = self.reference(t + lead)
        a1 = a1 + rate * lead + 0.5 * accel_ref * lead * lead
        rate = rate + accel_ref * lead
        accel = (accel_ref + self.cfg.velocity_gain * (rate_ref - rate)
                 + self.cfg.position_gain * (a_ref - a1))
        f = self._inverse_dynamics(a1, rate, accel)
        return min(max(f, self.cfg.min_force), self.cfg.max_force)


# ================================================================== offline loop
def constant_force_for(params: UmbrellaParams, target_time: float, rtol: float = 1e-4) -> float:
    """
    Return the constant sleeve force that deploys from rest in target_time on this model.

    The physics core decides; secant steps on t ~ F^-1/2 from the rigid quadrature's guess.
    """
    p = params.replace(v0=0.0)
    force = deployment_time_by_quadrature(p, sleeve_force=1.0) ** 2 / target_time ** 2
    for _ in range(20):
        run = simulate(p.replace(sleeve_force=force), 20.0 * target_time, stop_after_lock=0.0,
                       keep_samples=False)
        if run.lock is None:
            raise ValueError(f'no lock within {20 * target_time:g} s at F = {force:g} N')
        if abs(run.lock.time - target_time) <= rtol * target_time:
            return force
        force *= (run.lock.time / target_time) ** 2
    raise ValueError(f'no constant force found deploying in {target_time:g} s')


def leaf_state(sample) -> tuple[float, float]:
    """
    Return what the law reads of a publication: (alpha1, alpha1').

    The planar frame's; of the umbrella of N ribs (a Sample3D, per-rib arrays) the ribs'
    mean leaf angle and rate (rigid.mean_leaf_angle), as the node reads its joint states.
    """
    return (mean_leaf_angle(np.atleast_1d(sample.alpha1)),
            mean_leaf_angle(np.atleast_1d(sample.alpha1_rate)))


def simulate_closed_loop(params: UmbrellaParams | UmbrellaRibsParams, cfg: ControllerConfig,
                         publish_rate: float = 200.0, delay: int = 1, after_lock: float = 0.5,
                         plan_on: UmbrellaParams | UmbrellaRibsParams | None = None):
    """
    Run the law against the physics core as the node runs it.

    States are published at publish_rate (the node's publication Samples: peak stresses held
    over each period), each command acts ``delay`` publications later (the DDS round trip).
    params: the planar frame, or the umbrella of N ribs (the law plans on the whole of it
    and reads the ribs' mean leaf angle); plan_on: the model the law plans on, if not
    params (what planning on other values costs).  Returns (RunResult of the publications,
    first push time).
    """
    driver = RunDriver(params.replace(v0=0.0), publish_rate)
    sim = driver.sim
    law = DeployLaw(params if plan_on is None else plan_on, cfg)
    period = 1.0 / publish_rate
    result = RunResult(params=driver.params.as_dict())
    s = driver.publication()
    result.samples.append(s)
    pending = [0.0] * delay
    law.start(delay * period)
    while sim.lock_event is None or sim.time < sim.lock_event.time + after_lock - 1e-12:
        pending.append(0.0 if sim.lock_event else
                       law.force(s.time, *leaf_state(s), (delay + 0.5) * period))
        driver.command(pending.pop(0))
        result.error = driver.advance_period()[-1].error
        if result.error is not None:
            break
        s = driver.publication()
        result.samples.append(s)
        if sim.time > 20.0 * cfg.target_time:
            break
    result.lock, result.steps = sim.lock_event, sim.steps
    result.figures = driver.summary.figures()
    return result, delay * period
