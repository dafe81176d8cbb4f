"""This checkout against another commit (default: the last before issue 19's restructuring), side by side.

Each round runs one child process per tree, the two in alternating order, and each child times the
same workloads through the public API after a warm-up call of each (JIT compilation and first-call
caches excluded), as the median of about 0.5 s of repeats. A workload's figure per tree is the
median over the rounds; the ratio is new / old of those medians. On the 2 noisy cores here, ratios
within about 10 % are noise-level.

Workloads (``four_bar_fem4``: the stiffened thesis four-bar, coupler of 4 Hermite elements):
- ``assemble``: the scene's TOML read and assembled (``mechanisms.loads``, ``mechanisms.assemble``);
- ``linearize``: ``linearize.about`` at N = 512;
- ``steady_state``: ``periodic.steady_state`` of that system (with its N/2 and N/4 runs);
- ``simulate``: ``mechanisms.simulate``, 3 periods at 256 steps from the rigid start;
- ``study_steady``: ``studies.steady_state`` of the scene's problem (linearisation included);
- ``nonlinear_steady``: ``studies.nonlinear_steady_state`` at N = 128;
- ``sweep``: ``studies.sweep`` over 8 speeds at N = 128, in process;
- ``main_job``: the README's main job, ``flexvib run`` on the default scene, in process, quiet.

Usage: ``python benchmarks/bench_against.py [--base REV] [--rounds 5] [--only NAME ...]``
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

#: The last commit before the restructuring of issue 19.
BASE = "56570dd"
ROOT = Path(__file__).resolve().parent.parent

# The child: times each workload (warm-up call first) and prints {name: seconds} as JSON.
CHILD = r'''
import json, os, sys, tempfile, time, warnings
warnings.simplefilter("ignore")
import numpy as np
import linearize, mechanisms, periodic, studies

only = set(sys.argv[1:])
scene = "four_bar_fem4"
mechanism = mechanisms.load(scene)
text = mechanism.to_toml()
system = linearize.about(mechanism, n_steps=512).system
problem = studies.MechanismProblem.from_scene(scene)
folder = tempfile.mkdtemp()

def main_job():
    from studies.cli import main
    path = os.path.join(folder, "thesis.h5")
    for name in os.listdir(folder):
        os.remove(os.path.join(folder, name))
    code = main(["run", "--out", path, "--quiet"])
    assert code in (0, None), code

WORKLOADS = {
    "assemble": lambda: mechanisms.assemble(mechanisms.loads(text)),
    "linearize": lambda: linearize.about(mechanism, n_steps=512),
    "steady_state": lambda: periodic.steady_state(system),
    "simulate": lambda: mechanisms.simulate(mechanism, n_periods=3, steps_per_period=256),
    "study_steady": lambda: studies.steady_state(problem, n_steps=256),
    "nonlinear_steady": lambda: studies.nonlinear_steady_state(problem, n_steps=128),
    "sweep": lambda: studies.sweep(problem, "speed", np.linspace(60.0, 140.0, 8), n_steps=128),
    "main_job": main_job,
}
times = {}
for name, work in WORKLOADS.items():
    if only and name not in only:
        continue
    start = time.perf_counter()
    work()
    first = time.perf_counter() - start
    runs = []
    for _ in range(max(1, min(15, int(0.5 / max(first, 1e-6))))):   # about 0.5 s of each
        start = time.perf_counter()
        work()
        runs.append(time.perf_counter() - start)
    times[name] = sorted(runs)[len(runs) // 2]
print(json.dumps(times))
'''


def run_child(tree: Path, only: list[str]) -> dict[str, float]:
    """The child's timings in ``tree`` (its packages first on the path)."""
    env = dict(os.environ, PYTHONPATH=str(tree), PYTHONWARNINGS="ignore")
    done = subprocess.run([sys.executable, "-c", CHILD, *only], cwd=tree, env=env, capture_output=True,
                          text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"workloads failed in {tree}:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", default=BASE, help=f"the commit to compare against (default {BASE})")
    parser.add_argument("--rounds", type=int, default=5, help="alternating rounds (default 5)")
    parser.add_argument("--only", nargs="*", default=[], help="workload names to run (default all)")
    args = parser.parse_args(argv)
    scratch = Path(tempfile.mkdtemp(prefix="flexvib-base-"))
    old_tree = scratch / "tree"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(old_tree), args.base],
                   check=True, capture_output=True)
    try:
        trees = {"old": old_tree, "new": ROOT}
        for tree in trees.values():   # compile each tree's kernels into its own cache first
            run_child(tree, ["assemble"])
        samples: dict[str, dict[str, list[float]]] = {"old": {}, "new": {}}
        for round_index in range(args.rounds):
            order = ("old", "new") if round_index % 2 == 0 else ("new", "old")
            for label in order:
                for name, seconds in run_child(trees[label], args.only).items():
                    samples[label].setdefault(name, []).append(seconds)
        print(f"{args.rounds} alternating rounds, medians: {args.base} (old) against this checkout (new)")
        print("| workload | old [s] | new [s] | new / old |")
        print("| --- | ---: | ---: | ---: |")
        for name, old in samples["old"].items():
            old_median = statistics.median(old)
            new_median = statistics.median(samples["new"][name])
            print(f"| {name} | {old_median:.4f} | {new_median:.4f} | {new_median / old_median:.2f} |")
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(old_tree)],
                       check=False, capture_output=True)
        shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    main()
