"""The documentation: mkdocs builds it (strict: no broken link or reference) with the API reference
drawn from the docstrings, and every public name of the library has a docstring."""

from __future__ import annotations

import importlib
import inspect
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
API = [
    "ncadapt",
    "ncadapt.errors",
    "ncadapt.fields",
    "ncadapt.nc",
    "ncadapt.measure",
    "ncadapt.stats",
    "ncadapt.filters",
    "ncadapt.surfaces",
    "ncadapt.neighbours",
    "ncadapt.iso286",
    "ncadapt.cad",
    "ncadapt.heightmaps",
    "ncadapt.probing",
    "ncadapt.processes.freeform",
    "ncadapt.processes.bore",
    "ncadapt.processes.turning",
    "ncadapt.processes.skin",
    "ncadapt.processes.waffle",
]


def _public(module):
    names = getattr(module, "__all__", None) or [
        n
        for n, o in vars(module).items()
        if not n.startswith("_")
        and (inspect.isfunction(o) or inspect.isclass(o))
        and getattr(o, "__module__", "") == module.__name__
    ]
    return [(n, getattr(module, n)) for n in names]


def test_every_public_name_has_a_docstring():
    missing = []
    for name in API:
        for n, o in _public(importlib.import_module(name)):
            if not (inspect.isfunction(o) or inspect.isclass(o)):
                continue
            doc = (o.__doc__ or "").strip()
            # a dataclass without a docstring gets its signature as one
            if not doc or (inspect.isclass(o) and doc.startswith(o.__name__ + "(")):
                missing.append(f"{name}.{n}")
    assert missing == []


def test_the_documentation_builds(tmp_path):
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings")
    r = subprocess.run(
        [str(Path(sys.executable).with_name("mkdocs")), "build", "--strict", "-d", str(tmp_path / "site")],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    api = (tmp_path / "site" / "api" / "index.html").read_text()
    for name in ("GridField", "correct_file", "moran", "decompose", "read_plan", "deviations"):
        assert name in api, name
