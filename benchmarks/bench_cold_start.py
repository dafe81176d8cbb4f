"""Cold and warm start of the README's main job, ``flexvib run --out DIR/thesis.h5`` on the default
scene (four_bar_ritz: steady state, sweep, Campbell diagram, nonlinear check), and of the same scene
with its linear studies only (``--only steady_state --only sweep --only campbell``), each run a fresh
process:

- cold: an empty numba cache (``NUMBA_CACHE_DIR`` a new empty folder): every kernel compiles, as on a
  fresh install (the targets: at most 12 s for the main job, 8 s for the linear studies, on a 2-core
  machine);
- warm: the cache the cold run just filled.

Wall times are what a user waits; CPU times (user + system of the job) are steadier on a shared
machine. This measures; no test times the cold start.

With ``--baseline DIR`` (a checkout of the code before, e.g. ``git archive fe72604 | tar -x -C
/tmp/base``) the same job of that code runs alternately with this one, round by round, and the
ratios are printed: the machine is shared and noisy, so compare ratios and medians. Also printed:
the ``compile_time`` file attribute (s) and the summary's steady-state run time, which must not
include the compilation. Run:

    .venv/bin/python benchmarks/bench_cold_start.py [--rounds 3] [--baseline /tmp/base] [--jobs main linear]
        [--processes auto|1|2] [--baseline-processes auto|1|2]

The compile helper process (``studies/cli/_kernel_list.py``) starts only when the load average
leaves a core free; on a loaded machine ``--processes 2`` forces it, to measure it.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent


#: ``flexvib`` as the console script runs it (``studies._entry:main``), with the code on PYTHONPATH.
CONSOLE_SCRIPT = "from studies._entry import main; main()"
#: The jobs: extra arguments of ``flexvib run --out DIR/thesis.h5 --quiet``.
JOBS = {"main": [], "linear": ["--only", "steady_state", "--only", "sweep", "--only", "campbell"]}


def run_job(source: Path, cache: Path, folder: Path, job: str = "main", processes: str = "auto"
            ) -> tuple[float, float, str]:
    """Wall time (s), CPU time (s, user + system of the job and the processes it waited for, the
    compile helper included) and stdout of ``job`` (a key of ``JOBS``) with the code in ``source``
    and numba cache ``cache``; ``processes``: ``FLEXVIB_COMPILE_PROCESSES`` (``auto``: unset, the
    code decides by the free cores)."""
    out = folder / "thesis.h5"
    out.unlink(missing_ok=True)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(source))
    env.pop("FLEXVIB_COMPILE_PROCESSES", None)
    if processes != "auto":
        env["FLEXVIB_COMPILE_PROCESSES"] = processes
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    # the console script's route (``flexvib run``), whose entry starts the compile helper while the
    # packages import; ``python -m studies.cli`` starts it at the warm-up
    done = subprocess.run([sys.executable, "-c", CONSOLE_SCRIPT, "run", "--out", str(out), "--quiet", *JOBS[job]],
                          cwd=folder, env=env, capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode not in (0, 1):
        raise SystemExit(f"the job failed with exit code {done.returncode}:\n{done.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return elapsed, cpu, done.stdout


def compile_time(folder: Path) -> float:
    import h5py

    with h5py.File(folder / "thesis.h5", "r") as handle:
        return float(handle.attrs.get("compile_time", float("nan")))


def steady_run_time(stdout: str) -> float:
    """The run time the summary line of the steady state reports (s)."""
    line = next((line for line in stdout.splitlines() if line.startswith("steady_state")), "")
    found = re.findall(r"([0-9.e+-]+) s\b", line)
    return float(found[-1]) if found else float("nan")


def one_round(source: Path, scratch: Path, job: str, processes: str = "auto") -> dict[str, float]:
    cache = Path(tempfile.mkdtemp(prefix="empty-numba-cache-", dir=scratch))
    cold, cold_cpu, cold_out = run_job(source, cache, scratch, job, processes)
    cold_compile = compile_time(scratch)
    warm, warm_cpu, warm_out = run_job(source, cache, scratch, job, processes)
    return {"cold": cold, "warm": warm, "cold cpu": cold_cpu, "warm cpu": warm_cpu,
            "compile_time": cold_compile,
            "steady_state (cold)": steady_run_time(cold_out), "steady_state (warm)": steady_run_time(warm_out)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--baseline", type=Path, help="source folder of the code to compare with")
    parser.add_argument("--jobs", nargs="+", choices=sorted(JOBS), default=sorted(JOBS, reverse=True))
    parser.add_argument("--processes", choices=("auto", "1", "2"), default="auto",
                        help="FLEXVIB_COMPILE_PROCESSES for this code (auto: unset; 2 forces the compile "
                             "helper on a loaded machine, 1 turns it off)")
    parser.add_argument("--baseline-processes", choices=("auto", "1", "2"), default="auto",
                        help="the same for the baseline (a baseline of this code with 1: the helper's gain)")
    args = parser.parse_args()
    sources = {"this": HERE} | ({"baseline": args.baseline.resolve()} if args.baseline else {})
    print(f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the start", flush=True)
    for job in args.jobs:
        rounds: dict[str, list[dict[str, float]]] = {name: [] for name in sources}
        with tempfile.TemporaryDirectory(prefix="flexvib-cold-") as scratch:
            for k in range(args.rounds):
                for name, source in sources.items():  # alternately: both see the same load
                    processes = args.processes if name == "this" else args.baseline_processes
                    rounds[name].append(one_round(source, Path(scratch), job, processes))
                    print(f"{job} round {k + 1} {name}: " + ", ".join(
                        f"{key} {value:.2f} s" for key, value in rounds[name][-1].items())
                        + f" (load average {os.getloadavg()[0]:.1f})", flush=True)
        print()
        print(f"{job}: median of {args.rounds} rounds (s):")
        medians = {name: {key: statistics.median(r[key] for r in runs) for key in runs[0]}
                   for name, runs in rounds.items()}
        for name, values in medians.items():
            print(f"  {name:9s} " + ", ".join(f"{key} {value:.2f}" for key, value in values.items()))
        for other in [name for name in sources if name != "this"]:
            for key in ("cold", "warm", "cold cpu", "warm cpu", "compile_time"):
                ratios = [a[key] / b[key] for a, b in zip(rounds["this"], rounds[other])]
                print(f"  this / {other}, {key}: {statistics.median(ratios):.2f} "
                      f"(rounds: {', '.join(f'{r:.2f}' for r in ratios)})")
        print()


if __name__ == "__main__":
    main()
