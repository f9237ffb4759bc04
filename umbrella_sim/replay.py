"""
umbrella_replay LOG: republish a recorded run over ROS 2, or re-simulate and check it.

    umbrella_replay run1                      # republish with the recorded timing
    umbrella_replay run1 --rate 2 --start-offset 0.1 --loop
    umbrella_replay run1 --resimulate         # re-run the physics from the log and compare

Republishing sends the recorded serialized bytes (exactly what was recorded) on the
recorded topics with the recorded QoS, including /clock, spaced by the recorded log times
divided by --rate.  The recorded commands (sleeve_force and its refused/applied records) are
not republished unless --with-commands: they would drive a live simulator.
"""
from __future__ import annotations

import argparse
import math
import sys
import time

from .logs import LogData, LogError, qos_from_yaml, read_log

COMMAND_SUFFIXES = ("sleeve_force", "sleeve_force/refused", "sleeve_force/applied")
ACK_TIMEOUT_S = 3.5      # > Fast DDS's default 3 s heartbeat period, which prompts the acks


def _is_command(topic: str) -> bool:
    return any(topic.endswith("/" + s) or topic == s for s in COMMAND_SUFFIXES)


# ------------------------------------------------------------------- resimulate
def resimulate(log: LogData) -> dict:
    """
    Re-run the physics from the log's parameters and applied forces.

    The result maps each signal to its largest |recorded - re-simulated| over the
    recorded publications.
    """
    from .params import SPECS, UmbrellaParams
    from .publication import PublicationDriver

    params_all = log.parameters()
    params = UmbrellaParams.from_mapping({k: v for k, v in params_all.items() if k in SPECS})
    rate = float(params_all["publish_rate"])
    driver = PublicationDriver(params.validated(), rate)
    if abs(driver.step - float(params_all["physics_step"])) > 1e-15:
        raise LogError(f"{log.path}: physics step {params_all['physics_step']} cannot be "
                       f"reproduced from time_step and publish_rate (got {driver.step})")
    applied_topic = log.find_topic("sleeve_force/applied", required=False)
    applied = [(t, m.data) for t, m in log.decoded(applied_topic)] if applied_topic else []
    joint = log.decoded(log.find_topic("joint_states"))
    tip = {round(t, 9): m for t, m in log.decoded(log.find_topic("tip_deflection"))}
    peak = {round(t, 9): m for t, m in log.decoded(log.find_topic("peak_stress"))}
    times = [t for t, _ in joint]
    if any(b < a for a, b in zip(times, times[1:])):
        raise LogError(f"{log.path}: sim time goes backwards (a reset): resimulation covers "
                       "one continuous run")
    diffs = {"leaf_hinge": 0.0, "link_hinge": 0.0, "sleeve_slider": 0.0,
             "leaf_hinge_rate": 0.0, "sleeve_velocity": 0.0, "sleeve_force": 0.0,
             "tip_axial": 0.0, "tip_transverse": 0.0, "peak_stress_leaf": 0.0,
             "peak_stress_link": 0.0}
    sim = driver.sim
    force, i_app, compared = params.sleeve_force, 0, 0
    for t_rec, js in joint:
        while sim.time < t_rec - 1e-9:
            while i_app < len(applied) and applied[i_app][0] <= sim.time + 1e-12:
                force = applied[i_app][1]
                i_app += 1
            driver.advance(force)
        if abs(sim.time - t_rec) > 1e-9:
            raise LogError(f"{log.path}: recorded publication at t = {t_rec} s is not on the "
                           f"re-simulated grid (t = {sim.time})")
        s = sim.sample()
        ref = {"leaf_hinge": s.alpha1, "link_hinge": s.alpha2 - s.alpha1,
               "sleeve_slider": s.sleeve_position, "leaf_hinge_rate": s.alpha1_rate,
               "sleeve_velocity": s.sleeve_velocity, "sleeve_force": s.sleeve_force}
        rec = {"leaf_hinge": js.position[0], "link_hinge": js.position[1],
               "sleeve_slider": js.position[2], "leaf_hinge_rate": js.velocity[0],
               "sleeve_velocity": js.velocity[2], "sleeve_force": js.effort[2]}
        key = round(t_rec, 9)
        if key in tip:
            rec.update(tip_axial=tip[key].point.x, tip_transverse=tip[key].point.y)
            ref.update(tip_axial=s.tip_axial, tip_transverse=s.tip_transverse)
        if key in peak:
            rec.update(peak_stress_leaf=peak[key].data[0], peak_stress_link=peak[key].data[4])
            ref.update(peak_stress_leaf=s.peak_stress_leaf, peak_stress_link=s.peak_stress_link)
        for name in rec:
            diffs[name] = max(diffs[name], abs(rec[name] - ref[name]))
        compared += 1
    if compared == 0:
        raise LogError(f"{log.path}: no joint_states messages to compare")
    return {"compared": compared, "max_abs_diff": diffs}


