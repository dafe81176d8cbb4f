"""The README is a user's page that stays true: its set-up commands are the ones CI runs, every
command line it shows parses, every Python example in it runs, its picture exists, and it tells no
development history."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from studies.cli import _main  # the command's parser: no public face

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
MAIN_JOB = ("python3 -m venv .venv && .venv/bin/pip install -e . && .venv/bin/flexvib run --out out/thesis.h5 "
            "&& .venv/bin/flexvib plot out/thesis.h5 --outdir out/figures")
TESTS = "python3 -m venv .venv && .venv/bin/pip install -e '.[test]' && .venv/bin/python -m pytest -q"


def _blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", README, re.S)


def test_the_two_set_up_commands_are_there_and_ci_runs_the_same_tests():
    commands = [line for block in _blocks("bash") for line in block.splitlines()]
    assert MAIN_JOB in commands and TESTS in commands
    ci = (ROOT / ".ci" / "run").read_text()
    assert "pip install -e '.[test]'" in ci and "python -m pytest -q" in ci


def test_every_command_line_shown_parses():
    parser = _main._parser()
    shown = 0
    for block in _blocks("bash"):
        for line in block.splitlines():
            for command in line.split("&&"):
                words = shlex.split(command.split("  #")[0].strip(), comments=True)
                if words and words[0].endswith("bin/flexvib"):
                    args = parser.parse_args(words[1:])     # exits (SystemExit) on a bad option
                    assert callable(args.handler)
                    shown += 1
    assert shown >= 10


@pytest.mark.slow
def test_the_python_examples_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)       # an example writes its figure where it runs
    blocks = _blocks("python")
    assert len(blocks) == 2
    for block in blocks:
        exec(compile(block, "README.md", "exec"), {})
    assert (tmp_path / "sweep.png").is_file()


def test_it_is_a_user_s_page():
    assert len(README.splitlines()) <= 250
    for word in ("session", "issue", "round", "seed"):
        assert not re.search(rf"\b{word}s?\b", README, re.I), word
    picture = re.search(r"!\[[^]]*\]\(([^)]+\.png)\)", README).group(1)
    assert (ROOT / picture).is_file() and (ROOT / picture).stat().st_size < 150_000
    assert "docs/make_figures.py" in README
    for section in ("## Set up", "## Reading the results", "## Scenes and examples", "## The command line",
                    "## From Python", "## Headline figures"):
        assert section in README
    for status in ("failed", "unstable", "outside_linear_range", "inaccurate", "near_resonance", "marginal",
                   "unresolved_stiff_mode", "ok"):
        assert f"| `{status}` |" in README, status
    assert "Python 3.11" in README and "mechanisms/scenes/" in README and "examples/" in README
    assert "(docs/benchmarks.md)" in README.split("## Headline figures")[1]
