"""The ``flexvib`` command line: ``scenes``, ``show``, ``run``, ``plot``, ``animate``, ``report``, ``info``,
``export``, ``check``, ``demo``
(see ``flexvib --help``)."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
from pathlib import Path
from typing import Any, Sequence

from .._errors import UsageError, input_errors, interruption, is_numerical_failure
from ._scene import MATHIEU, ScenePlan, parse_set

__all__ = ["UsageError", "load_scene", "main"]

logger = logging.getLogger("flexvib")

DEFAULT_SCENE = "four_bar_ritz"
#: Set to 1 for the traceback of an internal error (a bug), which is otherwise one line.
DEBUG_VARIABLE = "FLEXVIB_DEBUG"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="flexvib",
        description="Steady-state vibration and stability studies of planar mechanisms with elastic "
                    "links. Studies are declared in a scene's [studies] table (docs/studies.md).")
    parser.add_argument("--version", action=_VersionAction,
                        help="print the versions of flexvib and of numpy, scipy, numba, h5py; exit")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    scenes = commands.add_parser("scenes", help="list the built-in scenes",
                                 description="List the built-in scenes (names for 'flexvib run').")
    scenes.set_defaults(handler=_scenes)
    show = commands.add_parser(
        "show", help="what a scene holds: links, joints, drives, observables, values --set changes",
        description="Describe a scene without running it: links (kind, length, section, discretisation), "
                    "joints, drives, controllers, the observables it offers with the names they take, "
                    "the studies it declares and every value --set PATH=VALUE may change; --out draws "
                    "the mechanism at t = 0 with its names.")
    show.add_argument("scene", nargs="?", default=DEFAULT_SCENE,
                      help=f"built-in scene name or .toml file (default: {DEFAULT_SCENE})")
    show.add_argument("--out", type=Path, help="also draw the mechanism at t = 0 into this file (.png, .svg)")
    show.set_defaults(handler=_show)
    run = commands.add_parser(
        "run", help="run the studies a scene declares into one HDF5 file",
        description="Run every study declared in the scene's [studies] table (a default set when it has "
                    "none) and write them to one HDF5 file. Re-running with the same file resumes: grid "
                    "points and studies already complete are not recomputed.")
    run.add_argument("scene", nargs="?", default=DEFAULT_SCENE,
                     help=f"built-in scene name or .toml file (default: {DEFAULT_SCENE})")
    run.add_argument("--out", type=Path, help="result file (default: SCENE.h5 in the current folder)")
    run.add_argument("--jobs", type=int, default=1,
                     help="worker processes for grid studies (default 1: in this process)")
    run.add_argument("--executor", choices=("process", "dask"), default="process",
                     help="'process' (local pool of --jobs workers) or 'dask' (a Dask distributed "
                          "cluster at --scheduler)")
    run.add_argument("--scheduler", help="address of the Dask scheduler, e.g. tcp://10.0.0.5:8786")
    talk = run.add_mutually_exclusive_group()   # --quiet --verbose together is a contradiction (exit 2)
    talk.add_argument("--quiet", action="store_true",
                      help="print errors only on stderr: no progress bars, log messages or warnings")
    talk.add_argument("--verbose", action="store_true", help="also the debug messages (one per point)")
    run.add_argument("--set", action="append", dest="sets", type=parse_set, default=[],
                     metavar="PATH=VALUE",
                     help="override a scene value (repeatable): PATH is a dotted key path such as "
                          "links.coupler.thickness or studies.sweep.count, VALUE a TOML value")
    run.add_argument("--only", action="append", metavar="STUDY",
                     help="run only this declared study (repeatable), e.g. --only sweep")
    run.add_argument("--force", action="store_true",
                     help="run studies whose estimated memory or time exceeds the limits of the "
                          "resource guard (docs/studies.md, Limits)")
    run.add_argument("--overwrite", action="store_true",
                     help="start the result file afresh (by default a run resumes it, and refuses a "
                          "file of another scene)")
    run.set_defaults(handler=_run)
    plot = commands.add_parser("plot", help="draw the figures of a result file (PNG and SVG)",
                               description="Draw every study of a result file as PNG and SVG figures.")
    plot.add_argument("file", type=Path, help="result file written by 'flexvib run'")
    plot.add_argument("--outdir", type=Path, help="folder for the figures (default: FILE without .h5, "
                                                  "plus _figures)")
    plot.set_defaults(handler=_plot)
    animate = commands.add_parser(
        "animate", help="the deformed mechanism of a steady state over one period (GIF or MP4)",
        description="Animate the deformed mechanism of a steady state over one period: links (plates "
                    "filled), joints and ground pins, the elastic deflection magnified by the factor "
                    "stated in the title. GIF with Pillow; MP4 needs ffmpeg.")
    animate.add_argument("file", type=Path, help="result file written by 'flexvib run'")
    animate.add_argument("--study", help="the study to animate (default: the first steady state of a "
                                         "mechanism in the file)")
    animate.add_argument("--out", type=Path, help="FILE.gif or FILE.mp4 (default: FILE without .h5, "
                                                  "plus _STUDY.gif)")
    animate.add_argument("--magnification", type=float,
                         help="deflection magnification (default: the largest deflection drawn as a "
                              "tenth of the longest link)")
    animate.add_argument("--frames", type=int,
                         help="at most this many frames over the period (default 72; every k-th step)")
    animate.set_defaults(handler=_animate)
    report = commands.add_parser(
        "report", help="a one-page Markdown and HTML report of a result file, with its figures",
        description="Write report.md and report.html: the summary table of every study (headline "
                    "numbers with units and errors, status, run time) and its figures (PNG files "
                    "beside them).")
    report.add_argument("file", type=Path, help="result file written by 'flexvib run'")
    report.add_argument("--out", type=Path, help="folder of the report (default: FILE without .h5, plus "
                                                 "_report)")
    report.set_defaults(handler=_report_command)
    info = commands.add_parser("info", help="summarise a result file",
                               description="Summarise a result file: versions, studies, settings, "
                                           "error estimates and run times.")
    info.add_argument("file", type=Path, help="result file written by 'flexvib run'")
    info.set_defaults(handler=_info)
    export = commands.add_parser(
        "export", help="write each study of a result file as a CSV table (needs flexvib[tables])",
        description="Write each study of a result file as DIR/STUDY.csv (one row per grid point or time "
                    "sample, a column per field, as StudyResult.to_dataframe()) and DIR/STUDY_info.csv "
                    "(the study's status, message, run time, scalar fields and each column's unit).")
    export.add_argument("file", type=Path, help="result file written by 'flexvib run'")
    export.add_argument("--csv", type=Path, required=True, metavar="DIR", help="folder of the CSV files")
    export.set_defaults(handler=_export)
    check = commands.add_parser(
        "check", help="run the table of extreme cases and say what the tool did with each",
        description="Run extreme cases (very stiff axial mode, 64 elements, zero damping, exact resonance, "
                    "parametric instability, compression near the Euler load, near-toggle geometry, "
                    "quasi-static speed, metres and millimetres) and print, for each, the status, "
                    "message and numbers the tool gave and the independent reference it is held to. "
                    "Exit code 0 when every case ends as expected, 1 otherwise.")
    check.add_argument("--case", action="append", dest="cases", metavar="NAME",
                       help="run only this case (repeatable; default: all)")
    check.set_defaults(handler=_check)
    demo = commands.add_parser(
        "demo", help="the periodic engine alone on a 2-DOF example (HDF5 and PNG)",
        description="Periodic steady state and Floquet multipliers of a damped 2-DOF Mathieu-type system "
                    "with harmonic forcing (periodic.demo_system), written to PREFIX.h5 and PREFIX.png.")
    demo.add_argument("--out", type=Path, required=True, help="prefix of the two files written")
    demo.add_argument("--n-steps", type=int, default=512, help="steps per period (even, >= 4; default 512)")
    demo.add_argument("--extrapolate", action="store_true",
                      help="Richardson-extrapolate N and N/2 steps (order 4)")
    demo.set_defaults(handler=_demo)
    return parser


class _VersionAction(argparse.Action):
    """``flexvib --version``: flexvib's version and those of the packages whose numbers it uses."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        import platform

        from .._store import versions

        found = versions()
        others = ", ".join(f"{name} {version}" for name, version in found.items() if name != "flexvib")
        print(f"flexvib {found['flexvib']} (Python {platform.python_version()}; {others})")
        parser.exit()


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``flexvib`` console script; returns the exit code: 0 done, 2 bad input
    (command line, scene, studies table), 1 a computation failed (or an internal error, a bug)."""
    from .._threads import one_blas_thread

    one_blas_thread()  # before any BLAS call of this process or a process it starts
    parser = _parser()
    args = parser.parse_args(argv)
    previous = _terminate_like_ctrl_c()
    hook = sys.unraisablehook
    sys.unraisablehook = _quiet_about_damaged_objects(hook)
    try:
        return args.handler(args)
    except KeyboardInterrupt as interrupt:
        # Ctrl-C or SIGTERM: a run has saved what it finished (studies.cli._run.RunInterrupted says what)
        print(getattr(interrupt, "line", "interrupted: nothing was saved"), file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (`flexvib info FILE | head`): stop quietly, as command-line tools do.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except Exception as error:
        interrupt = interruption(error)   # e.g. a lazy import cut by the signal: ImportError from it
        if interrupt is not None:
            print(getattr(interrupt, "line", "interrupted: nothing was saved"), file=sys.stderr)
            return 130
        return _report(error)
    finally:
        sys.unraisablehook = hook
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _quiet_about_damaged_objects(hook):
    """``sys.unraisablehook`` that logs (debug) instead of printing a traceback for an h5py object
    whose release fails: the objects of a damaged file, which the command has already reported."""
    def quiet(unraisable) -> None:
        where = getattr(unraisable.object, "__qualname__", "") or repr(unraisable.object)
        if "ObjectID" in where or "h5py" in str(getattr(unraisable.object, "__module__", "")):
            logger.debug("h5py could not release an object of a damaged file: %s", unraisable.exc_value)
            return
        hook(unraisable)

    return quiet


def _terminate_like_ctrl_c():
    """SIGTERM (``kill``, ``timeout``) raises ``KeyboardInterrupt`` as Ctrl-C does; returns the
    previous handler (None off the main thread, where signals cannot be handled)."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None

    def interrupt(signum, frame):
        raise KeyboardInterrupt("SIGTERM")

    return signal.signal(signal.SIGTERM, interrupt)


