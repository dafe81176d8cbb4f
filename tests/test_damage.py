"""Issue 23: result files that detect damage (result format 3, ``studies._integrity``).

64 bytes flipped at 17 offsets of a finished file (12 spread evenly over it, 5 on a grid study's
point data, a single study's data, the file's own attributes, the global heap of its text and a
point dataset's attributes):
``flexvib info`` either names the damaged study or the file (exit 1, or 2 for a file no longer
recognisable as HDF5) or the bytes were unused (the file loads to the undamaged numbers); running
the same command again (with ``--overwrite`` where the run says the file cannot be resumed) ends
with the undamaged run's numbers to the last bit. A damaged grid point is recomputed alone; a file
whose metadata is damaged is moved aside, never deleted; a format-2 file (no checksums) reads as
"not verifiable"."""

import contextlib
import io
import shutil
from pathlib import Path

import h5py
import pytest

import studies
from studies import _grid  # patched: counts the points a resume computes (internal)
from studies.cli import main

ROOT = Path(__file__).resolve().parents[1]
ONLY = ["--only", "steady_state", "--only", "sweep", "--only", "campbell"]


def _main(argv) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


def _run(path: Path, *extra: str) -> tuple[int, str]:
    code, _, err = _main(["run", "mathieu", "--out", path, "--quiet", *ONLY, *extra])
    return code, err


@pytest.fixture(scope="module")
def undamaged(tmp_path_factory) -> tuple[Path, dict]:
    path = tmp_path_factory.mktemp("undamaged") / "mathieu.h5"
    assert _run(path)[0] == 0
    return path, studies.load(path)


def _flip(path: Path, offset: int, count: int = 64) -> None:
    with open(path, "r+b") as raw:
        raw.seek(offset)
        data = bytearray(raw.read(count))
        raw.seek(offset)
        raw.write(bytes(b ^ 0xFF for b in data))


def _same(results: dict, expected: dict, assert_same) -> None:
    assert results.keys() == expected.keys()
    for name in expected:
        assert_same(expected[name], results[name])


def _offsets(path: Path) -> list[tuple[str, int]]:
    size = path.stat().st_size
    spread = [(f"at {k}/12 of the file", int(k * (size - 64) / 11)) for k in range(12)]
    with h5py.File(path, "r") as handle:
        sweep = handle["sweep"]
        grid = next(sweep[name] for name in ("spectral_radius", "point_run_time") if name in sweep)
        steady = handle["steady_state"]
        single = next(steady[name] for name in steady if hasattr(steady[name], "shape")
                      and steady[name].id.get_offset() is not None and steady[name].size > 8)
        targeted = [("a grid study's point data", grid.id.get_offset()),
                    ("a single study's data", single.id.get_offset())]
    data = path.read_bytes()
    targeted.append(("the file's own attributes", data.index(b"scene_hash")))  # the attribute's name
    targeted.append(("the global heap of the text", data.index(b"GCOL")))  # strings: messages, requests
    # a point dataset's own attribute (its object header, which the resume reads: not in any digest)
    targeted.append(("a point dataset's attributes", data.index(b"grid_points")))
    return spread + targeted


@pytest.mark.slow
def test_damage_at_17_offsets_is_found_and_the_rerun_restores_the_undamaged_numbers(undamaged, tmp_path,
                                                                                    assert_same):
    source, expected = undamaged
    detected = 0
    for what, offset in _offsets(source):
        path = tmp_path / f"damaged_{offset}.h5"
        shutil.copyfile(source, path)
        _flip(path, offset)
        code, out, err = _main(["info", path])
        if code == 0:
            # the bytes were not in use: nothing to find, and the file still holds the same numbers
            assert "Traceback" not in err and not what.startswith(("a ", "the ")), (what, out)
            _same(studies.load(path), expected, assert_same)
        else:
            detected += 1
            assert code in (1, 2) and err.startswith("flexvib: error: ") and err.count("\n") == 1, (what, err)
            assert "Traceback" not in err and "internal error" not in err, (what, err)
            assert str(path) in err and ("damaged" in err or "cannot read" in err or "not an HDF5" in err), \
                (what, err)
            with pytest.raises(studies.StudiesError):
                studies.load(path)
        code, err = _run(path)
        if code == 2:  # the file's own metadata is damaged: the run says how to start afresh
            assert "--overwrite" in err and "Traceback" not in err, (what, err)
            unreadable = "cannot be resumed" in err
            code, err = _run(path, "--overwrite")
            if unreadable:   # moved aside, not deleted
                assert list(tmp_path.glob(f"{path.name}.damaged-*")), what
        assert code == 0, (what, err)
        assert _main(["info", path])[0] == 0, what
        _same(studies.load(path), expected, assert_same)
    assert detected >= 10, detected


