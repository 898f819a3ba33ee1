"""Readers of actual points only (no nominal, no normal): the measurement of a part whose nominal is
its CAD model — CSV ``x,y,z``, DMIS ``FA(label)=FEAT/POINT`` outputs, QIF 3 ``PointFeatureActual``."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._io import csv_reader
from ..errors import InputError
from ._readers import (
    _number,
    _scale,
    dmis_points,
    local_name,
    qif_root,
    qif_scale,
    sniffed,
)


@dataclass(frozen=True)
class Actuals:
    """Actual points of a measurement file: ``points`` (n, 3) mm, the 1-based ``lines`` (n,) of the
    file they were read from (the element's line in a QIF file), their ``ids`` (labels; None when
    the file has none) and the file's name (``source``)."""

    points: np.ndarray
    lines: np.ndarray
    ids: tuple[str, ...] | None
    source: str


def read_actuals(path, units: str | None = None) -> Actuals:
    """Actual points only, the reader chosen from the file's contents: QIF 3 measured points
    (:func:`read_qif_actuals`), DMIS actuals (:func:`read_dmis_actuals`), else a CSV with a header
    naming ``x,y,z`` (optional ``id``; :func:`read_csv_actuals`). ``units``: the length unit of a file
    that declares none (mm by default); a file's own must agree. The points come back in mm."""
    p, kind = sniffed(path, units)
    if kind == "qif":
        return read_qif_actuals(p, units)
    if kind == "dmis":
        return read_dmis_actuals(p, units)
    if kind == "plan":
        raise InputError(
            "an ncadapt probe plan holds its own nominal points: read it without --nominal "
            "(ncadapt analyze PLAN.csv), or give the actual points alone",
            str(p),
            1,
        )
    return read_csv_actuals(p, units)


def read_csv_actuals(path, units: str | None = None) -> Actuals:
    """A CSV of actual points: a header naming ``x,y,z`` (optional ``id``), in mm unless ``units``
    says otherwise."""
    src = str(Path(path))
    rows = csv_reader(path)
    try:
        header = [h.strip().lower() for h in next(rows)]
    except StopIteration:
        raise InputError("empty file", src) from None
    if not all(c in header for c in "xyz"):
        raise InputError(f"header must name x,y,z (optional id); got {','.join(header)}", src, 1)
    k = [header.index(c) for c in "xyz"]
    pts, lines, ids = [], [], []
    for row in rows:
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise InputError(f"{len(row)} fields, the header has {len(header)}", src, rows.line_num)
        pts.append([_number(row[j], src, rows.line_num, c) for j, c in zip(k, "xyz")])
        lines.append(rows.line_num)
        if "id" in header:
            ids.append(row[header.index("id")].strip())
    if not pts:
        raise InputError("no points", src)
    return Actuals(np.asarray(pts) * _scale(units), np.asarray(lines), tuple(ids) if ids else None, src)


def read_dmis_actuals(path, units: str | None = None) -> Actuals:
    """DMIS output holding actual points only: ``FA(label)=FEAT/POINT,CART,x,y,z[,i,j,k]`` statements
    (a trailing ``$`` continues a statement; the vector, when given, is the probe's and is not used:
    the CAD face gives the normal). Other features (circles, planes …) are not points and are
    passed over.

    Lengths are in the units of the last ``UNITS/MM|CM|METER|INCH|FEET,…`` statement before each
    point (MM before any, or ``units`` for a file without one; a file's own statement must agree
    with ``units``). Refused, at the statement's line: an unknown unit, a polar point, a point
    without its three coordinates, a repeated label, and nominal points (``F(label)=FEAT/POINT``) —
    paired with every actual (the file carries its own nominals: read it without ``--nominal``) or
    with some (a mix of nominal/actual pairs and actual-only points)."""
    points, src = dmis_points(path, units)
    nominal: dict[str, int] = {}
    actual: dict[str, tuple[int, list[float]]] = {}
    for ln, kind, label, system, rest, k in points:
        statement = f"{kind}({label})=FEAT/POINT"
        if kind == "F":
            if label in nominal:
                raise InputError(
                    f"duplicate label {label!r}: F({label}) again (first at line {nominal[label]})", src, ln
                )
            nominal[label] = ln
            continue
        if label in actual:
            raise InputError(
                f"duplicate label {label!r}: FA({label}) again (first at line {actual[label][0]})", src, ln
            )
        if system != "CART":
            raise InputError(
                f"{statement},{system}: only Cartesian (CART) points are read; export the points in CART", src, ln
            )
        nums = [_number(v, src, ln, "coordinate") for v in rest.split(",") if v.strip()]
        if len(nums) not in (3, 6):
            raise InputError(
                f"{statement} needs its three coordinates x,y,z (and optionally the vector i,j,k): 3 or 6 numbers, "
                f"got {len(nums)}",
                src,
                ln,
            )
        actual[label] = (ln, [v * k for v in nums[:3]])
    if not actual:
        raise InputError("no FA(label)=FEAT/POINT,CART actual points", src)
    if nominal:
        alone = [lb for lb in actual if lb not in nominal]
        if not alone and len(nominal) == len(actual):
            lb = next(iter(nominal))
            raise InputError(
                f"every actual point has its nominal F(label) (F({lb}) here): the file carries its own nominal "
                "points; with --nominal the CAD model is the nominal and the file must hold actuals only — read it "
                "without --nominal to use its nominals",
                src,
                nominal[lb],
            )
        if alone:
            lb = next(iter(nominal))
            what = f"F({lb}) is a nominal point while FA({alone[0]}) at line {actual[alone[0]][0]} has none"
        else:
            lb = next(x for x in nominal if x not in actual)
            what = f"F({lb}) is a nominal point without its actual FA({lb}) while the others are pairs"
        raise InputError(
            f"mixed content: {what}; a file either pairs every nominal with its actual (read it without "
            "--nominal) or holds actual points only (with --nominal)",
            src,
            nominal[lb],
        )
    labels = list(actual)
    return Actuals(
        np.array([actual[lb][1] for lb in labels]),
        np.array([actual[lb][0] for lb in labels]),
        tuple(labels),
        src,
    )


