"""Rounds of freeform compensation: the correction carried from one round to the next.

A part is cut with a corrected program, measured again, and the new correction is the previous one
plus a gain times the systematic error measured now:

    dF_k+1(u, v) = dF_k(u, v) + g_eff · s_k(u, v),    g_eff = G · w,

s_k the systematic part of the new measurement (:func:`ncadapt.processes.freeform.decompose`),
G the user's gain (``--gain``, default 1) and w ∈ [0, 1] the damping (:func:`damping`): the
share of the estimate's mean square that is not what the same filter returns from noise alone,
w = max(0, 1 − L / S), S = mean(s²), L = mean(f(ε)²) with ε white normal noise of the estimated
noise std (a positive-part James–Stein shrink). On a part with noise only, s is filtered noise,
S ≈ L and the correction hardly moves; on a strong systematic error w → 1.

The correction a round needs is the field dF over the compensation grid, written to the JSON of
``compensate`` under ``correction`` (:meth:`Correction.as_dict`) and read back by
``compensate --previous`` (:func:`read`). dF is in mm along the nominal's outward normal (> 0:
material left, the part is cut at P − dF·n).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError

# the JSON key of the correction, and its format's version
KEY = "correction"
FORMAT = 1
# white-noise draws the damping averages over (seeded)
DAMPING_DRAWS = 4
# frames of two rounds must agree to this (their axes' components)
FRAME_TOL = 1e-9


def damping(method: str, xy, systematic, parameters: dict, *, seed: int = 0) -> float:
    """w = max(0, 1 − L / S) ∈ [0, 1]: S = mean(systematic²) mm², L the mean square that the same
    filter (``method`` with the decomposition's ``parameters``, incl. ``noise_estimate`` σ mm) returns
    from white normal noise of std σ at the points ``xy`` (n, 2) mm, averaged over
    :data:`DAMPING_DRAWS` seeded draws."""
    from . import freeform as pf

    s = np.asarray(systematic, float)
    S = float(np.mean(s * s))
    sigma = float(parameters.get("noise_estimate", 0.0))
    if S == 0.0:
        return 0.0
    if sigma == 0.0:
        return 1.0
    keys = ("sigma_c", "sigma_s") if method == "bilateral" else ("p",)
    par = {k: parameters[k] for k in keys}
    rng = np.random.default_rng(seed)
    L = float(
        np.mean(
            [
                np.mean(pf._filter(method, xy, sigma * rng.standard_normal(len(s)), par) ** 2)
                for _ in range(DAMPING_DRAWS)
            ]
        )
    )
    return float(np.clip(1.0 - L / S, 0.0, 1.0))


@dataclass(frozen=True)
class Grid:
    """dF (mm) on a grid: ``u`` (nu,), ``v`` (nv,) its axes (mm in a frame's (u, v), or a CAD face's
    own parameters), ``df`` (nu, nv) mm; ``face`` the CAD face's 1-based id (None for a frame)."""

    u: np.ndarray
    v: np.ndarray
    df: np.ndarray
    face: int | None = None

    def at(self, U, V) -> np.ndarray:
        """dF at (U, V) (any shape): bilinear on the grid, the nearest edge value beyond it."""
        from scipy.interpolate import RegularGridInterpolator

        U, V = np.asarray(U, float), np.asarray(V, float)
        q = np.stack([np.clip(U, self.u[0], self.u[-1]), np.clip(V, self.v[0], self.v[-1])], axis=-1)
        return RegularGridInterpolator((self.u, self.v), self.df)(q)

    def as_dict(self) -> dict:
        """``u``, ``v``, ``df`` (and ``face``) as lists."""
        d = {"u": self.u.tolist(), "v": self.v.tolist(), "df": self.df.tolist()}
        return ({"face": self.face} | d) if self.face is not None else d


@dataclass(frozen=True)
class Correction:
    """The correction of a round: ``kind`` "frame" (a nominal from the measured points: one grid over
    the frame's (u, v), ``frame`` (3, 3) its axes) or "faces" (a CAD nominal: one grid per compensated
    face in its own (u, v); ``nominal`` the CAD file's name and ``sha256``); ``round`` 1 for a first
    compensation; ``gains`` {face id or 0: the effective gain of this round}."""

    kind: str
    grids: tuple[Grid, ...]
    round: int = 1
    frame: np.ndarray | None = None
    nominal: dict | None = None
    gains: dict | None = None

    def grid(self, face: int | None = None) -> Grid | None:
        """The grid of CAD face ``face`` (None: the frame's), or None when there is none."""
        return next((g for g in self.grids if g.face == face), None)

    def as_dict(self) -> dict:
        """The JSON object ``correction`` (docs/freeform.md gives its keys)."""
        d: dict = {"format": FORMAT, "kind": self.kind, "units": "mm", "round": self.round}
        if self.frame is not None:
            d["frame"] = np.asarray(self.frame).tolist()
        if self.nominal is not None:
            d["nominal"] = self.nominal
        if self.gains is not None:
            d["gains"] = {str(k): v for k, v in self.gains.items()}
        if self.kind == "frame":
            d |= self.grids[0].as_dict()
        else:
            d["faces"] = [g.as_dict() for g in self.grids]
        return d


def file_digest(path) -> str:
    """SHA-256 of a file (hex): which CAD nominal a correction belongs to."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def read(path) -> Correction:
    """The ``correction`` of a ``compensate --json`` file; refused (located) when absent or malformed."""
    src = str(path)
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(f"--previous: not a JSON file of compensate ({e})", src) from None
    c = doc.get(KEY) if isinstance(doc, dict) else None
    if not isinstance(c, dict):
        raise InputError(f"--previous: no '{KEY}' object (write it with compensate --json)", src)
    if c.get("format") != FORMAT or c.get("units") != "mm" or c.get("kind") not in ("frame", "faces"):
        raise InputError(f"--previous: '{KEY}' must have format {FORMAT}, units mm and kind frame or faces", src)

    def grid(g, where) -> Grid:
        try:
            u, v, df = (np.asarray(g[k], float) for k in ("u", "v", "df"))
        except (KeyError, TypeError, ValueError):
            raise InputError(f"--previous: {where} needs numeric u, v and df", src) from None
        ok = (
            u.ndim == 1
            and v.ndim == 1
            and len(u) >= 2
            and len(v) >= 2
            and df.shape == (len(u), len(v))
            and np.isfinite(df).all()
            and np.all(np.diff(u) > 0)
            and np.all(np.diff(v) > 0)
        )
        if not ok:
            raise InputError(f"--previous: {where}: u, v must increase and df be finite, len(u) x len(v)", src)
        return Grid(u, v, df, g.get("face"))

    rnd = c.get("round", 1)
    if not isinstance(rnd, int) or rnd < 1:
        raise InputError("--previous: 'round' must be a positive integer", src)
    if c["kind"] == "frame":
        frame = np.asarray(c.get("frame", np.eye(3)), float)
        if frame.shape != (3, 3) or not np.allclose(frame @ frame.T, np.eye(3), atol=1e-9):
            raise InputError("--previous: 'frame' must be 3 orthonormal rows", src)
        return Correction("frame", (grid(c, KEY),), rnd, frame=frame)
    faces = c.get("faces")
    if (
        not isinstance(faces, list)
        or not faces
        or not all(isinstance(g, dict) and isinstance(g.get("face"), int) for g in faces)
    ):
        raise InputError("--previous: 'faces' must list the faces' grids, each with its integer face id", src)
    return Correction("faces", tuple(grid(g, f"face {g['face']}") for g in faces), rnd, nominal=c.get("nominal"))


def check_frame(previous: Correction, frame_axes, source: str) -> None:
    """Refuse a previous correction made for a nominal from the measured points in another frame,
    or for a CAD nominal."""
    if previous.kind != "frame":
        raise InputError("--previous holds the correction of a CAD nominal: give --nominal as in that round", source)
    assert previous.frame is not None
    if not np.allclose(previous.frame, frame_axes, atol=FRAME_TOL):
        raise InputError(
            "--previous was made in another frame (its (u, v) do not match this measurement's): measure the part "
            "as in that round",
            source,
        )


def check_nominal(previous: Correction, nominal, faces, source: str) -> None:
    """Refuse a previous correction made for another CAD file, or for faces not measured now."""
    if previous.kind != "faces":
        raise InputError(
            "--previous holds the correction of a nominal from the measured points: leave out --nominal", source
        )
    digest = (previous.nominal or {}).get("sha256")
    if digest != file_digest(nominal):
        raise InputError(f"--previous was made against another CAD file than {nominal} (its SHA-256 differs)", source)
    missing = [g.face for g in previous.grids if g.face not in faces]
    if missing:
        raise InputError(
            f"--previous corrects face {missing[0]}, which no point of this measurement fell on: measure it again",
            source,
        )