def _report(error: Exception) -> int:
    """Print what went wrong in one line; the exit code (see ``studies._errors`` for the classes)."""
    if isinstance(error, input_errors()):
        print(f"flexvib: error: {error}", file=sys.stderr)
        return 2
    if is_numerical_failure(error):
        print(f"flexvib: error: {type(error).__name__}: {error}", file=sys.stderr)
        return 1
    if os.environ.get(DEBUG_VARIABLE, "") not in ("", "0"):
        import traceback

        traceback.print_exception(error, file=sys.stderr)
    print(f"flexvib: internal error: {type(error).__name__}: {error} (please report; set "
          f"{DEBUG_VARIABLE}=1 for the traceback)", file=sys.stderr)
    return 1


# ---------------------------------------------------------------------------------------------------
def _demo(args: argparse.Namespace) -> int:
    from ._demo import write_demo

    for path in write_demo(args.out, n_steps=args.n_steps, extrapolate=args.extrapolate):
        print(path)
    return 0


def _check(args: argparse.Namespace) -> int:
    from ._check import CASES, run_check, table

    unknown = [name for name in args.cases or () if name not in CASES]
    if unknown:
        raise UsageError(f"--case: unknown case {unknown[0]!r} (cases: {', '.join(CASES)})")
    from ._console import collected_warnings, console

    with console():     # a warning of the cases (a log record each time a model is assembled) once each
        outcomes = run_check(args.cases)
    print(table(outcomes))
    for warning in collected_warnings():
        print(warning, file=sys.stderr)
    failed = [o.case for o in outcomes if not o.passed]
    print(f"{len(outcomes) - len(failed)} of {len(outcomes)} cases as expected"
          + (f"; not as expected: {', '.join(failed)}" if failed else ""))
    return 1 if failed else 0


