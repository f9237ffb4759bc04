"""Offline command line: ``umbrella_sim simulate`` (also ``python -m umbrella_sim``)."""
from __future__ import annotations

import argparse
import csv
import io
import json
import math
import os
import sys

from . import sweep
from .arguments import ArgumentParser
from .. import __version__
from ..bag.paths import check_new_output, read_text_input
from ..core.forcing import command_force
from ..core.params import (check_known_names, check_types, check_values, CONTROLLER_PARAMETERS,
                           NODE_ONLY_PARAMS, NODE_PARAMETERS, parameter_help, shortened_step_note,
                           SPECS, UmbrellaParams)
from ..core.solver import simulate, UmbrellaSimulator
from ..ros.params_file import load_params_file
from ..ros.share import package_path
from ..ros.signals import EXIT_READER_GONE, interruptible, print_for_reader


def default_params_file() -> str | None:
    """Return the package's config/umbrella.yaml (the source checkout's, or installed)."""
    return package_path("config", "umbrella.yaml")


def _number(text: str) -> float:
    """Return a CSV field as a number: Python's float forms but for digit separators (1_0)."""
    if "_" in text:
        raise ValueError(text)
    return float(text)


def _is_number(text: str) -> bool:
    try:
        _number(text)
    except ValueError:
        return False
    return True


def read_force_profile(path: str, params: UmbrellaParams | None = None
                       ) -> list[tuple[float, float]]:
    """
    Read a CSV of (t, F) rows, an optional header line.

    Blank lines and lines starting with # are skipped; the first other line may be a header
    (neither of its two fields a number; one naming force then time, F,t, is refused).
    Times are non-decreasing; each F is a command the
    model (params) accepts.
    """
    rows: list[tuple[float, float]] = []
    text = read_text_input(path, "force profile").removeprefix("\ufeff")   # (Excel's BOM)
    try:
        parsed = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise ValueError(f"force profile {path}: not CSV ({exc})") from None
    first = True
    for lineno, row in enumerate(parsed, start=1):
        if not row or row[0].strip().startswith("#"):
            continue
        if len(row) < 2 or any(field.strip() for field in row[2:]):
            raise ValueError(f"force profile {path}:{lineno}: expected two columns t,F, "
                             f"got {row}")
        header, first = first and not any(map(_is_number, row[:2])), False
        if header:
            names = [field.strip().lower() for field in row[:2]]
            if names[0].startswith("f") and names[1].startswith("t"):   # (any other names)
                raise ValueError(f"force profile {path}:{lineno}: header {row[:2]}: the "
                                 "columns are time then force (t,F), not force then time")
            continue
        try:
            t, f = _number(row[0]), _number(row[1])
        except ValueError:
            raise ValueError(f"force profile {path}:{lineno}: not numbers: {row[:2]}") from None
        if not math.isfinite(t) or t < 0.0:
            raise ValueError(f"force profile {path}:{lineno}: time {t} must be finite and >= 0")
        if rows and t < rows[-1][0]:
            raise ValueError(f"force profile {path}:{lineno}: time {t} goes backwards")
        if rows and t == rows[-1][0]:     # which one acts? one force per instant
            raise ValueError(f"force profile {path}:{lineno}: time {t} given twice (the row "
                             "before has it too): one force per instant")
        try:
            command_force(f, params or UmbrellaParams())
        except ValueError as exc:
            raise ValueError(f"force profile {path}:{lineno}: {exc}") from None
        rows.append((t, f))
    if not rows:
        raise ValueError(f"force profile {path}: no (t, F) rows")
    return rows


#: node parameters that ``--set`` may give offline: they shape the --mcap recording
RECORDING_PARAMS = ("publish_rate", "marker_magnification")
#: models whose lock is always plastic (a rigid mechanism stopped at a point)
RIGID_MODELS = ("rigid", "rigid-fe")


def resolve_params(overrides: dict, params_file: str | None = None,
                   from_file: dict | None = None) -> UmbrellaParams:
    """
    Return an offline run's parameters, validated (a ValueError names the parameter).

    The params file (default config/umbrella.yaml, its node-only keys skipped), then the
    overrides; from_file: that file's parameters, if the caller has read them.
    """
    values: dict = {}
    params_file = params_file or default_params_file()
    if params_file:
        if from_file is None:
            from_file = load_params_file(params_file)
        check_known_names(from_file, set(SPECS) | set(NODE_ONLY_PARAMS) | set(SHARED_NAMES),
                          f"params file {params_file}")
        try:        # its own values first: an error names the file
            check_values({k: v for k, v in from_file.items()
                          if k in SPECS and k not in overrides})
        except ValueError as exc:
            raise ValueError(f"params file {params_file}: {exc}") from None
        values.update(from_file)
    for name in (*NODE_ONLY_PARAMS, *SHARED_NAMES):   # a file shared with the nodes: theirs
        values.pop(name, None)
    values.update(overrides)
    return UmbrellaParams.from_mapping(values).validated()


