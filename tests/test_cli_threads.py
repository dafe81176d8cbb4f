"""Every process of the ``flexvib`` command runs its BLAS and OpenMP libraries on one thread
(``studies._threads``), the command's own included, unless the user set a thread count."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from studies import _grid, _threads  # the pool workers' pinning and the command's: no public face

ROOT = Path(__file__).resolve().parent.parent

_SCRIPT = """
import json, sys
import numpy, scipy.linalg, threadpoolctl  # loaded before the command starts: threadpoolctl pins them
from studies.cli import main
main(["scenes"])
import numba  # loaded after: the environment pins it
print(json.dumps([entry["num_threads"] for entry in threadpoolctl.threadpool_info()
                  if entry["user_api"] in ("blas", "openmp")]))
"""


def _threads_after_a_command(**variables: str) -> list[int]:
    env = {key: value for key, value in os.environ.items() if key not in _threads.THREAD_VARIABLES}
    env.update(PYTHONPATH=str(ROOT), **variables)
    done = subprocess.run([sys.executable, "-c", _SCRIPT], env=env, capture_output=True, text=True,
                          timeout=300, check=True)
    return json.loads(done.stdout.splitlines()[-1])


def test_the_command_runs_its_own_process_on_one_blas_thread():
    threads = _threads_after_a_command()
    assert threads and set(threads) == {1}, threads


def test_a_thread_count_the_user_set_is_left_alone():
    assert 2 in _threads_after_a_command(OPENBLAS_NUM_THREADS="2")


def test_the_command_and_the_pool_workers_pin_the_same_variables():
    assert _grid.THREAD_VARIABLES is _threads.THREAD_VARIABLES   # one list, the command's