def _show(args: argparse.Namespace) -> int:
    from ._show import describe, draw

    plan_mechanism = ScenePlan.read(args.scene).problem
    if not hasattr(plan_mechanism, "mechanism"):
        raise UsageError(f"show: {args.scene!r} is not a mechanism (the {MATHIEU} scene is a periodic "
                         f"equation; 'flexvib scenes' lists the mechanisms)")
    mechanism = plan_mechanism.mechanism()
    if args.out is not None:   # a bad path is refused before the text is printed
        if args.out.is_dir():
            raise UsageError(f"--out {str(args.out)!r}: is a folder, expected the path of a .png or .svg file")
        _output_folder(args.out.parent, "--out", args.out)
    print(describe(mechanism))
    if args.out is not None:
        print(f"wrote {draw(mechanism, args.out)}")
    return 0


def _export(args: argparse.Namespace) -> int:
    from ._export import write_csv

    results = _load_results(args.file)
    folder = _output_folder(args.csv, "--csv")
    for path in write_csv(results, folder):
        print(path)
    return 0


def _scenes(args: argparse.Namespace) -> int:
    import mechanisms

    for name in mechanisms.scenes():
        mechanism = mechanisms.load(name)
        description = (mechanism.spec or {}).get("description", "")
        print(f"{name:24s} {description}")
    print(f"{MATHIEU:24s} damped forced Mathieu oscillator (no mechanism; numbers known in closed form)")
    return 0


