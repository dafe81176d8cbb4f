"""The ``flexvib`` command: ``scenes``, ``run``, ``plot``, ``info`` (see ``flexvib --help``)."""

from __future__ import annotations

import argparse
import logging
import math
import os
import sys
from pathlib import Path
from typing import Any, Sequence

logger = logging.getLogger("flexvib")

DEFAULT_SCENE = "four_bar_thesis"
#: A built-in non-mechanism scene: the damped, forced Mathieu oscillator (studies.mathieu_problem),
#: whose every number is known independently; small and fast, for trying the command out.
MATHIEU = "mathieu"
_MATHIEU_STUDIES = {
    "n_steps": 128,
    "steady_state": {"speed": 0.7},
    "sweep": {"parameter": "speed", "start": 0.2, "stop": 3.0, "count": 57},
    "campbell": {"start": 0.2, "stop": 3.0, "count": 15},
    "stability_chart": {"x": {"parameter": "speed", "start": 0.5, "stop": 3.0, "count": 26},
                        "y": {"parameter": "epsilon", "start": 0.0, "stop": 0.8, "count": 9},
                        "n_steps": 64},
    "nonlinear_check": {"speed": 0.7, "n_periods": 3},
    "error_cost": {"speed": 0.7, "n_steps": [16, 32, 64, 128]},
}


