"""What a plain `pip install` of bgc carries: every module, the SARIB and every other
model, the scenes and the library of components (the repository's models/, scenes/ and
library/ as bgc.data.models, bgc.data.scenes and bgc.data.library, pyproject.toml's
package-dir), found from any directory."""

from __future__ import annotations

import json
import os
import posixpath
import shutil
import subprocess
import sys
import venv
import zipfile
from pathlib import Path

import pytest
import yaml
from helpers import ROOT

from bgc import data

# what setuptools reads to build the wheel
SOURCES = ("pyproject.toml", "README.md", "bgc", "models", "scenes", "library")


def build_wheel(tmp_path: Path) -> Path:
    """``pip wheel --no-deps`` of a copy of the repository's sources (setuptools builds
    in the source tree: the repository is left as it is). pip fetches the build backend
    the project names (setuptools, wheel) into its isolated build: offline and without
    pip's cache, this fails and says so."""
    src = tmp_path / "src"
    src.mkdir()
    for name in SOURCES:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, src / name,
                            ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(ROOT / name, src / name)
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w",
                        str(tmp_path / "wheel"), str(src)], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    return next((tmp_path / "wheel").glob("bgc-*.whl"))


@pytest.mark.slow      # building the wheel: 4 s; `make test-all`
def test_the_wheel_carries_every_module_model_and_scene(tmp_path):
    with zipfile.ZipFile(build_wheel(tmp_path)) as z:
        names = set(z.namelist())
        shipped = {f"bgc/{p.relative_to(ROOT / 'bgc')}" for p in (ROOT / "bgc").rglob("*")
                   if p.is_file() and "__pycache__" not in p.parts}
        assert shipped <= names, sorted(shipped - names)
        for folder in data.FOLDERS:
            for p in sorted((ROOT / folder).glob("*.yaml")):
                assert z.read(f"bgc/data/{folder}/{p.name}") == p.read_bytes(), p
        assert {n.split("/")[0] for n in names} == {"bgc", "bgc-0.1.0.dist-info"}
        for scene in (ROOT / "scenes").glob("*.yaml"):      # its model, by its path
            model = yaml.safe_load(scene.read_text())["model"]
            assert posixpath.normpath(f"bgc/data/scenes/{model}") in names, scene


def test_a_shipped_scene_finds_the_shipped_model_from_another_directory(tmp_path):
    code = ("from bgc import data; from bgc.scene.scenes import load_scene\n"
            "print(data.path('models', 'sarib.yaml').resolve())\n"
            "print(load_scene(data.path('scenes', 'pumping_chirp.yaml')).model)")
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                       text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=120)
    assert r.returncode == 0, r.stderr
    shipped, model = r.stdout.split()
    assert shipped == model == str((ROOT / "models" / "sarib.yaml").resolve())
    assert data.names("scenes") == sorted(p.name for p in (ROOT / "scenes").glob("*.yaml"))


@pytest.mark.slow      # a venv, the SARIB compiled cold and numba's loops: a few minutes
def test_an_installed_wheel_runs_the_main_job_from_an_empty_directory(tmp_path):
    wheel = build_wheel(tmp_path)
    env_dir = tmp_path / "venv"
    venv.create(env_dir, system_site_packages=True, with_pip=True)   # its dependencies
    py = env_dir / "bin" / "python"
    subprocess.run([py, "-m", "pip", "install", "-q", "--no-deps", "--ignore-installed",
                    wheel], check=True, timeout=300)    # not the bgc of the system's site
    work = tmp_path / "empty"
    work.mkdir()
    r = subprocess.run([env_dir / "bin" / "bgc", "simulate", "--excitation", "chirp",
                        "--t-end", "0.05", "--json", "--quiet"], cwd=work,
                       capture_output=True, text=True, timeout=900,
                       env=dict(os.environ, PYTHONPATH="",
                                NUMBA_CACHE_DIR=str(tmp_path / "nc")))
    assert r.returncode == 0, r.stderr
    files = json.loads(r.stdout)["files"]
    assert files == {"csv": "results/sarib_pumping_chirp.csv",
                     "png": "results/sarib_pumping_chirp.png",
                     "report": "results/sarib_pumping_chirp.html"}   # its template shipped
    assert (work / "generated" / "sarib_zcp.py").is_file()      # the main job: zcp
    where = subprocess.run([py, "-c", "from bgc import data; print(data.folder('models'))"],
                           cwd=work, capture_output=True, text=True, check=True,
                           env=dict(os.environ, PYTHONPATH=""))
    assert Path(where.stdout.strip()).is_relative_to(env_dir)     # the wheel's, not ROOT's


def test_a_scene_name_is_the_shipped_scene_where_no_such_file_is(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    shipped = data.path("scenes", "pumping_chirp.yaml")
    assert data.find("scenes", "pumping_chirp") == data.find("scenes", shipped.name) == shipped
    assert data.find("scenes", "sub/pumping_chirp") == Path("sub/pumping_chirp")
    assert data.find("scenes", "no_such_scene") == Path("no_such_scene")
    (tmp_path / "pumping_chirp.yaml").write_text("model: mine.yaml\n")
    assert data.find("scenes", "pumping_chirp.yaml") == Path("pumping_chirp.yaml")   # own file