def load_scene(scene: str, sets: Sequence[tuple[str, Any]] = (), *, only: Sequence[str] | None = None,
               force: bool = False, workers: int = 1, result_file: str | Path | None = None
               ) -> tuple[Any, dict[str, Any]]:
    """``(problem, {kind: options})`` of a built-in scene name or a .toml path (``ScenePlan.read``:
    the ``--set`` values ``(path, value)`` of ``sets`` applied before the scene is checked, only the
    studies named in ``only``), after the resource guard (``ScenePlan.guard``: unless ``force``, a
    study whose estimated memory or time with ``workers`` processes is above the limits is refused;
    studies complete in ``result_file`` are not estimated)."""
    plan = ScenePlan.read(scene, sets, only=only)
    plan.guard(force=force, workers=workers, result_file=result_file)
    return plan.problem, dict(plan.studies)


def _executor(args: argparse.Namespace):
    """``(executor, client)`` of the command line: None for in-process, a pool whose workers die
    with this process, or a Dask cluster's executor and its client."""
    from .._grid import process_pool

    if args.jobs < 1:
        raise UsageError(f"--jobs: expected a positive number of workers, got {args.jobs}")
    if args.executor == "dask":
        if not args.scheduler:
            raise UsageError("--executor dask needs --scheduler ADDRESS (e.g. tcp://127.0.0.1:8786)")
        try:
            import distributed
        except ImportError:
            raise UsageError("--executor dask needs the 'distributed' package: pip install "
                             "'flexvib[dask]'") from None
        _check_reachable(args.scheduler)
        try:
            client = distributed.Client(args.scheduler, timeout="10s")
        except (OSError, ValueError) as error:  # TimeoutError is an OSError; a bad address a ValueError
            raise UsageError(f"--scheduler {args.scheduler}: cannot connect to the Dask scheduler "
                             f"({type(error).__name__}: {error})") from None
        return client.get_executor(), client
    if args.scheduler:
        raise UsageError("--scheduler is only used with --executor dask")
    if args.jobs == 1:
        return None, None
    return process_pool(args.jobs), None


