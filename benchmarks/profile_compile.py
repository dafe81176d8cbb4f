"""Where the cold start's compile CPU goes: each kernel's compilation, exclusive of its callees, with
the LLVM part of it (numba's ``numba:compile`` and ``numba:llvm_lock`` events), for the main job's
warm-up (the default scene with its studies) in a fresh process on an empty numba cache, compiling
in this process only (``FLEXVIB_COMPILE_PROCESSES=1``). CPU times are the process's (user + system),
steadier than wall times on a shared machine. This measures; no test times it. Run:

    .venv/bin/python benchmarks/profile_compile.py [--steps "steady state" ...] [--top 25]
        [--baseline DIR --rounds 3]

Prints one line a kernel signature, largest first: exclusive CPU (s), of it LLVM (s), and the total.
With ``--baseline DIR`` (a checkout of the code before, ``git archive``) the same profile of that code
runs alternately with this one, round by round (the machine is shared: compare the ratios), and the
totals' ratios are printed; the table is this code's last round.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent


def profile(steps: list[str] | None) -> list[dict]:
    """In this process (cache empty, set by the caller): run the warm-up steps and return one record
    a compilation: ``kernel``, ``cpu`` (exclusive, s), ``llvm`` (exclusive LLVM, s)."""
    import time

    from numba.core import event

    from studies.cli._jit import _attempt, _muted, warm_up_steps
    from studies.cli._main import DEFAULT_SCENE
    from studies.cli._scene import ScenePlan

    records: list[dict] = []
    stack: list[dict] = []        # open compilations, innermost last
    llvm_depth = [0, 0.0]         # nesting of llvm_lock, start CPU of the outermost

    class Compiles(event.Listener):
        def on_start(self, ev):
            now = time.process_time()
            if stack:
                stack[-1]["cpu"] += now - stack[-1]["since"]
            dispatcher = ev.data["dispatcher"]
            name = f"{dispatcher.py_func.__module__}.{dispatcher.py_func.__qualname__}"
            stack.append({"kernel": name, "cpu": 0.0, "llvm": 0.0, "since": now})

        def on_end(self, ev):
            now = time.process_time()
            top = stack.pop()
            top["cpu"] += now - top["since"]
            records.append({"kernel": top["kernel"], "cpu": top["cpu"], "llvm": top["llvm"]})
            if stack:
                stack[-1]["since"] = now

    class Llvm(event.Listener):
        def on_start(self, ev):
            if llvm_depth[0] == 0:
                llvm_depth[1] = time.process_time()
            llvm_depth[0] += 1

        def on_end(self, ev):
            llvm_depth[0] -= 1
            if llvm_depth[0] == 0 and stack:
                stack[-1]["llvm"] += time.process_time() - llvm_depth[1]

    scene = ScenePlan.read(DEFAULT_SCENE)
    chosen = [(name, run) for name, run in warm_up_steps(scene.problem, scene.studies)
              if steps is None or name in steps]
    event.register("numba:compile", Compiles())
    event.register("numba:llvm_lock", Llvm())
    with _muted():
        for name, run in chosen:
            _attempt(name, run)
    return records


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", nargs="+", help="warm-up steps (default: all of the main job's)")
    parser.add_argument("--top", type=int, default=30)
    parser.add_argument("--baseline", type=Path, help="source folder of the code to compare with")
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        json.dump(profile(args.steps), sys.stdout)
        return
    sources = {"this": HERE} | ({"baseline": args.baseline.resolve()} if args.baseline else {})
    totals: dict[str, list[tuple[float, float]]] = {name: [] for name in sources}
    for k in range(args.rounds):
        for name, source in sources.items():   # alternately: both see the same load
            records = run_profile(source, args.steps)
            totals[name].append((sum(r["cpu"] for r in records), sum(r["llvm"] for r in records)))
            print(f"round {k + 1} {name}: {len(records)} compilations, compile CPU {totals[name][-1][0]:.2f} s, "
                  f"of it LLVM {totals[name][-1][1]:.2f} s (load average {os.getloadavg()[0]:.1f})", flush=True)
            if name == "this":
                last = records
    if args.baseline:
        for part, key in (("compile CPU", 0), ("LLVM", 1)):
            ratios = [a[key] / b[key] for a, b in zip(totals["this"], totals["baseline"])]
            print(f"this / baseline, {part}: {statistics.median(ratios):.2f} "
                  f"(rounds: {', '.join(f'{r:.2f}' for r in ratios)})")
    print(f"this code, round {args.rounds}, largest first:")
    for r in sorted(last, key=lambda r: -r["cpu"])[:args.top]:
        print(f"  {r['cpu']:6.2f} s  (LLVM {r['llvm']:5.2f} s)  {r['kernel']}")


def run_profile(source: Path, steps: list[str] | None) -> list[dict]:
    """The records of :func:`profile` for the code in ``source``, in a fresh process on an empty cache."""
    with tempfile.TemporaryDirectory(prefix="flexvib-empty-cache-") as empty:
        env = dict(os.environ, NUMBA_CACHE_DIR=empty, FLEXVIB_COMPILE_PROCESSES="1", PYTHONPATH=str(source))
        command = [sys.executable, __file__, "--child"] + (["--steps", *steps] if steps else [])
        done = subprocess.run(command, env=env, capture_output=True, text=True, cwd=source, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    main()