#: deploy_controller's parameters, which a '/**' params file shared with it may hold
SHARED_NAMES = tuple(CONTROLLER_PARAMETERS)

#: simulate's options that give a parameter: (argparse dest, parameter)
CLI_FLAGS = (("model", "model"), ("elements_per_segment", "elements_per_segment"),
             ("v0", "v0"), ("force", "sleeve_force"), ("lock", "lock"),
             ("time_step", "time_step"), ("publish_rate", "publish_rate"))


def _given_once(given: dict, name: str, how: str) -> None:
    """Record that the command line gives parameter name (how); refuse a second time."""
    if name in given:
        raise ValueError(f"{how}: {name} is already given by {given[name]} (give each "
                         "parameter once)")
    given[name] = how


def build_params(args) -> UmbrellaParams:
    values: dict = {}
    given: dict = {}            # parameter -> the option that gave it, to refuse a second
    lock_given = None
    flags = {name: getattr(args, flag) for flag, name in CLI_FLAGS
             if getattr(args, flag) is not None}
    for flag, name in CLI_FLAGS:
        if name in flags:
            _given_once(given, name, f"--{flag.replace('_', '-')} {flags[name]}")
    for item in args.set or []:
        if "=" not in item:
            raise ValueError(f"--set {item!r}: expected name=value")
        name, value = (x.strip() for x in item.split("=", 1))
        _given_once(given, name, f"--set {name}={value}")
        if name in RECORDING_PARAMS:
            if not args.mcap:
                raise ValueError(f"--set {name}={value}: a parameter of umbrella_node's "
                                 "publication; offline it only shapes a --mcap recording "
                                 "(the summary comes from every physics step whatever the "
                                 "rate): add --mcap BAG_DIR")
            setattr(args, name, NODE_PARAMETERS[name].coerce(value))
            NODE_PARAMETERS[name].check(getattr(args, name))
            continue
        if name in NODE_PARAMETERS:
            raise ValueError(f"--set {name}: a parameter of the live umbrella_node only, with "
                             "no meaning offline (see --duration, --mcap, --publish-rate)")
        check_known_names([name], SPECS, "--set")
        values[name] = value
        if name == "lock":
            lock_given = f"--set lock={value}"
    values.update({name: value for name, value in flags.items() if name in SPECS})
    if args.lock is not None:
        lock_given = f"--lock {args.lock}"
    params_file = args.params or default_params_file()
    from_file = load_params_file(params_file) if params_file else {}
    params = resolve_params(values, params_file, from_file)
    check_lock_given(params, lock_given)
    # what shapes a --mcap recording: --publish-rate / --set, else the params file's (a file
    # shared with the node), else the node's default
    for name in RECORDING_PARAMS:
        spec = NODE_PARAMETERS[name]
        if getattr(args, name) is None and name in from_file:
            try:
                check_types({name: from_file[name]})    # typed as the node reads the file
                setattr(args, name, spec.coerce(from_file[name]))
                spec.check(getattr(args, name))
            except ValueError as exc:
                raise ValueError(f"params file {params_file}: {exc}") from None
        elif getattr(args, name) is None:
            setattr(args, name, spec.default)
    return params


def check_lock_given(params: UmbrellaParams, given: str | None) -> None:
    """
    Refuse a lock asked for explicitly (given: how) that the model cannot take.

    A rigid model always stops plastically; a lock from a params file shared with flexible
    runs only gets the validity warning (outputs.lock_warning).
    """
    if given and params.model in RIGID_MODELS and params.lock != "plastic":
        raise ValueError(f"{given}: does not apply to model {params.model}, whose lock "
                         "is always plastic (a rigid mechanism stopped at a point keeps no "
                         "kinetic energy to redistribute); use lock plastic or a flexible "
                         "model")


class Progress:

    def __init__(self, duration: float, stream=None):
        self.duration = duration
        self.stream = stream or sys.stderr     # (at call time: a redirected stderr)

    def __call__(self, t: float) -> None:
        frac = min(1.0, t / self.duration) if self.duration > 0 else 1.0
        bar = "#" * int(30 * frac)
        self.stream.write(f"\r[{bar:<30}] {100 * frac:5.1f}%  t = {t:.3f} s")
        self.stream.flush()

    def close(self) -> None:
        self.stream.write("\n")


class _Once(argparse.Action):
    """An option that gives a parameter: given twice is an error, not the last one winning."""

    def __call__(self, parser, namespace, values, option_string=None):
        if getattr(namespace, self.dest) is not None:
            parser.error(f"{option_string} given twice (give each parameter once)")
        setattr(namespace, self.dest, values)


