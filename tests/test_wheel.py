"""The built wheel (``make wheel``) installed into a fresh virtual environment: the base install
corrects a program and says which extra the demo needs; with ``[all]`` the demo runs. Skipped
unless ``NCADAPT_WHEEL`` names the wheel (``make wheel`` builds it and runs this test)."""

from __future__ import annotations

import os
import subprocess
import sys
import venv
from pathlib import Path

import pytest

WHEEL = os.environ.get("NCADAPT_WHEEL")
EXAMPLES = Path(__file__).resolve().parent.parent / "examples"

pytestmark = pytest.mark.skipif(not WHEEL, reason="NCADAPT_WHEEL is not set (make wheel runs this test)")


def _venv(path: Path, spec: str) -> Path:
    venv.create(path, with_pip=True)
    py = path / "bin" / "python"
    subprocess.run([str(py), "-m", "pip", "install", "-q", spec], check=True)
    return path / "bin" / "ncadapt"


def test_the_wheel_is_manylinux_abi3_with_its_licence_and_types():
    import zipfile

    name = Path(WHEEL).name
    assert "-abi3-" in name and "manylinux" in name, name
    files = zipfile.ZipFile(WHEEL).namelist()
    assert "ncadapt/py.typed" in files and any(f.endswith("licenses/LICENSE") for f in files)


def test_base_install_corrects_and_names_the_missing_extra(tmp_path):
    exe = _venv(tmp_path / "base", WHEEL)
    out = tmp_path / "o.ngc"
    r = subprocess.run(
        [str(exe), "correct", str(EXAMPLES / "nc" / "plate.ngc"), "--shift", "0,0,0.01", "-o", str(out)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0 and out.stat().st_size > 0, r.stderr
    r = subprocess.run([str(exe), "demo", "--out", str(tmp_path / "d")], capture_output=True, text=True)
    assert r.returncode == 2 and "pip install 'ncadapt[" in r.stderr, r.stderr


def test_all_extras_run_the_demo(tmp_path):
    exe = _venv(tmp_path / "all", f"{WHEEL}[all]")
    r = subprocess.run([str(exe), "demo", "--out", str(tmp_path / "d")], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "d" / "compensated.step").stat().st_size > 0
    assert sys.version_info >= (3, 11)
