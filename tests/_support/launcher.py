"""Starts ``flexvib`` commands as child processes of one warm Python, for the fault-injection tests.

Each line on stdin is JSON ``{"argv": [...], "log": path}``; the launcher forks a child that runs
``studies.cli.main(argv)`` exactly as the ``flexvib`` script does, its stdout and stderr going to
``log``, prints ``pid PID``, waits for it and prints ``exit CODE`` (or ``signal NUMBER``). The child is a separate
process killed like a
command (SIGKILL, SIGTERM), but starts in milliseconds: the imports and the numba kernels are loaded
once here (``--warm ARGS...`` runs one command in-process first), so that twenty kills cost twenty
partial runs, not twenty interpreter start-ups.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import sys


def _child(argv: list[str], log: str) -> None:
    from studies.cli import main

    output = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(output, 1)
    os.dup2(output, 2)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        code = main(argv)
    except SystemExit as done:
        code = done.code if isinstance(done.code, int) else 1
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def run() -> None:
    from studies.cli import main

    if len(sys.argv) > 2 and sys.argv[1] == "--warm":
        with contextlib.redirect_stdout(io.StringIO()):  # stdout is the protocol
            main(sys.argv[2:])
    print("ready", flush=True)
    for line in sys.stdin:
        command = json.loads(line)
        pid = os.fork()
        if pid == 0:
            _child(command["argv"], command["log"])
        print(f"pid {pid}", flush=True)
        _, status = os.waitpid(pid, 0)
        if os.WIFSIGNALED(status):
            print(f"signal {os.WTERMSIG(status)}", flush=True)
        else:
            print(f"exit {os.WEXITSTATUS(status)}", flush=True)


if __name__ == "__main__":
    run()
