"""Output paths bgc cannot write (issue 23, item 3, files) and the modes of what it writes
(item 6).

A bad output path (under a regular file, in a directory that takes no new files, under
/proc, a file where a directory is wanted) ends with exit 2 and one line naming the path
and what would be valid, before any work, leaving every directory as it was. Missing
directories are created (as ``mkdir -p`` would). Every file is written through
``fileio.atomic_write``: a temporary file renamed on success, removed on failure, with the
mode the umask asks for (``mkstemp`` alone gives 0600).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest
from helpers import ROOT, bgc, error_lines, snapshot

from bgc.errors import BgcError
from bgc.fileio import atomic_write, check_writable

RLC = ROOT / "models" / "rlc.yaml"


def refused(tmp_path: Path, *args, names: str):
    """Run bgc on ``args`` in ``tmp_path``: exit 2, at most two stderr lines naming
    ``names`` and a hint, no traceback, nothing in tmp_path (or /proc) changed."""
    before = snapshot(tmp_path)
    proc = bgc(*args, cwd=tmp_path)
    detail = f"\nstdout: {proc.stdout!r}\nstderr: {proc.stderr!r}"
    assert proc.returncode == 2, detail
    assert "Traceback" not in proc.stderr + proc.stdout, detail
    lines = error_lines(proc.stderr)
    assert 1 <= len(lines) <= 2 and lines[0].startswith("error: "), detail
    assert names in lines[0] and "(hint: " in lines[0], detail
    assert snapshot(tmp_path) == before, "the directory changed" + detail
    return lines[0]


@pytest.fixture
def work(tmp_path):
    """A directory holding a regular file and an output package with an existing module."""
    (tmp_path / "afile").write_text("keep me\n")
    gen = tmp_path / "gen"
    gen.mkdir()
    (gen / "__init__.py").write_text("# mine\n")
    return tmp_path


def test_files_output_dir_under_regular_file(work):
    refused(work, "compile", RLC, "-o", "afile/gen", names="'afile/gen'")


def test_files_output_dir_is_regular_file(work):
    err = refused(work, "compile", RLC, "-o", "afile", names="'afile'")
    assert "not a directory" in err


def test_files_output_dir_under_proc(work):
    refused(work, "compile", RLC, "-o", "/proc/bgc_gen", names="'/proc/bgc_gen'")
    assert not Path("/proc/bgc_gen").exists()


def test_files_csv_under_regular_file(work):
    refused(work, "simulate", RLC, "-o", "gen", "--out", "afile/x.csv", names="--out")


def test_files_csv_under_proc(work):
    refused(work, "simulate", RLC, "-o", "gen", "--out", "/proc/x.csv", names="'/proc/x.csv'")


def test_files_plot_in_missing_dir_under_proc(work):
    refused(work, "simulate", RLC, "-o", "gen", "--plot", "/proc/none/x.png",
            names="'/proc/none/x.png'")


def test_files_good_csv_bad_plot_changes_neither(work):
    """An existing CSV is not replaced when the run's plot path is bad (checked first)."""
    (work / "x.csv").write_text("old results\n")
    refused(work, "simulate", RLC, "-o", "gen", "--out", "x.csv", "--plot", "/proc/x.png",
            names="'/proc/x.png'")
    assert (work / "x.csv").read_text() == "old results\n"


def test_files_plot_unknown_format(work):
    err = refused(work, "simulate", RLC, "-o", "gen", "--plot", "x.xyz", names="'x.xyz'")
    assert ".png" in err


def test_files_frf_csv_under_regular_file(work):
    refused(work, "frf", RLC, "--input", "x", "--output", "current", "--out", "afile/f.csv",
            names="'afile/f.csv'")


