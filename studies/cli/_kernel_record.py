"""Write ``studies/cli/kernel_list.json`` (see :mod:`studies.cli._kernel_list`): the kernels and
signatures the warm-up of the main job (the default scene with its studies) compiles, step by step.
Run it in a fresh process on an empty numba cache after changing a kernel or a code path of the
warm-up (the command sets ``NUMBA_CACHE_DIR`` to a new empty folder when it is not set already):

    .venv/bin/python -m studies.cli._kernel_record

(``tests/test_jit.py`` fails, naming this command, when the list is out of date).
"""

from __future__ import annotations

import json

from ._jit import _attempt, _muted, warm_up_steps
from ._kernel_list import KERNEL_LIST, record
from ._main import DEFAULT_SCENE
from ._scene import ScenePlan


def main_job_list() -> list[dict[str, str]]:
    """The list entries of the main job, recorded in this process (run it in a fresh one)."""
    scene = ScenePlan.read(DEFAULT_SCENE)   # the problem and studies ``flexvib run`` would run
    steps = warm_up_steps(scene.problem, scene.studies)
    with _muted():
        return record([(name, lambda name=name, run=run: _attempt(name, run)) for name, run in steps])


if __name__ == "__main__":
    import os
    import subprocess
    import sys
    import tempfile

    if "NUMBA_CACHE_DIR" not in os.environ:   # numba reads it at import: record in a child process
        with tempfile.TemporaryDirectory(prefix="flexvib-empty-cache-") as empty:
            sys.exit(subprocess.call([sys.executable, "-m", "studies.cli._kernel_record"],
                                     env=dict(os.environ, NUMBA_CACHE_DIR=empty)))
    entries = main_job_list()
    KERNEL_LIST.write_text(json.dumps(entries, indent=1) + "\n")
    print(f"{len(entries)} kernel signatures written to {KERNEL_LIST}")
