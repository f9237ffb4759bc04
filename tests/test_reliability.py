"""
The reliability suite: the node and the tools under long runs, bad input and stop signals.

* Long publication periods (a low ``publish_rate`` with a small step: millions of steps a
  period): memory bounded by what a run keeps, not by its steps; ``~/pause``, commands and
  /diagnostics served inside the period; SIGINT ends the run promptly and the recording
  holds every step taken.
* Runtime parameter sets: every refusal names the parameter and says why (wrong type,
  unknown name with a suggestion, read-only, out of range, unset), and changes nothing.
* Offline: ``umbrella_sim simulate``'s memory does not grow with the duration, with or
  without ``--csv`` / ``--mcap``.
* Damaged recordings: bytes damaged anywhere in a bag give a one-line error naming the file
  (or a recovered log), never a traceback.

What it asserts is behaviour; how fast is for bench/bench_long_period.py and
bench/bench_commands.py (timeouts here only bound a failure).
"""
import os
import subprocess
import sys

from diagnostic_msgs.msg import DiagnosticArray
from mcap.reader import make_reader
import numpy as np
import pytest

from tests.ros_helpers import ros_env
from umbrella_sim.bag.reader import LogError, read_log
from umbrella_sim.core.driver import RunDriver
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.summary import stage2_figures, STAGE2_SAMPLES, STAGE2_WINDOW
from umbrella_sim.ros.recording import record_offline

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def diag_values(msg: DiagnosticArray) -> dict:
    return {kv.key: kv.value for kv in msg.status[0].values}


# --------------------------------------------------------------- the run's summary
def run_through_stage2(params: UmbrellaParams, chunk_steps: int | None = None):
    """Run to the end of the stage-2 window; return the driver and every step's (t, tip)."""
    driver = RunDriver(params, chunk_steps=chunk_steps)
    t, v = [], []
    k_end = None                    # the first step past the window's end
    while k_end is None or driver.sim.step_index < k_end:
        chunk = driver.advance(None if k_end is None else k_end - driver.sim.step_index)
        assert chunk.error is None, chunk.error
        if chunk.lock is not None:
            k_end = int((chunk.lock.time + STAGE2_WINDOW) / driver.step) + 2
        t.append(chunk.block.time.copy())
        v.append(chunk.block.tip_transverse.copy())
    return driver, np.concatenate(t), np.concatenate(v)


@pytest.mark.slow
def test_the_stage2_series_a_summary_keeps_is_bounded():
    """
    A fine step's stage-2 window: a bounded series for its period, every step for the rest.

    At 2 us the 0.3 s window has 150 000 steps; the summary keeps at most STAGE2_SAMPLES of
    them (at 0.1 us all 3e6 took 48 MB and ~4 s to analyse at a node's stop), whatever the
    chunks; the amplitude and the window's end are those of every step and the period is
    that of every step to 1e-6.  At the default step every step is kept.
    """
    fine = UmbrellaParams(v0=-2.0, time_step=2e-6)
    driver, t, v = run_through_stage2(fine)
    summary = driver.summary
    kept = sum(len(a) for a in summary._s2_t)
    assert kept <= STAGE2_SAMPLES + 1
    exact = stage2_figures(t, v, driver.sim.lock_event.time)
    figures = summary.figures()
    assert figures["stage2_tip_amplitude"] == exact["stage2_tip_amplitude"]
    assert figures["stage2_window"] == exact["stage2_window"]
    assert figures["stage2_tip_period"] == pytest.approx(exact["stage2_tip_period"], rel=1e-6)
    other, _, _ = run_through_stage2(fine, chunk_steps=997)
    assert other.summary.figures() == figures                   # whatever the chunks

    default = UmbrellaParams(v0=-2.0)
    driver, t, v = run_through_stage2(default)
    in_window = (t > driver.sim.lock_event.time) & \
        (t <= driver.sim.lock_event.time + STAGE2_WINDOW + 1e-9)
    assert sum(len(a) for a in driver.summary._s2_t) == int(in_window.sum())
    exact = stage2_figures(t, v, driver.sim.lock_event.time)
    figures = driver.summary.figures()
    assert {k: figures[k] for k in exact} == exact              # to the bit


# ------------------------------------------------------------------ damaged recordings
@pytest.fixture(scope="module")
def small_bag(tmp_path_factory):
    """Record 0.3 s offline (through the lock); return its .mcap."""
    bag = tmp_path_factory.mktemp("bags") / "run"
    record_offline(UmbrellaParams(v0=-0.5), str(bag), 0.3)
    return bag / "run_0.mcap"


def tool(module: str, *args, cwd=None):
    return subprocess.run([sys.executable, "-m", f"umbrella_sim.tools.{module}", *args],
                          capture_output=True, text=True, cwd=cwd or ROOT, env=ros_env(),
                          timeout=300)


def test_a_damaged_chunk_is_a_one_line_error(small_bag, tmp_path):
    """
    A chunk whose compressed bytes were damaged: the tools name the file, no traceback.

    (zstd's own error escaped the reader: a traceback from replay --resimulate and compare.)
    """
    data = bytearray(small_bag.read_bytes())
    with open(small_bag, "rb") as fh:
        chunk = make_reader(fh).get_summary().chunk_indexes[0]
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle:middle + 64] = bytes(64)
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    for module, args in (("replay", [str(damaged), "--resimulate"]),
                         ("compare", [str(small_bag), str(damaged), "--out",
                                      str(tmp_path / "cmp"), "--no-plots"])):
        r = tool(module, *args)
        assert r.returncode == 2, (module, r.stdout, r.stderr)
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and f"{damaged}: unreadable MCAP data" in lines[0], r.stderr


def test_damaged_bytes_anywhere_give_a_log_error_or_a_recovered_log(small_bag, tmp_path):
    """
    Bytes flipped, zeroed, cut or repeated anywhere: LogError naming the file, or a log.

    A seeded sweep over the whole file (header, chunks, summary, footer) through what the
    tools do with a log: open it (its summary, or a scan of its records), read every message
    and decode it.  A damaged chunk index once raised struct.error from the summary.
    """
    src = small_bag.read_bytes()
    rng = np.random.default_rng(20240611)
    path = tmp_path / "damaged.mcap"
    outcomes = {"error": 0, "read": 0}
    for _ in range(120):
        data = bytearray(src)
        at = int(rng.integers(len(data)))
        kind = ("flip", "zero", "cut", "repeat")[int(rng.integers(4))]
        if kind == "flip":
            for pos in rng.integers(len(data), size=int(rng.integers(1, 9))):
                data[pos] ^= 1 << int(rng.integers(8))
        elif kind == "zero":
            data[at:at + 64] = bytes(len(data[at:at + 64]))
        elif kind == "cut":
            del data[at:]
        else:
            data[at:at] = data[at:at + 100]
        path.write_bytes(bytes(data))
        try:
            log = read_log(str(path))
            for i, m in enumerate(log.iter_raw()):
                log.decode(m.topic, m.data, index=i, log_time=m.log_time)
        except LogError as exc:
            assert str(path) in str(exc), (kind, at, exc)
            outcomes["error"] += 1
        else:
            outcomes["read"] += 1
    assert outcomes["error"] and outcomes["read"], outcomes