def test_files_scene_output_under_regular_file(work):
    scene = work / "scene.yaml"
    scene.write_text(f"model: {RLC}\noutputs: [current]\ntime: {{end: 0.01, points: 11}}\n")
    refused(work, "run", scene, "--results", "afile/res", "-o", "gen", names="'afile/res'")
    refused(work, "run", scene, "--results", "res", "-o", "afile", names="'afile'")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only directory")
def test_files_read_only_dir(work):
    ro = work / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        refused(work, "compile", RLC, "-o", "ro/gen", names="'ro/gen'")
        refused(work, "simulate", RLC, "-o", "gen", "--out", "ro/x.csv", names="'ro/x.csv'")
    finally:
        ro.chmod(0o755)


def test_files_missing_dirs_are_created(tmp_path):
    """A missing output directory is created, parents included."""
    proc = bgc("compile", RLC, "-o", "new/deeper/gen", cwd=tmp_path, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "new/deeper/gen/rlc.py").is_file()
    assert (tmp_path / "new/deeper/gen/__init__.py").is_file()


def test_files_check_writable_leaves_nothing(tmp_path):
    """The probe of a writable directory leaves no file; a file where a directory is
    wanted, and a directory where a file is, are refused."""
    check_writable(tmp_path / "a" / "b.csv")
    check_writable(tmp_path / "out", directory=True)
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "f").write_text("")
    with pytest.raises(BgcError, match="not a directory"):
        check_writable(tmp_path / "f", directory=True)
    with pytest.raises(BgcError, match="a directory"):
        check_writable(tmp_path, "--out")


# ------------------------------------------------------------------ atomic writes
def test_files_failed_write_keeps_old_file_and_no_temp(tmp_path):
    """A writer failing (Ctrl-C included) halfway leaves the old file and no temporary."""
    target = tmp_path / "r.csv"
    target.write_text("old\n")

    for exc in (ValueError("boom"), KeyboardInterrupt()):
        def writer(tmp, exc=exc):
            Path(tmp).write_text("half")
            raise exc
        with pytest.raises(type(exc)):
            atomic_write(target, writer)
        assert target.read_text() == "old\n"
        assert sorted(p.name for p in tmp_path.iterdir()) == ["r.csv"]


def test_files_write_error_is_one_line_bgc_error(tmp_path):
    (tmp_path / "f").write_text("")
    with pytest.raises(BgcError, match=r"cannot write CSV '.*f/x.csv'"):
        atomic_write(tmp_path / "f" / "x.csv", "data", "CSV")


@pytest.mark.parametrize("mask,mode", [(0o022, 0o644), (0o027, 0o640), (0o077, 0o600)])
def test_atomic_write_respects_umask(tmp_path, mask, mode):
    old = os.umask(mask)
    try:
        a = atomic_write(tmp_path / "a.txt", "text")
        b = atomic_write(tmp_path / "b.bin", lambda tmp: Path(tmp).write_bytes(b"\0"))
    finally:
        os.umask(old)
    assert stat.S_IMODE(a.stat().st_mode) == mode
    assert stat.S_IMODE(b.stat().st_mode) == mode


@pytest.mark.parametrize("mask,mode", [  # 0o027 tells the umask's mode from a fixed 0o644
    pytest.param(0o022, 0o644, marks=pytest.mark.slow), (0o027, 0o640)])
def test_result_files_respect_umask(tmp_path, mask, mode):
    """bgc simulate's CSV, PNG and generated module get 0o666 & ~umask."""
    proc = bgc("simulate", RLC, "-o", "gen", "--t-end", "0.005", "--out", "r/x.csv",
               "--plot", "r/x.png", cwd=tmp_path, umask=mask, timeout=120)
    assert proc.returncode == 0, proc.stderr
    for f in ("r/x.csv", "r/x.png", "gen/rlc.py", "gen/__init__.py"):
        assert stat.S_IMODE((tmp_path / f).stat().st_mode) == mode, f
    assert (tmp_path / "r/x.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not [p for p in tmp_path.rglob("*.tmp")]