def test_a_damaged_grid_point_is_recomputed_alone(undamaged, tmp_path, monkeypatch, assert_same):
    source, expected = undamaged
    path = tmp_path / "one_point.h5"
    shutil.copyfile(source, path)
    with h5py.File(path, "r+") as handle:   # one value of point 7 changed, its checksum not
        dataset = handle["sweep"]["spectral_radius"]
        dataset[7] = dataset[7] * (1.0 + 1e-12)
    code, out, err = _main(["info", path])
    assert code == 1 and "[sweep]" in out and "1 of 57 points" in out, out
    assert "sweep" in err and "damaged" in err
    computed = []
    evaluate = _grid.evaluate

    def counting(point, problem, values, options):
        computed.append(dict(values))
        return evaluate(point, problem, values, options)

    monkeypatch.setattr(_grid, "evaluate", counting)
    assert _run(path)[0] == 0
    assert len(computed) == 1
    _same(studies.load(path), expected, assert_same)


def test_a_damaged_single_study_is_recomputed_and_the_others_kept(undamaged, tmp_path, assert_same):
    source, expected = undamaged
    path = tmp_path / "steady.h5"
    shutil.copyfile(source, path)
    with h5py.File(path, "r+") as handle:
        handle["steady_state"].attrs["spectral_radius"] = "0.5"   # a headline number changed
    code, out, err = _main(["info", path])
    assert code == 1 and "[steady_state] steady_state of mathieu, DAMAGED" in out
    assert "[sweep] sweep of mathieu, complete, checksums match" in out
    with pytest.raises(studies.StudiesError, match="steady_state"):
        studies.load(path)
    assert _run(path)[0] == 0
    _same(studies.load(path), expected, assert_same)


def test_overwrite_moves_an_unreadable_result_file_aside_in_one_line(undamaged, tmp_path, capsys):
    source, _ = undamaged
    path = tmp_path / "broken.h5"
    shutil.copyfile(source, path)
    _flip(path, 0, 512)   # the superblock: no longer HDF5 at all
    damaged_bytes = path.read_bytes()
    code, err = _run(path)
    assert code == 2 and "is damaged" in err and "--overwrite" in err and err.count("\n") == 1, err
    assert path.read_bytes() == damaged_bytes   # refused: untouched
    code, _, err = _main(["run", "mathieu", "--out", path, "--overwrite", *ONLY])
    assert code == 0
    lines = [line for line in err.splitlines() if "moved it aside" in line]
    assert len(lines) == 1 and f"{path.name}.damaged-1" in lines[0], err
    assert (tmp_path / f"{path.name}.damaged-1").read_bytes() == damaged_bytes
    # a second time: the next free name
    _flip(path, 0, 512)
    assert _run(path, "--overwrite")[0] == 0
    assert (tmp_path / f"{path.name}.damaged-2").is_file()


def test_a_file_of_an_older_format_reads_as_not_verifiable(tmp_path):
    for name in ("mathieu_format1.h5", "results_before_core.h5"):
        code, out, err = _main(["info", ROOT / "tests" / "data" / name])
        assert code == 0, err
        assert "not verifiable" in out and "DAMAGED" not in out
        assert studies.load(ROOT / "tests" / "data" / name)


def test_an_interrupted_grid_verifies_and_resumes(undamaged, tmp_path, monkeypatch, assert_same):
    """A grid study cut after some points (as a kill leaves it) is intact by its checksums, not
    damaged; its points then resume to the undamaged numbers."""
    _, expected = undamaged
    path = tmp_path / "cut.h5"
    evaluate = _grid.evaluate
    calls = []

    def cut(point, problem, values, options):
        if len(calls) == 20:
            raise KeyboardInterrupt
        calls.append(1)
        return evaluate(point, problem, values, options)

    monkeypatch.setattr(_grid, "evaluate", cut)
    assert _run(path)[0] == 130
    code, out, err = _main(["info", path])
    assert code == 0 and "INCOMPLETE, checksums match" in out, (out, err)
    monkeypatch.setattr(_grid, "evaluate", evaluate)
    assert _run(path)[0] == 0
    _same(studies.load(path), expected, assert_same)
