"""The package's metadata: one version everywhere, the licence shipped."""

from __future__ import annotations

import re
import tomllib
from importlib.metadata import metadata, version
from pathlib import Path

import ncadapt

ROOT = Path(__file__).resolve().parent.parent


def test_one_version_in_cargo_python_and_the_metadata():
    versions = {
        tomllib.loads((ROOT / c / "Cargo.toml").read_text())["package"]["version"]
        for c in ("crates/nc", "crates/nc-py")
    }
    assert versions == {ncadapt.__version__} == {version("ncadapt")}
    assert re.fullmatch(r"\d+\.\d+\.\d+", ncadapt.__version__)


def test_the_licence_is_apache_2_0():
    meta = metadata("ncadapt")
    assert "Apache-2.0" in (meta.get("License-Expression") or meta.get("License") or "")
    text = (ROOT / "LICENSE").read_text()
    assert "Apache License" in text and "Version 2.0, January 2004" in text
    for c in ("crates/nc", "crates/nc-py"):
        assert tomllib.loads((ROOT / c / "Cargo.toml").read_text())["package"]["license"] == "Apache-2.0"