def _check_reachable(address: str, timeout: float = 3.0) -> None:
    """One line instead of Dask's retries and traceback when nothing listens at a tcp:// address."""
    import socket
    from urllib.parse import urlsplit

    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    if parts.scheme not in ("tcp", "tls") or not parts.hostname:
        return  # another protocol (inproc, ucx): let distributed judge
    try:
        with socket.create_connection((parts.hostname, parts.port or 8786), timeout=timeout):
            pass
    except (OSError, ValueError) as error:
        raise UsageError(f"--scheduler {address}: cannot reach the Dask scheduler "
                         f"({getattr(error, 'strerror', None) or error}); is it running?") from None


def _run(args: argparse.Namespace) -> int:
    from ._console import collected_warnings, console
    from ._run import RunInterrupted, interrupted_run

    if args.out is not None and not args.out.name:   # --out "" (Path('.')) or a bare folder
        raise UsageError(f"--out {str(args.out)!r}: expected the path of a result file, e.g. --out run.h5")
    out = args.out or Path(f"{Path(args.scene).stem}.h5")
    plan = None
    try:
        with console(quiet=args.quiet, verbose=args.verbose):
            plan = ScenePlan.read(args.scene, args.sets, only=args.only)
            code = _run_studies(args, plan, out)
            if not args.quiet:
                # each distinct warning once, after the run (not once per point as it happened)
                for warning in collected_warnings():
                    print(warning, file=sys.stderr)
    except RunInterrupted:
        raise
    except BaseException as error:
        # outside the run proper (the guard, the summary): the file holds what it holds, and the
        # line says so (a finished run's file is complete: the same command only reports it);
        # an import cut by the signal raises ImportError from it (studies._errors.interruption)
        if plan is None or interruption(error) is None:
            raise
        raise interrupted_run(plan.studies, str(out)) from None
    return code


def _run_studies(args: argparse.Namespace, plan: ScenePlan, out: Path) -> int:
    from .._kind import kind_of

    # a run started with --force resumes without it: what the file holds complete is not estimated
    plan.guard(force=args.force, workers=args.jobs, result_file=None if args.overwrite else out)
    executor, client = _executor(args)
    finished = False
    try:
        # the kernels the studies need are compiled before any of them starts its clock
        results, failures = plan.run(out, executor=executor, progress=not args.quiet,
                                     overwrite=args.overwrite, warm_up=True)
        finished = True
    finally:
        if client is not None:
            client.close()
        elif executor is not None:
            from .._grid import stop_executor

            stop_executor(executor, interrupted=not finished)  # busy workers: no waiting
    for name, result in results.items():
        print(f"{name:16s} {kind_of(result).summary(result)}")
    for name, message in failures.items():
        print(f"{name:16s} FAILED: {message}")
    if results:
        from .._kind import summaries
        from .._summary import text_table

        print()
        print(text_table(summaries(results)))
        print()
    # a single study whose computation failed (a nonlinear check whose run failed) is written with
    # the status "failed"; grid studies report their failed points in their summary
    failed = sorted(name for name, result in results.items()
                    if not getattr(result, "is_grid", False) and result.status == "failed")
    if failed:
        print(f"failed: {', '.join(failed)}")
    print(f"wrote {out}")
    # exit code 1: the input was fine but a study could not be computed
    return 1 if failures or failed else 0


def _plot(args: argparse.Namespace) -> int:
    from ._report import write_figures

    outdir = args.outdir or args.file.with_name(args.file.stem + "_figures")
    for paths in write_figures(_load_results(args.file), outdir).values():
        for target in paths:
            print(target)
    return 0


def _load_results(path: Path) -> dict[str, Any]:
    from .._store import load

    if not path.is_file():
        raise UsageError(f"result file {str(path)!r} does not exist")
    return load(path)