def make_parser() -> argparse.ArgumentParser:
    ap = ArgumentParser(prog="umbrella_sim",
                        description="Flexible umbrella-frame deployment simulator.")
    ap.add_argument("--version", action="version", version=f"umbrella_sim {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    sp = sub.add_parser("simulate", help="run one simulation offline",
                        description="Run the physics core offline and report the result. "
                                    "Units SI (m, s, N, Pa, rad).",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        epilog="parameters (--set NAME=VALUE, or a --params file):\n"
                               + "\n".join(parameter_help(SPECS.values())))
    sp.add_argument("--params", metavar="FILE",
                    help="ROS 2 params YAML (default: config/umbrella.yaml)")
    sp.add_argument("--set", action="append", metavar="NAME=VALUE",
                    help="override one parameter (repeatable; each parameter once, here or "
                         "by its own option)")
    sp.add_argument("--model", choices=SPECS["model"].choices, action=_Once)
    sp.add_argument("--elements-per-segment", type=int, dest="elements_per_segment",
                    action=_Once)
    sp.add_argument("--v0", type=float, action=_Once,
                    help="initial sleeve velocity along Y (m/s)")
    force = sp.add_mutually_exclusive_group()
    force.add_argument("--force", type=float, action=_Once,
                       help="constant sleeve force F_H >= 0 (N)")
    force.add_argument("--force-profile", metavar="CSV",
                       help="CSV of t,F rows: F_H held from each t until the next")
    sp.add_argument("--lock", choices=SPECS["lock"].choices, action=_Once)
    sp.add_argument("--time-step", type=float, dest="time_step", action=_Once,
                    help="physics step (s)")
    sp.add_argument("--duration", type=float, default=1.0, help="simulated time (s)")
    sp.add_argument("--csv", metavar="FILE",
                    help="write the time series (every physics step; with --mcap, each "
                         "publication)")
    sp.add_argument("--csv-state", action="store_true", help="add q and qd to the CSV")
    sp.add_argument("--json", action="store_true", help="print one JSON summary")
    sp.add_argument("--mcap", metavar="BAG_DIR",
                    help="record the node's topics to a new bag directory (BAG_DIR/"
                         "BAG_DIR_0.mcap + metadata.yaml), as umbrella_node would; the same "
                         "states and summary as without it when the physics step divides the "
                         "publication period (the default's does; else the recording takes "
                         "the largest step that does, as the node, and says so), but for "
                         "energy_drift and constraint_residual_max, checked at each "
                         "publication instead of each step (they differ in the last digits), "
                         "and --csv, whose rows are then the publications")
    sp.add_argument("--publish-rate", type=float, default=None, dest="publish_rate",
                    action=_Once,
                    help="publication rate of the --mcap recording (Hz, sim time; also "
                         "--set publish_rate=... or the params file's; default 100); the "
                         "summary is the same at any rate whose period the step divides")
    sp.set_defaults(marker_magnification=None)
    sweep.add_parser(sub)
    return ap


#: text summary: key -> (unit, scale, format); keys in this order, then any others
TEXT_FIELDS = {
    "deploy_time": ("s", 1.0, ".6f"),
    "deploy_start": ("s", 1.0, ".6f"),
    "lock_time": ("s", 1.0, ".6f"),
    "tip_deflection_max": ("mm", 1e3, ".4g"),
    "tip_deflection_max_time": ("s", 1.0, ".4f"),
    "stage2_tip_amplitude": ("mm", 1e3, ".4g"),
    "stage2_tip_period": ("s", 1.0, ".5f"),
    "stage2_window": ("s", 1.0, ".4f"),
    "peak_stress_leaf": ("MPa", 1e-6, ".4g"),
    "peak_stress_leaf_x": ("m", 1.0, ".4g"),
    "peak_stress_leaf_time": ("s", 1.0, ".4f"),
    "peak_stress_link": ("MPa", 1e-6, ".4g"),
    "peak_stress_link_x": ("m", 1.0, ".4g"),
    "peak_stress_link_time": ("s", 1.0, ".4f"),
    "yield_strength": ("MPa", 1e-6, ".4g"),
    "stress_ratio_max": ("-", 1.0, ".3g"),
    "tip_deflection_ratio_max": ("% of l1+l2", 100.0, ".3g"),
    "lock": ("", None, ""),
    "lock_energy_before": ("J", 1.0, ".6g"),
    "lock_energy_after": ("J", 1.0, ".6g"),
    "lock_free_velocities": ("", None, ""),
    "energy_drift": ("-", 1.0, ".2e"),
    "constraint_residual_max": ("m, m/s", 1.0, ".1e"),
    "final_time": ("s", 1.0, ".4f"),
    "steps": ("", None, ""),
    "wall_time": ("s", 1.0, ".2f"),
    "real_time_factor": ("-", 1.0, ".3g"),
    "figures_from": ("", None, ""),
}