# -------------------------------------------------------------------- republish
def republish(log: LogData, rate: float, start_offset: float, loop: bool,
              with_commands: bool, topics: list[str] | None, ros_args: list[str],
              wait_for_subscribers: float = 0.0) -> int:
    import rclpy
    from rclpy.duration import Duration
    from rclpy.executors import ExternalShutdownException

    chosen = [t for t in log.topics() if (with_commands or not _is_command(t))
              and (not topics or t in topics)]
    if topics:
        missing = sorted(set(topics) - set(log.channels))
        if missing:
            raise LogError(f"{log.path}: topics not in the log: {', '.join(missing)}")
    msgs = sorted((m for m in log.messages if m.topic in chosen), key=lambda m: m.log_time)
    if not msgs:
        raise LogError(f"{log.path}: nothing to replay")
    t0 = msgs[0].log_time + int(round(start_offset * 1e9))
    msgs = [m for m in msgs if m.log_time >= t0]
    if not msgs:
        raise LogError(f"{log.path}: --start-offset {start_offset} s is past the end of the log")
    rclpy.init(args=["umbrella_replay", "--ros-args", *ros_args])
    node = rclpy.create_node("umbrella_replay")
    pubs = {t: node.create_publisher(log.msg_type(t), t, qos_from_yaml(log.channels[t][1]))
            for t in chosen}
    print(f"replaying {len(msgs)} messages on {len(pubs)} topics from {log.path} at "
          f"{rate:g}x{' (truncated log)' if log.truncated else ''}", flush=True)
    time.sleep(0.5)   # let subscribers discover the publishers
    if wait_for_subscribers > 0:
        deadline = time.monotonic() + wait_for_subscribers
        while any(p.get_subscription_count() == 0 for p in pubs.values()):
            if time.monotonic() > deadline:
                idle = sorted(t for t, p in pubs.items() if p.get_subscription_count() == 0)
                print(f"no subscriber after {wait_for_subscribers:g} s on: {', '.join(idle)};"
                      " replaying anyway", flush=True)
                break
            time.sleep(0.05)
    sent = 0
    try:
        while True:
            wall0 = time.monotonic()
            for m in msgs:
                target = wall0 + (m.log_time - t0) * 1e-9 / rate
                delay = target - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                pubs[m.topic].publish(m.data)
                sent += 1
            if not loop:
                break
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        # reliable subscribers get every sample (a lost one is resent on their NACK) before the
        # publishers go away; Fast DDS asks for acknowledgements with its periodic heartbeat,
        # every 3 s by default, hence the bound
        unacked = [t for t, pub in pubs.items()
                   if not pub.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))]
        if unacked:
            print(f"not acknowledged by every subscriber within {ACK_TIMEOUT_S:g} s: "
                  f"{', '.join(unacked)}", flush=True)
        node.destroy_node()
        rclpy.try_shutdown()
    print(f"replayed {sent} messages", flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    ros_args = []
    if "--ros-args" in argv:
        i = argv.index("--ros-args")
        argv, ros_args = argv[:i], argv[i + 1:]
    ap = argparse.ArgumentParser(prog="umbrella_replay", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("log", help="bag directory or .mcap file")
    ap.add_argument("--rate", type=float, default=1.0, help="playback rate factor")
    ap.add_argument("--start-offset", type=float, default=0.0,
                    help="skip the first S seconds of the log")
    ap.add_argument("--loop", action="store_true", help="replay until interrupted")
    ap.add_argument("--topics", nargs="+", help="only these topics")
    ap.add_argument("--wait-for-subscribers", type=float, default=0.0, metavar="SECONDS",
                    help="before replaying, wait up to SECONDS until every replayed topic "
                         "has a subscriber")
    ap.add_argument("--with-commands", action="store_true",
                    help="also republish the recorded sleeve_force commands")
    ap.add_argument("--resimulate", action="store_true",
                    help="re-run the physics from the log and compare, no ROS traffic")
    ap.add_argument("--tolerance", type=float, default=1e-9,
                    help="largest accepted difference for --resimulate")
    args = ap.parse_args(argv)
    try:
        if not (math.isfinite(args.rate) and args.rate > 0):
            raise LogError(f"--rate {args.rate}: must be > 0")
        if not (math.isfinite(args.start_offset) and args.start_offset >= 0):
            raise LogError(f"--start-offset {args.start_offset}: must be >= 0")
        log = read_log(args.log)
        if args.resimulate:
            res = resimulate(log)
            worst = max(res["max_abs_diff"].values())
            print(f"resimulated {res['compared']} publications of {log.path}"
                  + (" (truncated log)" if log.truncated else ""))
            print(f"{'signal':<20} {'max |recorded - resimulated|':>30}")
            for name, d in res["max_abs_diff"].items():
                print(f"{name:<20} {d:>30.3e}")
            ok = worst <= args.tolerance
            print(f"{'PASS' if ok else 'FAIL'}: largest difference {worst:.3e} "
                  f"(tolerance {args.tolerance:g})")
            return 0 if ok else 1
        return republish(log, args.rate, args.start_offset, args.loop, args.with_commands,
                         args.topics, ros_args, args.wait_for_subscribers)
    except LogError as exc:
        print(f"umbrella_replay: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