def _animate(args: argparse.Namespace) -> int:
    from ._animate import MAX_FRAMES, animate, drawable

    name, result = drawable(_load_results(args.file), args.study)
    out = args.out or args.file.with_name(f"{args.file.stem}_{name}.gif")
    if out.is_dir():
        raise UsageError(f"--out {str(out)!r}: is a folder, expected the path of a .gif or .mp4 file")
    _output_folder(out.parent, "--out", out)
    frames = MAX_FRAMES if args.frames is None else args.frames
    if frames < 1:
        raise UsageError(f"--frames: expected a positive number of frames, got {frames}")
    path, n_frames = animate(result, out, magnification=args.magnification, max_frames=frames)
    print(f"wrote {path} ({n_frames} frames)")
    return 0


def _output_folder(folder: Path, option: str, target: Path | None = None) -> Path:
    """``folder``, created with its parents if missing (as ``run --out a/b.h5`` creates ``a``), where
    the command will write ``target`` (default: into ``folder`` itself); a path that is a file, cannot
    be created or cannot be written raises a one-line ``UsageError`` naming it (exit code 2)."""
    named = f"{option} {str(target or folder)!r}"
    if folder.exists() and not folder.is_dir():
        raise UsageError(f"{named}: {str(folder)!r} is a file, expected a folder; choose another {option}")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise UsageError(f"{named}: cannot create the folder {str(folder)!r} "
                         f"({error.strerror or error}); choose another {option}") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise UsageError(f"{named}: no permission to write in the folder {str(folder)!r}; "
                         f"choose another {option}")
    return folder


def _report_command(args: argparse.Namespace) -> int:
    from ._report import write_report

    results = _load_results(args.file)   # a missing file is refused before any folder is made
    outdir = _output_folder(args.out or args.file.with_name(args.file.stem + "_report"), "--out")
    for path in write_report(results, outdir, source=args.file):
        print(path)
    return 0


#: Study attributes ``flexvib info`` does not print: shown in its header line, or bulky and internal
#: (and the checksums' bookkeeping, ``studies._integrity.BOOKKEEPING_ATTRS``).
_INFO_HIDDEN = ("kind", "format_version", "problem", "complete", "request", "request_hash", "settings_hash", "scene",
                "outlines", "labels", "mode_labels")


def _info(args: argparse.Namespace) -> int:
    """Summarise a result file; every dataset of every study is read and checked against its
    checksum (format 3), and a study whose data cannot be read or do not match is called DAMAGED,
    a file whose own metadata is damaged unreadable (exit code 1 for either)."""
    import h5py

    from .._integrity import check_group, check_root, open_study
    from .._store import check_format, format_of, study_attrs
    from .._studies import status_counts

    if not args.file.is_file():
        raise UsageError(f"result file {str(args.file)!r} " + (
            "does not exist" if not args.file.exists() else "is not a regular file (a folder or a device)"))
    unreadable = (f"flexvib: error: {args.file}: unreadable: its HDF5 metadata is damaged or it is not a "
                  f"result file")
    fix = "`flexvib run ... --out FILE --overwrite` moves a damaged file aside and starts afresh"
    try:
        handle = h5py.File(args.file, "r", locking=False)  # a run never holds the file open
    except OSError as error:
        if h5py.is_hdf5(args.file):
            print(f"{unreadable} ({error}); {fix}", file=sys.stderr)
            return 1
        raise UsageError(f"{str(args.file)!r} is not an HDF5 result file ({error}); if it was one, its "
                         f"first bytes are damaged: {fix}") from None
    corrupt, damaged = [], []
    try:
        with handle:
            check_format(handle)  # a newer format: refused, naming the flexvib that wrote it
            root = check_root(handle, format_of(handle))
            print(f"{args.file}: flexvib {handle.attrs.get('flexvib_version', '?')}, result format "
                  f"{format_of(handle)}, created {handle.attrs.get('created', '?')}"
                  + ("" if root.state == "intact" else f"; {root.describe()}"))
            if root.damaged:
                damaged.append("the file's own attributes")
            print(f"  versions: {handle.attrs.get('versions', '?')}")
            if "compile_time" in handle.attrs:   # numba compilation of the file's runs, outside their run times
                print(f"  compile_time: {float(handle.attrs['compile_time']):.3g} s")
            if "scene_hash" in handle.attrs:
                print(f"  scene: sha256 {handle.attrs['scene_hash']}")
            for name in handle:
                item, unopened = open_study(handle, name)
                if unopened is not None:   # its link is there, the object does not open
                    damaged.append(name)
                    print(f"[{name}] DAMAGED: {unopened.describe()}")
                    continue
                if not hasattr(item, "items"):  # a dataset at the root (e.g. a `flexvib demo` file)
                    print(f"{name}: {item.shape} {item.attrs.get('units', '')}")
                    continue
                problem = _unreadable(item)
                check = check_group(item, format_of(item))
                if problem:
                    corrupt.append(name)
                elif check.damaged:
                    damaged.append(name)
                attrs = study_attrs(item)
                state = (f"CORRUPT ({problem})" if problem else
                         f"DAMAGED: {check.describe()}" if check.damaged else
                         "complete" if attrs.get("complete") else "INCOMPLETE")
                verified = "" if check.damaged or problem else f", {check.describe() or 'checksums match'}"
                print(f"[{name}] {attrs.get('kind')} of {attrs.get('problem', '?')}, {state}{verified}")
                if problem or (check.damaged and check.points is None):
                    continue
                _print_study(item, attrs, status_counts)
    except BrokenPipeError:
        raise  # the reader went away (main() stops quietly)
    except (OSError, RuntimeError, KeyError) as error:  # the file's structure gave way while listing it
        print(f"{unreadable} ({type(error).__name__}: {error}); {fix}", file=sys.stderr)
        return 1
    found = ([f"cannot read {', '.join(corrupt)}"] if corrupt else []) + (
        [f"damaged (checksums do not match): {', '.join(damaged)}"] if damaged else [])
    if found:
        print(f"flexvib: error: {args.file}: {'; '.join(found)}; run the same `flexvib run` command to "
              f"recompute what is damaged (the intact studies and points are kept)", file=sys.stderr)
    return 1 if found else 0


