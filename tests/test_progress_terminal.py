"""Progress bars on a real (pseudo-)terminal, and none in redirected output: ``flexvib run`` in a
fresh process whose stderr is a pty (``pty.openpty``, never given a size: 0 columns, 0 rows, as under
``script`` without a terminal of its own, where tqdm alone draws nothing) or a file."""

from __future__ import annotations

import os
import pty
import subprocess
import sys
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _run_on_pty(args: list[str], timeout: float = 300.0) -> str:
    """stdout and stderr of ``python args`` run with both on a new pseudo-terminal (its size unset)."""
    master, slave = pty.openpty()
    assert os.get_terminal_size(slave) == (0, 0)  # the case tqdm alone draws nothing in
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    process = subprocess.Popen([sys.executable, *args], stdin=slave, stdout=slave, stderr=slave, env=env,
                               cwd=ROOT)
    os.close(slave)
    chunks, deadline = [], time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            try:
                chunk = os.read(master, 65536)
            except OSError:  # EIO: the child closed the terminal
                break
            if not chunk:
                break
            chunks.append(chunk)
    finally:
        os.close(master)
        process.wait(timeout=60)
    assert process.returncode == 0, b"".join(chunks).decode(errors="replace")
    return b"".join(chunks).decode(errors="replace")


def test_a_run_on_a_terminal_draws_a_bar_of_its_grid_points(tmp_path):
    out = _run_on_pty(["-m", "studies.cli", "run", "mathieu", "--out", str(tmp_path / "m.h5"),
                       "--only", "sweep", "--set", "studies.sweep.count=40"])
    assert "running sweep" in out
    assert "%|" in out and "/40 [" in out, out  # tqdm's bar: percentage, then points done of 40


def test_redirected_output_has_no_bar(tmp_path):
    log = tmp_path / "log.txt"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    with log.open("w") as handle:
        subprocess.run([sys.executable, "-m", "studies.cli", "run", "mathieu", "--out", str(tmp_path / "m.h5"),
                        "--only", "sweep", "--set", "studies.sweep.count=40"], stdout=handle, stderr=handle,
                       env=env, cwd=ROOT, check=True, timeout=300)
    text = log.read_text()
    assert "running sweep" in text
    assert "\r" not in text and "%|" not in text and "/40 [" not in text


_TICKING = textwrap.dedent("""
    import time
    from studies._progress import progress_bar  # the command's bars: no public face
    with progress_bar(["one study"], desc="studies", enabled=True, ticking=True, delay=0.3) as bar:
        for _ in bar:
            time.sleep(1.6)  # a study without grid points: the bar does not advance while it runs
""")


def test_a_ticking_bar_shows_its_clock_running_through_a_long_step():
    out = _run_on_pty(["-c", _TICKING])
    # drawn while the one step lasted (0/1), its elapsed time advancing, before it completed (1/1)
    waiting = [segment for segment in out.split("\r") if "0/1 [" in segment]
    assert any("00:01" in segment for segment in waiting), out
    assert "1/1 [" in out


def test_a_short_ticking_bar_never_shows():
    quick = _TICKING.replace("time.sleep(1.6)", "time.sleep(0.05)")
    assert "studies" not in _run_on_pty(["-c", quick])