def _element_path(el) -> str:
    """The element's path from the root by local names, with a [k] index (1-based) among same-named
    siblings: ``QIFDocument/MeasurementsResults/…/PointFeatureActual[3]/Location``."""
    parts = []
    while el is not None:
        name = local_name(el)
        parent = el.getparent()
        if parent is not None:
            same = [c for c in parent if local_name(c) == name]
            if len(same) > 1:
                name += f"[{same.index(el) + 1}]"
        parts.append(name)
        el = parent
    return "/".join(reversed(parts))


def read_qif_actuals(path, units: str | None = None) -> Actuals:
    """QIF 3 measurement results holding measured points only: ``PointFeatureActual`` elements (its
    ``id`` is the point's id) with their ``Location`` (three numbers), whose feature item has no
    nominal ``Location``. Other actual features are passed over.

    Lengths are in the document's ``FileUnits/PrimaryUnits/LinearUnit`` (``UnitName``; a
    ``UnitConversion`` factor must agree with it), else in ``units`` (mm by default; a declared unit
    must agree). Refused, at the element's line and path: an unknown unit, a point without its
    ``id`` or without three coordinates, a repeated id or a feature item measured twice, and points
    with a nominal ``Location`` (``PointFeatureNominal``) — every one (the file carries its own
    nominals: read it without ``--nominal``) or some (a mix)."""
    root, src = qif_root(path)
    k = qif_scale(root, units, src)

    def child(el, name):
        return next((c for c in el if local_name(c) == name), None)

    def text_of(el, name):
        c = child(el, name)
        return c.text.strip() if c is not None and c.text else None

    def fail(msg, el):
        raise InputError(f"{_element_path(el)}: {msg}", src, el.sourceline or 0)

    nominals: dict[str, Any] = {}
    items: dict[str, str | None] = {}
    found = []
    for el in root.iter():
        name = local_name(el)
        if name == "PointFeatureNominal":
            if child(el, "Location") is not None:
                nominals[el.get("id")] = el
        elif name == "PointFeatureItem":
            items[el.get("id")] = text_of(el, "FeatureNominalId")
        elif name in ("PointFeatureActual", "PointFeatureMeasurement"):
            found.append(el)
    if not found:
        raise InputError("no PointFeatureActual elements (measured points)", src)
    ids: dict[str, int] = {}
    by_item: dict[str, int] = {}
    pts: list[list[float]] = []
    lines: list[int] = []
    paired: list[tuple[Any, str | None]] = []
    alone: list[tuple[Any, str | None]] = []
    for el in found:
        pid = el.get("id")
        if not pid:
            fail("a measured point without its id attribute", el)
        if pid in ids:
            fail(f"duplicate id {pid!r} (first at line {ids[pid]})", el)
        ids[pid] = el.sourceline or 0
        item = text_of(el, "FeatureItemId")
        if item is not None:
            if item in by_item:
                fail(f"feature item {item} measured twice (first at line {by_item[item]})", el)
            by_item[item] = el.sourceline or 0
            nid = items.get(item, item)
            (paired if nid in nominals else alone).append((el, nid))
        else:
            alone.append((el, None))
        loc = child(el, "Location")
        if loc is None:
            fail("a measured point without its Location", el)
        parts = (loc.text or "").split()
        if len(parts) != 3:
            fail(f"Location needs three coordinates x y z, got {len(parts)} numbers", loc)
        pts.append([_number(v, src, loc.sourceline or 0, "Location") * k for v in parts])
        lines.append(el.sourceline or 0)
    if paired:
        el, nid = paired[0]
        nom = nominals[str(nid)]
        if not alone:
            fail(
                f"every measured point has a nominal Location (this one: PointFeatureNominal {nid} at line "
                f"{nom.sourceline}): the file carries its own nominal points; with --nominal the CAD model is the "
                "nominal and the file must hold measured points only — read it without --nominal to use its nominals",
                el,
            )
        fail(
            f"mixed content: this measured point has a nominal Location (PointFeatureNominal {nid}) while "
            f"{_element_path(alone[0][0])} at line {alone[0][0].sourceline} has none; a file either pairs every "
            "measured point with its nominal (read it without --nominal) or holds measured points only "
            "(with --nominal)",
            el,
        )
    return Actuals(np.asarray(pts), np.asarray(lines), tuple(ids), src)
