"""The ``turnout`` command line: parses arguments and delegates to the orchestrator's jobs
(:mod:`orchestrator.results.jobs`, ``build_job``, ``ssp``, ``sweep``, ``figures``, ``calibrate``,
``diagnose``, ``synthetic``).

No logic lives here (as in FMPy's ``command_line.py``). User errors
(:class:`~orchestrator.inputs.errors.UserInputError`, which includes
:class:`~orchestrator.inputs.errors.ScenarioError`, and unusable files or folders)
are printed as one line ``turnout: error: ...`` and give exit status 2;
set ``TURNOUT_DEBUG=1`` to get the traceback of an OSError instead.
"""
from __future__ import annotations

import argparse
import gc
import math
import os
import sys
import warnings
from pathlib import Path
from typing import Sequence

from orchestrator import __version__
from orchestrator.inputs.errors import UserInputError, UserInputWarning, one_line

PROG = "turnout"
EXIT_USAGE = 2  # bad input (also argparse's status for usage errors)
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as shells report it
EXIT_INCOMPLETE = 1  # a sweep ended with runs not finished (failed, or a worker died); rerunning resumes
RESULTS_DIR = Path("results")  # default parent of --out


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line (no usage block) and do not exit."""

    def error(self, message: str):
        raise _UsageError(f"{message} (see '{self.prog} --help')")


def _positive_float(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(x) and x > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return x


def _int_at_least(least: int):
    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if n < least:
            raise argparse.ArgumentTypeError(f"must be >= {least}, got {text!r}")
        return n
    return parse


_positive_int = _int_at_least(1)


def _point(text: str) -> str:
    """``body:x`` (a body name and a track coordinate in m); checked for form only."""
    body, sep, x = text.rpartition(":")
    try:
        ok = bool(sep and body) and math.isfinite(float(x))
    except ValueError:
        ok = False
    if not ok:
        raise argparse.ArgumentTypeError(f"expected BODY:X such as crossing:42.0, got {text!r}")
    return text


def _add_scenario_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", metavar="SCENARIO", type=Path, help="scenario YAML file")
    p.add_argument("--set", metavar="KEY=VALUE", action="append", default=[], dest="overrides",
                   help="override a scenario value, e.g. --set track.ballast.stiffness_scale=2 "
                        "or --set 'track.ballast.voids[0].gaps=[0, 1e-3, 1e-3, 1e-3, 1e-3, 0]' "
                        "(value in YAML; repeatable)")


def _add_executor_options(p: argparse.ArgumentParser) -> None:
    """--workers, --scheduler, --no-progress: where the runs of a study go (orchestrator.sweeps.executors)."""
    p.add_argument("--workers", metavar="N", type=_positive_int, default=None,
                   help="local worker processes (default: one per core; ignored with --scheduler)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on a Dask cluster, e.g. tcp://10.0.0.5:8786 (needs dask[distributed])")
    p.add_argument("--no-progress", action="store_true", help="do not show a progress bar")


def build_parser() -> argparse.ArgumentParser:
    """The ``turnout`` parser: ``--version`` and one sub-command each ``_add_*_command`` adds (in help order)."""
    parser = _Parser(prog=PROG, description="Crossing-panel co-simulation: track model + vehicle FMUs.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add_command in (_add_run_command, _add_build_fmus_command, _add_export_ssp_command,
                        _add_frf_command, _add_sweep_command, _add_calibrate_command,
                        _add_diagnose_command, _add_synthesize_command, _add_figures_command):
        add_command(sub)
    return parser


def _add_run_command(sub) -> None:
    """The ``run`` sub-command: its arguments and handler."""
    run = sub.add_parser("run", help="run one co-simulation",
                         description="Run one co-simulation of SCENARIO; writes sensors.csv, results, "
                                     "summary.json and plots into DIR.")
    _add_scenario_args(run)
    run.add_argument("--out", metavar="DIR", type=Path, help="output folder (default: results/<scenario name>)")
    run.add_argument("--no-progress", action="store_true", help="do not show a progress bar")
    run.add_argument("--backend", choices=("fmu", "inprocess"), default="fmu",
                     help="fmu: the track and vehicle FMUs through FMPy (default); inprocess: the same "
                          "model objects without the FMU boundary")
    run.add_argument("--save-states", action="store_true",
                     help="also write the track's reduced states (track/q, v, a; u = T q) to results.h5 "
                          "(about 70 MB per 5000 output steps each, before compression)")
    run.add_argument("--dry-run", action="store_true",
                     help="check only: load and validate SCENARIO, build its layout, place the vehicle, check a "
                          "third-party FMU's ports; print the plan and a rough run time, simulate nothing")
    run.set_defaults(handler=_cmd_run)


def _add_build_fmus_command(sub) -> None:
    """The ``build-fmus`` sub-command: its arguments and handler."""
    bld = sub.add_parser("build-fmus", help="build track.fmu, bogie.fmu and quarter.fmu",
                         description="Build the track FMU of SCENARIO (default: the default scenario) and "
                                     "the vehicle FMUs into DIR.")
    bld.add_argument("scenario", metavar="SCENARIO", type=Path, nargs="?",
                     help="scenario YAML whose track the track FMU carries (default: "
                          "scenarios/crossing_1_12_through_120.yaml)")
    bld.add_argument("--set", metavar="KEY=VALUE", action="append", default=[], dest="overrides",
                     help="override a scenario value (repeatable)")
    bld.add_argument("--out", metavar="DIR", type=Path, default=Path("fmus_built"),
                     help="output folder (default: fmus_built)")
    bld.set_defaults(handler=_cmd_build_fmus)


def _add_export_ssp_command(sub) -> None:
    """The ``export-ssp`` sub-command: its arguments and handler."""
    ssp = sub.add_parser("export-ssp", help="write the co-simulation system as an SSP file",
                         description="Write SCENARIO's system (track and vehicle FMUs, connections, "
                                     "parameters) as an SSP 1.0 file for other FMI tools (libcosim, FMPy).")
    _add_scenario_args(ssp)
    ssp.add_argument("--out", metavar="FILE.ssp", type=Path, required=True, help="SSP file to write")
    ssp.set_defaults(handler=_cmd_export_ssp)


def _add_frf_command(sub) -> None:
    """The ``frf`` sub-command: its arguments and handler."""
    frf = sub.add_parser("frf", help="receptance (frequency response) of the track",
                         description="Receptance of the track of SCENARIO at one rail point; "
                                     "writes frf.csv and frf.png into DIR.")
    _add_scenario_args(frf)
    frf.add_argument("--at", metavar="POINT", type=_point,
                     help="BODY:X, a rail body and track coordinate [m], e.g. crossing:42.0 "
                          "(default: the crossing rail at the transition)")
    frf.add_argument("--fmax", metavar="HZ", type=_positive_float,
                     help="highest frequency [Hz] (default: the model cut-off track.reduction.f_cut)")
    frf.add_argument("--out", metavar="DIR", type=Path, help="output folder (default: results/<scenario name>-frf)")
    frf.set_defaults(handler=_cmd_frf)


def _add_sweep_command(sub) -> None:
    """The ``sweep`` sub-command: its arguments and handler."""
    swp = sub.add_parser("sweep", help="parameter study: one run per combination of values",
                         description="Run SCENARIO once per combination of the --vary values (their Cartesian "
                                     "product) or once per item of a --list file; writes one row per run to "
                                     "DIR/sweep.csv, the runs' files to DIR/runs/<run id>/ and a plot per result. "
                                     "Resumable: run the same command again and only unfinished runs are done.")
    swp.add_argument("scenario", metavar="SCENARIO", type=Path, help="base scenario YAML file")
    what = swp.add_mutually_exclusive_group(required=True)
    what.add_argument("--vary", metavar="KEY=V1,V2,...", action="append", dest="vary",
                      help="values of one scenario key, e.g. --vary vehicle.speed=27.78,33.33 "
                           "--vary track.crossing.impact_angle=0.006,0.012 (values in YAML; repeatable)")
    what.add_argument("--list", metavar="FILE.yaml", type=Path, dest="run_list",
                      help="YAML list of mappings {key.path: value}, one run each")
    swp.add_argument("--out", metavar="DIR", type=Path, help="output folder (default: results/<scenario name>-sweep)")
    _add_executor_options(swp)
    swp.set_defaults(handler=_cmd_sweep)


def _add_calibrate_command(sub) -> None:
    """The ``calibrate`` sub-command: its arguments and handler."""
    cal = sub.add_parser("calibrate", help="surrogate calibration of scenario parameters against a measurement",
                         description="Calibrate parameters of SCENARIO against a measurement (DESIGN.md section 5): "
                                     "Latin hypercube, thin-plate-spline response surface (smoothing by "
                                     "cross-validation), sensitivity -> narrowed bounds, second hypercube + corners, "
                                     "bounded trust-constr optimisation with multistart, confirmation run, then a "
                                     "least-squares polish on real runs. Writes "
                                     "calibrated.yaml, calibration.json, report.md and plots into DIR. Resumable: "
                                     "the same command again does only the unfinished runs.")
    cal.add_argument("scenario", metavar="SCENARIO", type=Path, help="nominal scenario YAML file")
    cal.add_argument("--measured", metavar="FILE", type=Path, required=True,
                     help="measured sensor data (.csv, .h5 or .mat; DESIGN.md section 4.3)")
    cal.add_argument("--params", metavar="LIST",
                     help="comma-separated parameters, each optionally =LO:HI[:log|:lin] (SI units): h1, h2, angle, "
                          "gaps@K (the 6 void gaps of sleeper K), gapI@K (one of them, I=1..6), pad@K, or a "
                          "scenario key with bounds such as track.ballast.stiffness_scale=0.3:3:log; K is an "
                          "index or T, T+1, T-2 (crossing transition sleeper). Default: gaps@T,h1,h2")
    cal.add_argument("--out", metavar="DIR", type=Path,
                     help="output folder (default: results/<scenario name>-calibration)")
    cal.add_argument("--n1", metavar="N", type=_positive_int, default=500, help="runs of the first hypercube (default 500)")
    cal.add_argument("--n2", metavar="N", type=_positive_int, default=500,
                     help="runs of the second hypercube in the narrowed bounds (default 500; plus 2^k corners)")
    cal.add_argument("--seed", metavar="S", type=int, default=0, help="seed of the designs and starts (default 0)")
    cal.add_argument("--polish", metavar="N", type=_int_at_least(0), default=15,
                     help="least-squares iterations on real runs after the surrogate optimum (default 15; 0: none)")
    _add_executor_options(cal)
    cal.set_defaults(handler=_cmd_calibrate)


def _add_diagnose_command(sub) -> None:
    """The ``diagnose`` sub-command: its arguments and handler."""
    dia = sub.add_parser("diagnose", help="residuals -> named cause -> extended model -> gain",
                         description="Compare SCENARIO with a measured passage: fit the nuisance parameters first "
                                     "(speed, time shift, vehicle, track damping, channel gains: reported apart, "
                                     "never a track cause), then screen and fit the catalogue of track causes "
                                     "(ballast_void, ballast_stiffness, rail_pad_stiffness, impact_angle; up to "
                                     "two at once) and answer with named cause(s) and their gains and intervals, "
                                     "'none' (the residual is at the noise level) or 'unexplained' (where the "
                                     "residual lives). Writes diagnosis.json, extended.yaml, report.md and plots "
                                     "into DIR.")
    dia.add_argument("scenario", metavar="SCENARIO", type=Path, help="nominal scenario YAML file")
    dia.add_argument("--measured", metavar="FILE", type=Path, required=True,
                     help="measured sensor data (.csv, .h5 or .mat; DESIGN.md section 4.3)")
    dia.add_argument("--validate", metavar="FILE@SPEED", action="append", default=[],
                     help="a further measured passage and its speed [m/s], compared before/after (repeatable)")
    dia.add_argument("--out", metavar="DIR", type=Path, help="output folder (default: results/<scenario name>-diagnosis)")
    _add_executor_options(dia)
    dia.set_defaults(handler=_cmd_diagnose)


def _add_synthesize_command(sub) -> None:
    """The ``synthesize`` sub-command: its arguments and handler."""
    syn = sub.add_parser("synthesize", help="write a synthetic measurement (a scenario with a hidden effect + noise)",
                         description="Run SCENARIO with an effect and write what its sensors would have measured "
                                     "(sampled, displacements reconstructed from accelerations, white noise), for "
                                     "demos and tests of `diagnose` and `calibrate`.")
    syn.add_argument("scenario", metavar="SCENARIO", type=Path, help="nominal scenario YAML file")
    syn.add_argument("--out", metavar="FILE", type=Path, required=True, help="output file (.csv, .h5 or .mat)")
    syn.add_argument("--effect", metavar="KEY=VALUE", action="append", dest="overrides", default=[],
                     help="the hidden effect as scenario overrides, e.g. "
                          "--effect 'track.ballast.voids=[{sleeper: 21, gaps: [0, 1e-3, 1e-3, 1e-3, 1e-3, 0]}]'")
    syn.add_argument("--speed", metavar="V", type=float, help="vehicle speed [m/s] (same stretch of track)")
    syn.add_argument("--noise", metavar="SHARE", type=float, default=None,
                     help="noise std as a share of each channel's std (default 0.01)")
    syn.add_argument("--seed", metavar="S", type=int, default=0, help="seed of the noise and trigger time")
    syn.set_defaults(handler=_cmd_synthesize)


def _add_figures_command(sub) -> None:
    """The ``figures`` sub-command: its arguments and handler."""
    figs = sub.add_parser("figures", help="regenerate the source papers' figures",
                          description="Run the seed studies (resumable, on the sweep executor) and write the "
                                      "figures of seed 001 (Figs. 3-7) and seed 000 (Table 1, beam) and the "
                                      "profile study (issue 15: wheel wear x lateral offset x speed) into DIR.")
    figs.add_argument("--study", choices=("seed001", "seed000", "profiles", "all"), default="all")
    figs.add_argument("--out", metavar="DIR", type=Path, default=RESULTS_DIR / "figures",
                      help="output folder (default: results/figures)")
    _add_executor_options(figs)
    figs.set_defaults(handler=_cmd_figures)


_ONE_COMMAND = False   # set by console(): this process runs one command, then ends (_jobs freezes its imports)


def _jobs():
    # Imported here so that `turnout --help` and scenario errors do not pay for the model's imports.
    from orchestrator.results import jobs

    if _ONE_COMMAND:
        # The imported modules' objects (numba's, scipy's, numpy's: ~0.1 M) live as long as the
        # process; frozen, the collector's full passes during the command no longer walk them:
        # 0.26 -> 0.14 s of collection in the default `turnout run` (2026-11-27, RESULTS.md). Not in
        # a process that goes on after main() (tests): what it freezes would never be collected.
        gc.freeze()
    return jobs


def _cmd_run(args: argparse.Namespace) -> int:
    from orchestrator.inputs.scenario import load_scenario

    scenario = load_scenario(args.scenario, overrides=args.overrides)
    if args.dry_run:
        from orchestrator.cosim.passage import plan_run

        print(f"{PROG}: {args.scenario}: valid; {plan_run(scenario).summary()} (dry run: nothing simulated)")
        return 0
    out_dir = args.out if args.out is not None else RESULTS_DIR / scenario.name
    _jobs().run_scenario(scenario, out_dir, progress=not args.no_progress, backend=args.backend,
                         save_states=args.save_states)
    print(f"{PROG}: results in {out_dir}")
    return 0


DEFAULT_SCENARIO = "crossing_1_12_through_120.yaml"  # in the repository's scenarios/ folder


def _cmd_build_fmus(args: argparse.Namespace) -> int:
    from orchestrator.inputs.scenario import bundled_scenario, load_scenario

    path = args.scenario if args.scenario is not None else bundled_scenario(DEFAULT_SCENARIO)
    scenario = load_scenario(path, overrides=args.overrides)
    from orchestrator.cosim.build_job import build_fmus

    built = build_fmus(scenario, args.out)
    for name, p in built.items():
        print(f"{PROG}: {name}: {p}")
    return 0


def _cmd_export_ssp(args: argparse.Namespace) -> int:
    from orchestrator.inputs.scenario import load_scenario

    scenario = load_scenario(args.scenario, overrides=args.overrides)
    from orchestrator.cosim.ssp import export_ssp

    out = export_ssp(scenario, args.out)
    print(f"{PROG}: system written to {out}")
    return 0


def _cmd_frf(args: argparse.Namespace) -> int:
    from orchestrator.inputs.scenario import load_scenario

    scenario = load_scenario(args.scenario, overrides=args.overrides)
    out_dir = args.out if args.out is not None else RESULTS_DIR / f"{scenario.name}-frf"
    fmax = args.fmax if args.fmax is not None else scenario.track.reduction.f_cut
    _jobs().frf_job(scenario, out_dir, at=args.at, fmax=fmax)
    print(f"{PROG}: receptance in {out_dir}")
    return 0


def _cmd_sweep(args: argparse.Namespace) -> int:
    from orchestrator.inputs.scenario import load_scenario
    from orchestrator.sweeps import sweep
    if args.run_list is not None:
        variations = sweep.list_from_file(args.run_list)
    else:
        variations = sweep.grid_from_vary(args.vary)
    out_dir = args.out if args.out is not None else RESULTS_DIR / f"{load_scenario(args.scenario).name}-sweep"
    try:
        result = sweep.run_sweep(args.scenario, variations, out_dir, workers=args.workers,
                                 scheduler=args.scheduler, progress=not args.no_progress)
    except sweep.SweepIncomplete as exc:
        print(f"{PROG}: error: {one_line(exc)}", file=sys.stderr)
        return EXIT_INCOMPLETE
    if result.failed:
        print(f"{PROG}: error: {one_line(result.summary())}", file=sys.stderr)
        return EXIT_INCOMPLETE
    print(f"{PROG}: sweep: {result.summary()}")
    return 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from orchestrator.inputs.scenario import load_scenario
    from orchestrator.inverse import calibrate as calibration
    out_dir = args.out if args.out is not None else \
        RESULTS_DIR / f"{load_scenario(args.scenario).name}-calibration"
    try:
        result = calibration.calibrate(args.scenario, args.measured, out_dir, params=args.params, n1=args.n1,
                                       n2=args.n2, seed=args.seed, workers=args.workers, scheduler=args.scheduler,
                                       progress=not args.no_progress, polish=args.polish)
    except calibration.CalibrationIncomplete as exc:
        print(f"{PROG}: error: {one_line(exc)}", file=sys.stderr)
        return EXIT_INCOMPLETE
    s = result.summary
    print(f"{PROG}: calibrate: J {s['objective_before']:.4g} -> {s['objective_after']:.4g}; "
          f"scenario {result.scenario_file}, report {out_dir / 'report.md'}")
    return 0


def _cmd_diagnose(args: argparse.Namespace) -> int:
    from orchestrator.inputs.scenario import load_scenario
    from orchestrator.inverse import diagnose as diagnosis
    out_dir = args.out if args.out is not None else RESULTS_DIR / f"{load_scenario(args.scenario).name}-diagnosis"
    result = diagnosis.diagnose(args.scenario, args.measured, out_dir, validate=args.validate, workers=args.workers,
                                scheduler=args.scheduler, progress=not args.no_progress)
    named = result.named_cause
    where = f" at sleeper {named.sleeper}" if named.sleeper is not None else ""
    print(f"{PROG}: diagnose: cause {named.cause}{where}; J {result.baseline.objective:.4g} -> "
          f"{named.objective:.4g} (gain {100 * result.gain.total:.1f} %); report {out_dir / 'report.md'}")
    return 0


def _cmd_synthesize(args: argparse.Namespace) -> int:
    from orchestrator.inverse import synthetic
    info = synthetic.synthesize_file(args.scenario, args.out, overrides=args.overrides, speed=args.speed,
                                     noise=args.noise, seed=args.seed)
    print(f"{PROG}: synthesize: {args.out} ({info['rate']:g} Hz, noise {info['noise']:g})")
    return 0


def _cmd_figures(args: argparse.Namespace) -> int:
    from orchestrator.studies import figures
    from orchestrator.sweeps import sweep
    try:
        files = figures.make_figures(args.out, study=args.study, workers=args.workers, scheduler=args.scheduler,
                                     progress=not args.no_progress)
    except sweep.SweepIncomplete as exc:
        print(f"{PROG}: error: {one_line(exc)}", file=sys.stderr)
        return EXIT_INCOMPLETE
    print(f"{PROG}: figures: {', '.join(p.name for p in files)} in {args.out}")
    return 0


def _run_handler(args: argparse.Namespace) -> int:
    """The command's handler, with the warnings about the user's input (:class:`UserInputWarning`)
    held back and printed as one line each, ``turnout: warning: ...``, once the command has
    finished: a command that fails on bad input says one line, its error (other warnings
    show as Python shows them, at once)."""
    held: list[str] = []

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        if issubclass(category, UserInputWarning):
            held.append(f"{PROG}: warning: {one_line(message)}")
        else:
            sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))

    with warnings.catch_warnings():
        warnings.showwarning = show
        status = args.handler(args)
    for text in held:
        print(text, file=sys.stderr)
    return status


def _error(message: str) -> int:
    print(f"{PROG}: error: {one_line(message)}", file=sys.stderr)
    return EXIT_USAGE


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``turnout`` command line; returns the exit status."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except _UsageError as exc:
        return _error(str(exc))
    except SystemExit as exc:  # --help / --version
        return exc.code if isinstance(exc.code, int) else 0
    try:
        return _run_handler(args)
    except UserInputError as exc:
        return _error(str(exc))
    except OSError as exc:
        # A file or folder the user named cannot be read or written (out dir on a
        # read-only disk, ...). TURNOUT_DEBUG=1 shows the traceback for bug hunting.
        if os.environ.get("TURNOUT_DEBUG"):
            raise
        if exc.filename:
            where = f": {exc.filename}"
        else:  # a write that failed (disk full, file too large) names no file: name the output
            out = getattr(args, "out", None)
            where = f" (writing {out})" if out is not None else ""
        return _error(f"{exc.strerror or exc}{where}")
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def console(argv: Sequence[str] | None = None) -> int:
    """The installed ``turnout`` script (and ``python -m orchestrator.cli``): :func:`main`, and then
    the process ends at once (:func:`_end_process`). Not in :func:`main`, which tests call in a
    process that goes on."""
    global _ONE_COMMAND
    _ONE_COMMAND = True
    return _end_process(main(argv))


def _end_process(status: int) -> int:
    """End this process with ``status``, without the interpreter's teardown.

    Every file is closed by then. The teardown would walk every object the run made (numba's
    dispatchers and compiled libraries, the FMUs' ctypes, the model's arrays) only to free memory
    the OS takes back anyway: 0.22-0.30 s of the default ``turnout run`` (~3 s), measured
    2026-11-27 (benchmarks/RESULTS.md). The ``atexit`` handlers (temporary folders, worker pools)
    run first and the standard streams are flushed. Where another thread that is not a daemon
    still runs (a library's), or the interpreter has no ``atexit._run_exitfuncs``, the process
    exits normally instead, with the objects frozen out of the exit collection (``gc.freeze``:
    0.13 s of the same run), and ``status`` is returned.
    """
    import atexit
    import threading

    run_exit_handlers = getattr(atexit, "_run_exitfuncs", None)
    others = [t for t in threading.enumerate() if t is not threading.main_thread() and not t.daemon]
    if run_exit_handlers is None or others:
        gc.freeze()
        return status
    run_exit_handlers()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(int(status or 0))


if __name__ == "__main__":
    sys.exit(console())