class UsageError(Exception):
    """Bad input on the command line: reported as ``flexvib: error: ...`` with exit code 2."""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="flexvib",
        description="Steady-state vibration and stability studies of planar mechanisms with elastic "
                    "links. Studies are declared in a scene's [studies] table (docs/studies.md).")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    scenes = commands.add_parser("scenes", help="list the built-in scenes",
                                 description="List the built-in scenes (names for 'flexvib run').")
    scenes.set_defaults(handler=_scenes)
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
    run.add_argument("--quiet", action="store_true", help="no progress bars or log messages")
    run.set_defaults(handler=_run)
    plot = commands.add_parser("plot", help="draw the figures of a result file (PNG and SVG)",
                               description="Draw every study of a result file as PNG and SVG figures.")
    plot.add_argument("file", type=Path, help="result file written by 'flexvib run'")
    plot.add_argument("--outdir", type=Path, help="folder for the figures (default: FILE without .h5, "
                                                  "plus _figures)")
    plot.set_defaults(handler=_plot)
    info = commands.add_parser("info", help="summarise a result file",
                               description="Summarise a result file: versions, studies, settings, "
                                           "error estimates and run times.")
    info.add_argument("file", type=Path, help="result file written by 'flexvib run'")
    info.set_defaults(handler=_info)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``flexvib`` console script; returns the exit code."""
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        return args.handler(args)
    except (UsageError, ValueError, FileNotFoundError, KeyError, TypeError) as error:
        message = error.args[0] if isinstance(error, KeyError) and error.args else error
        print(f"flexvib: error: {message}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # The reader went away (`flexvib info FILE | head`): stop quietly, as command-line tools do.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


# ---------------------------------------------------------------------------------------------------
def _scenes(args: argparse.Namespace) -> int:
    import mechanisms

    for name in mechanisms.scenes():
        mechanism = mechanisms.load(name)
        description = (mechanism.spec or {}).get("description", "")
        print(f"{name:24s} {description}")
    print(f"{MATHIEU:24s} damped forced Mathieu oscillator (no mechanism; numbers known in closed form)")
    return 0


def load_scene(scene: str) -> tuple[Any, dict[str, Any]]:
    """``(problem, [studies] table)`` of a built-in scene name or a .toml path."""
    from ._mechanism import MechanismProblem
    from ._plan import default_table, parameters_needed, plan
    from ._problem import mathieu_problem

    if scene == MATHIEU:
        common, declared = plan(_MATHIEU_STUDIES)
        return mathieu_problem(), declared
    import mechanisms

    path = Path(scene)
    if path.suffix == ".toml" and not path.is_file():
        raise UsageError(f"scene file {scene!r} does not exist")
    mechanism = mechanisms.load(scene)
    # the studies' speed is the motion's fundamental frequency 2 pi / period (the crank speed)
    table = dict(mechanism.studies) or default_table(2.0 * math.pi / mechanism.period)
    common, declared = plan(table)
    problem = MechanismProblem(name=mechanism.name, text=mechanism.to_toml(),
                               parameter_paths=parameters_needed(declared),
                               observable_specs=common["observables"])
    return problem, declared


def _executor(args: argparse.Namespace):
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
        client = distributed.Client(args.scheduler, timeout="10s")
        return client.get_executor(), client
    if args.scheduler:
        raise UsageError("--scheduler is only used with --executor dask")
    if args.jobs == 1:
        return None, None
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(args.jobs), None


def _run(args: argparse.Namespace) -> int:
    from ._plan import run_plan

    if not args.quiet:
        logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    problem, declared = load_scene(args.scene)
    out = args.out or Path(f"{Path(args.scene).stem}.h5")
    executor, client = _executor(args)
    try:
        results, failures = run_plan(problem, declared, str(out), executor=executor,
                                     progress=not args.quiet)
    finally:
        if client is not None:
            client.close()
        elif executor is not None:
            executor.shutdown()
    for kind, result in results.items():
        print(f"{kind:16s} {_summary(result)}")
    for kind, message in failures.items():
        print(f"{kind:16s} FAILED: {message}")
    print(f"wrote {out}")
    # exit code 1: the input was fine but a study could not be computed
    return 1 if failures else 0


def _summary(result: Any) -> str:
    kind = type(result).__name__
    run_time = getattr(result, "run_time", float("nan"))
    if kind == "SteadyStateResult":
        errors = ", ".join(f"{k} +- {v:.2g}" for k, v in result.response_error.items())
        return f"spectral radius {result.spectral_radius:.6f}, {result.status}; errors {errors}; {run_time:.3g} s"
    if kind in ("SweepResult", "CampbellResult", "StabilityChart"):
        done, failed = int(result.done.sum()), int((result.status == "failed").sum())
        extra = ""
        if kind == "SweepResult":
            extra = f", {len(result.resonances)} resonances, {len(result.instabilities)} unstable intervals"
        return f"{done}/{result.done.size} points ({failed} failed){extra}; {run_time:.3g} s"
    if kind == "NonlinearCheck":
        diffs = ", ".join(f"{k} {100 * v:.3g} %" for k, v in result.relative_difference.items())
        return (f"nonlinear - linear: {diffs} of peak to peak; {result.nonlinear_run_time:.3g} s "
                f"nonlinear vs {result.linear_run_time:.3g} s linear")
    if kind == "ErrorCostResult":
        best = ", ".join(f"{k} {v[-1, -1]:.2g}" for k, v in result.error.items())
        return (f"{len(result.n_steps)} step counts x {len(result.resolutions)} resolutions; finest relative "
                f"error {best} in {result.run_time[-1, -1]:.3g} s")
    return kind


def _plot(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    matplotlib.rcParams["svg.fonttype"] = "none"  # keep text as text: editable and searchable
    import matplotlib.pyplot as plt

    from ._store import load

    results = load(args.file)
    outdir = args.outdir or args.file.with_name(args.file.stem + "_figures")
    outdir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, result in results.items():
        figures = {name: result.plot()}
        if type(result).__name__ == "SteadyStateResult":
            figures[f"{name}_multipliers"] = result.plot_multipliers()
            if result.outlines:
                figures[f"{name}_mechanism"] = result.plot_mechanism()
        for stem, artists in figures.items():
            first = next(iter(artists.values()))[0] if isinstance(artists, dict) else artists[0]
            figure = first.figure if getattr(first, "figure", None) is not None else first.axes.figure
            for suffix in ("png", "svg"):
                target = outdir / f"{stem}.{suffix}"
                figure.savefig(target, dpi=150)
                written.append(target)
            plt.close(figure)
    for target in written:
        print(target)
    return 0


def _info(args: argparse.Namespace) -> int:
    import h5py

    from ._store import study_attrs

    if not args.file.is_file():
        raise UsageError(f"result file {str(args.file)!r} does not exist")
    try:
        handle = h5py.File(args.file, "r")
    except OSError as error:
        raise UsageError(f"{str(args.file)!r} is not an HDF5 result file ({error})") from None
    with handle:
        print(f"{args.file}: flexvib {handle.attrs.get('flexvib_version', '?')}, created "
              f"{handle.attrs.get('created', '?')}")
        print(f"  versions: {handle.attrs.get('versions', '?')}")
        for name, group in handle.items():
            attrs = study_attrs(group)
            print(f"[{name}] {attrs.get('kind')} of {attrs.get('problem', '?')}, "
                  f"{'complete' if attrs.get('complete') else 'INCOMPLETE'}")
            if "done" in group:
                done = group["done"][()]
                print(f"  points done: {int(done.sum())} of {done.size}")
            for key in ("parameter", "parameters", "n_steps", "spectral_radius", "error_estimate",
                        "response_error", "status", "resonances", "instabilities", "difference",
                        "relative_difference", "periodicity_defect", "periods_to_steady", "run_time",
                        "linear_run_time", "nonlinear_run_time", "rest_run_time", "reference_run_time"):
                if key in attrs and key in group.attrs:
                    print(f"  {key}: {attrs[key]}")
            for key, dataset in group.items():
                if hasattr(dataset, "shape"):
                    print(f"  {key}: {dataset.shape} {dataset.attrs.get('units', '')}")
                else:
                    print(f"  {key}/: {', '.join(dataset.keys())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