def format_summary(summary: dict) -> str:
    """
    Return the summary as text: one figure a line, with its unit, rounded to what it means.

    The warnings and the error are printed to stderr (main).
    """
    lines = []
    keys = [k for k in TEXT_FIELDS if k in summary]
    keys += sorted(k for k in summary if k not in TEXT_FIELDS and k not in ("warnings", "error"))
    for key in keys:
        value = summary[key]
        unit, scale, spec = TEXT_FIELDS.get(key, ("", None, ""))
        if value is None:
            text = "-"
        elif isinstance(value, list) and scale is None:
            text = ", ".join(str(v) for v in value) or "-"
        elif isinstance(value, list):
            text = " to ".join(format(v * scale, spec) for v in value) + f" {unit}"
        elif scale is None or isinstance(value, str):
            text = str(value)
        else:
            text = f"{format(value * scale, spec)} {unit}".rstrip()
        lines.append(f"{key:28s} {text}")
    return "\n".join(lines)


def write_stdout(text: str) -> bool:
    """Print text; False if the reader went away (``umbrella_sim simulate | head``)."""
    return print_for_reader(lambda: sys.stdout.write(text + "\n"))


@interruptible("umbrella_sim", "what was written is complete (a --mcap recording is "
               "finalised up to the interruption; --csv is only written after a finished run)")
def main(argv: list[str] | None = None) -> int:
    ap = make_parser()
    args = ap.parse_args(argv)
    if args.command == "sweep":
        return sweep.main(args, ap)
    try:
        params = build_params(args)
        profile = (read_force_profile(args.force_profile, params)
                   if args.force_profile else None)
        if not (math.isfinite(args.duration) and args.duration > 0):
            raise ValueError(f"--duration {args.duration}: must be > 0")
        if args.duration < params.physics_time_step * (1.0 - 1e-9):   # (it ran no step)
            raise ValueError(f"--duration {args.duration}: shorter than one physics step "
                             f"({params.physics_time_step:g} s); the run takes every step "
                             "that ends by then")
        if args.csv is not None:
            check_new_output(args.csv, "--csv")
        if args.mcap is not None:
            check_new_output(args.mcap, "--mcap")
        if not (math.isfinite(args.publish_rate) and 1.0 <= args.publish_rate <= 5000.0):
            raise ValueError(f"--publish-rate {args.publish_rate}: must be in [1, 5000] Hz")
        # the model, before the run (a ModelError names the parameters; --mcap builds its own)
        simulator = None if args.mcap else UmbrellaSimulator(params)
    except ValueError as exc:
        ap.exit(2, f"umbrella_sim: error: {exc}\n")
    progress = Progress(args.duration) if sys.stderr.isatty() and not args.json else None
    if args.mcap:
        note = shortened_step_note(params.physics_time_step, args.publish_rate)
        if note:
            print(f"umbrella_sim: note: the --mcap recording takes a {note}", file=sys.stderr)
        from ..bag.recording import record_offline
        try:
            result = record_offline(params, args.mcap, args.duration, profile,
                                    publish_rate=args.publish_rate,
                                    marker_magnification=args.marker_magnification,
                                    progress=progress)
        except ValueError as exc:
            ap.exit(2, f"umbrella_sim: error: {exc}\n")
    else:
        result = simulate(params, args.duration, force_profile=profile, progress=progress,
                          simulator=simulator)
    if progress:
        progress.close()
    summary = result.summary()          # printed before any file is written: never lost
    for text in summary.get("warnings", []):
        print(f"umbrella_sim: warning: {text}", file=sys.stderr)
    reader_there = write_stdout(json.dumps(summary, indent=2, sort_keys=True) if args.json
                                else format_summary(summary))
    output_error = getattr(result, "recording_error", None)
    if args.csv:
        try:
            result.write_csv(args.csv, with_state=args.csv_state)
        except OSError as exc:
            try:
                os.unlink(args.csv)
            except OSError:
                pass
            output_error = f"--csv {args.csv}: {exc.strerror or exc}"
    if output_error:
        print(f"umbrella_sim: error: output incomplete: {output_error} (the summary above "
              "is complete)", file=sys.stderr)
    if result.error:
        print(f"umbrella_sim: error: {result.error} (kept {len(result.samples)} samples"
              + (f" in {args.csv}" if args.csv and not output_error else "") + ")",
              file=sys.stderr)
        return 3
    if output_error:
        return 4
    return 0 if reader_there else EXIT_READER_GONE


if __name__ == "__main__":
    sys.exit(main())
