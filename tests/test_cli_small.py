"""Small things of the command: a resume keeps the compile time of the file's earlier runs, ``flexvib
info`` prints numbers and units for a person, ``flexvib check`` says each warning once, the "no drive"
error names the scene's ``[drive]`` table, ``flexvib report`` of a missing file makes no folder."""

from __future__ import annotations

import re

import h5py
import pytest

import mechanisms
from studies._resultfile import ResultFile  # the run's writer of result files: no public face
from studies.cli import main


@pytest.fixture(scope="module")
def mathieu_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("small") / "m.h5"
    assert main(["run", "mathieu", "--out", str(path), "--only", "steady_state", "--only", "sweep",
                 "--quiet"]) == 0
    return path


def test_a_resume_adds_to_the_file_s_compile_time(mathieu_file, tmp_path):
    path = tmp_path / "resumed.h5"
    path.write_bytes(mathieu_file.read_bytes())
    with h5py.File(path, "r") as handle:
        first = float(handle.attrs["compile_time"])
    # as if the first run had compiled for 7.5 s more, written as a run writes it: through the result
    # file, whose commit seals the file's attributes again (an edit beside it is damage, refused)
    with ResultFile(path) as file, file.writing():
        file.handle.attrs["compile_time"] = first + 7.5
    assert main(["run", "mathieu", "--out", str(path), "--only", "steady_state", "--only", "sweep",
                 "--quiet"]) == 0
    with h5py.File(path, "r") as handle:
        # the resume (warm: it compiles little or nothing) adds its own, never replaces
        assert float(handle.attrs["compile_time"]) >= first + 7.5


def test_info_prints_rounded_numbers_with_units(mathieu_file, capsys):
    assert main(["info", str(mathieu_file)]) == 0
    out = capsys.readouterr().out
    studies_part = out.split("\n[", 1)[1]                   # after the file's header (versions, date)
    for number in re.findall(r"(?<![\w.])\d+\.\d+(?:e[-+]?\d+)?(?![\w.])", studies_part):
        digits = number.split("e")[0].replace(".", "").lstrip("0")
        assert len(digits) <= 4, number                     # no 99.99999999999999
    assert not re.search(r"\(\d+[,)].* 1$", out, re.M)      # no "(45,) 1": dimensionless in words
    assert "dimensionless" in out
    assert "point_digest" not in out and "point_outputs" not in out   # the checksums: bookkeeping
    assert re.search(r"run_time: [\d.]+ s$", out, re.M)
    assert re.search(r"spectral_radius: \d+(\.\d+)?, dimensionless", out) or "spectral_radius: " in out


@pytest.mark.slow
def test_check_says_a_warning_once_after_the_table(capsys):
    case = "stiff axial mode (1e4 x crank)"     # its axially rigid coupler makes the model warn
    assert main(["check", "--case", case, "--case", case]) == 0
    captured = capsys.readouterr()
    text = "geometric stiffening needs axial coordinates"
    # collected while the cases run and said once after the table, as flexvib run does (the log
    # record itself reached stderr as it came, once per assembly)
    assert captured.err.count(text) == 1, captured.err
    assert captured.err.startswith(f"warning: link 'coupler': {text}")
    assert text not in captured.out


def test_no_drive_names_the_drive_table(tmp_path, capsys):
    text = mechanisms.load("four_bar_thesis").to_toml()
    assert "[drive]" in text
    scene = tmp_path / "undriven.toml"
    scene.write_text(text.split("[drive]")[0])     # the scene without its drive (and what follows it)
    assert main(["run", str(scene), "--out", str(tmp_path / "u.h5")]) == 2
    err = capsys.readouterr().err
    assert "[drive]" in err and "PrescribedDrive" not in err and "TorqueDrive" not in err
    assert "joint = \"O\"" in err


def test_report_of_a_missing_file_makes_no_folder(tmp_path, capsys):
    missing = tmp_path / "nosuch.h5"
    assert main(["report", str(missing)]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert not (tmp_path / "nosuch_report").exists()
    assert list(tmp_path.iterdir()) == []