def _print_study(item: Any, attrs: dict[str, Any], status_counts: Any) -> None:
    """The points done, statuses, headline attributes and datasets of one study for ``info``."""
    from .._integrity import BOOKKEEPING_ATTRS, BOOKKEEPING_DATASETS
    from ._info import dataset as dataset_line
    from ._info import formatted

    if "done" in item:
        done = item["done"][()]
        print(f"  points done: {int(done.sum())} of {done.size}")
        if "status" in item:  # a grid study: its verdicts, most severe first
            statuses = item["status"].asstr()[()][done]
            print(f"  statuses: {status_counts(statuses)}")
    # every headline attribute the study wrote (a new kind's too); the bulky or internal ones
    # (the scene text, the request it was run for) are left out
    units = attrs.get("units") if isinstance(attrs.get("units"), dict) else {}
    for key, value in attrs.items():
        if key == "settings" and isinstance(value, dict):  # the scene text is in the file
            value = {k: v for k, v in value.items() if k != "scene"}
        if key not in _INFO_HIDDEN and key not in BOOKKEEPING_ATTRS and value not in ("", None, {}, []):
            print(f"  {key}: {formatted(key, value, units)}")
    for key, dataset in item.items():
        if key in BOOKKEEPING_DATASETS:   # the checksums: verified above, not a field of the study
            continue
        if hasattr(dataset, "shape"):
            print(f"  {key}: {dataset_line(dataset.shape, str(dataset.attrs.get('units', '')))}")
        else:
            print(f"  {key}/: {', '.join(dataset.keys())}")


def _unreadable(group: Any) -> str:
    """Why a study group cannot be read back ("" if it can): every dataset is read, and a complete
    study is loaded as its result."""
    from .._store import read_group

    names: list[str] = []
    current = ""
    try:
        group.visit(names.append)
        for current in names:
            item = group[current]
            if hasattr(item, "shape"):
                item[()]
        current = ""
        if group.attrs.get("complete"):
            read_group(group)
    except Exception as error:  # any failure to read is the finding, whatever h5py raises
        return f"{current + ': ' if current else ''}{type(error).__name__}: {error}"
    return ""

