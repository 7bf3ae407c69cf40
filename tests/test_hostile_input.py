"""Hostile model files (issue 23, item 3): each gets exit status 2 and one located line
within 10 s, never a traceback or a hang. Test ids name the category (test_yaml_...)."""

import os
import subprocess
import sys

import pytest

from test_bad_input import ERROR_LINE

BGC = [sys.executable, "-c", "from bgc.cli import main; main()"]


def _refused(args, cwd, contains):
    proc = subprocess.run(BGC + args, capture_output=True, text=True, cwd=cwd, timeout=10)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert 1 <= len(lines) <= 2, proc.stderr
    assert lines[0].startswith("error: "), lines[0]
    assert contains in lines[0], lines[0]
    return lines[0]


def _bomb(levels=9):
    rows = ['l0: &l0 ["x", "x", "x", "x", "x", "x", "x", "x", "x"]']
    for i in range(1, levels):
        rows.append(f"l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * 9) + "]")
    return "\n".join(rows) + "\n"


YAML_TEXTS = {
    "billion_laughs": (_bomb(), "expands to more than"),
    "recursive_alias": ("elements: &a\n  r: [*a]\nbonds: []\n", "nested more than"),
    "deep_flow_nesting": ("x: " + "[" * 20000 + "]" * 20000 + "\n", "nested too deeply"),
    "deep_block_nesting": ("".join("  " * i + f"k{i}:\n" for i in range(200)) + "  " * 200
                           + "v: 1\n", "nested more than"),
    "python_tag": ('elements: !!python/object/apply:os.system ["touch PWNED"]\nbonds: []\n',
                   "tag 'tag:yaml.org,2002:python/object/apply:os.system' is not allowed"),
    "python_name_scalar": ("elements: {r: {type: R, R: !!python/name:os.system ''}}\n",
                           "is not allowed"),
    "unknown_tag": ("elements: !custom {r: 1}\nbonds: []\n", "tag '!custom' is not allowed"),
}


@pytest.mark.parametrize("case", sorted(YAML_TEXTS))
def test_yaml_hostile_text_is_refused(tmp_path, case):
    text, contains = YAML_TEXTS[case]
    (tmp_path / "m.yaml").write_text(text)
    line = _refused(["check", "m.yaml"], tmp_path, contains)
    assert ERROR_LINE.match(line), line
    assert not (tmp_path / "PWNED").exists()


def test_yaml_non_utf8_names_the_line(tmp_path):
    (tmp_path / "m.yaml").write_bytes(b"elements:\n  r: {type: R}\n\xff\xfe: 1\n")
    line = _refused(["check", "m.yaml"], tmp_path, "not UTF-8")
    assert line.startswith("error: m.yaml:3:"), line


def test_yaml_50_mb_file_is_refused_quickly(tmp_path):
    with open(tmp_path / "m.yaml", "wb") as fh:
        fh.write(b"elements:\n" + b"# padding\n" * (5 * 1024 * 1024))
    _refused(["check", "m.yaml"], tmp_path, "bytes; a model file has at most")


def test_yaml_fifo_as_model_does_not_block(tmp_path):
    os.mkfifo(tmp_path / "m.yaml")
    _refused(["check", "m.yaml"], tmp_path, "is a FIFO")


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom", "/dev/null"])
def test_yaml_device_as_model_is_refused(tmp_path, device):
    if not os.path.exists(device):
        pytest.skip(f"no {device}")
    _refused(["check", device], tmp_path, "device")


def test_yaml_directory_as_model_is_refused(tmp_path):
    (tmp_path / "d.yaml").mkdir()
    proc = subprocess.run(BGC + ["check", "d.yaml"], capture_output=True, text=True,
                          cwd=tmp_path, timeout=10)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "directory" in proc.stderr


@pytest.mark.parametrize("cmd", ["compile", "simulate"])
def test_yaml_bomb_leaves_output_directory_untouched(tmp_path, cmd):
    (tmp_path / "m.yaml").write_text(_bomb())
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    flag = "-o" if cmd == "compile" else "--out"
    target = str(out) if cmd == "compile" else str(out / "r.csv")
    _refused([cmd, "m.yaml", flag, target], tmp_path, "expands to more than")
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]
    assert (out / "keep.txt").read_text() == "mine"


def test_yaml_aliases_within_bounds_still_work(tmp_path):
    """Anchors and aliases are YAML a model may use: only an explosion is refused."""
    (tmp_path / "m.yaml").write_text(
        "parameters:\n  R: &ohm {value: 10.0, unit: ohm}\n  R2: *ohm\n"
        "  L: {value: 0.05, unit: H}\n  C: {value: 2.0e-5, unit: F}\n"
        "elements:\n  source: {type: Se, effort: 1.0}\n  loop: {type: \"1\"}\n"
        "  resistor: {type: R, R: R + R2}\n  inductor: {type: I, I: L}\n"
        "  capacitor: {type: C, C: C}\n"
        "bonds: [[source, loop], [loop, resistor], [loop, inductor], [loop, capacitor]]\n")
    proc = subprocess.run(BGC + ["check", "m.yaml"], capture_output=True, text=True,
                          cwd=tmp_path, timeout=30)
    assert proc.returncode == 0, proc.stderr
