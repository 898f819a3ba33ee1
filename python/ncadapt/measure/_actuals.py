"""Readers of the actual points of a part whose nominal is its CAD model: CSV ``x,y,z``, DMIS
``FA(label)=FEAT/POINT`` outputs, QIF 3 ``PointFeatureActual`` and measured point sets — and files
that pair each actual point with a nominal of their own (whose nominals are then checked against
the CAD by :func:`~ncadapt.measure.project_on_cad`)."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._io import csv_reader
from ..errors import InputError
from ._core import Measurements
from ._readers import (
    MEASURED,
    NORMAL,
    UNITS_MM,
    _number,
    _scale,
    dmis_points,
    local_name,
    qif_root,
    qif_scale,
    read_csv,
    read_xyzijk,
    sniffed,
)


@dataclass(frozen=True)
class Actuals:
    """Actual points of a measurement file: ``points`` (n, 3) mm, the 1-based ``lines`` (n,) of the
    file they were read from (the element's line in a QIF file, the line of its numbers for a
    point of a QIF point set), their ``ids`` (labels; None when the file has none) and the file's
    name (``source``); for a file with nominals of its own, those (``nominals``, ``nominal_lines``,
    ``from_deviation``); what a QIF point set says of the probe (``compensated``,
    ``probe_radii``)."""

    points: np.ndarray
    lines: np.ndarray
    ids: tuple[str, ...] | None
    source: str
    #: (n, 3) mm: the file's own nominal point of each actual point (a row of NaN where the point
    #: has none, e.g. a QIF measured point set); None for a file of actual points only
    nominals: np.ndarray | None = None
    #: (n,) the line of each nominal point (0 where there is none); None with ``nominals``
    nominal_lines: np.ndarray | None = None
    #: True when the file gives no actual coordinates: the points are nominal + deviation × normal
    from_deviation: bool = False
    #: (n,) int8: 1 where the file says the point is compensated for the probe radius (a surface
    #: point), 0 where it says it is not (a probe-tip centre), -1 where it says nothing; None: nothing
    compensated: np.ndarray | None = None
    #: (n,) mm: the probe radius the file states for each point (NaN where it states none); None: none
    probe_radii: np.ndarray | None = None


def read_actuals(path, units: str | None = None) -> Actuals:
    """Actual points, the reader chosen from the file's contents: QIF 3 measured points
    (:func:`read_qif_actuals`), DMIS actuals (:func:`read_dmis_actuals`), a CSV with a header
    naming ``x,y,z`` (optional ``id``; :func:`read_csv_actuals`), or PC-DMIS XYZIJK text. ``units``:
    the length unit of a file that declares none (mm by default); a file's own must agree. The
    points come back in mm.

    A file that pairs every actual point with a nominal of its own (CSV ``x,y,z,i,j,k`` with
    ``mx,my,mz`` or ``dev``, XYZIJK rows, DMIS ``F``/``FA`` pairs, QIF nominal/actual point
    features) gives its actual points with its nominals (:attr:`Actuals.nominals`); a file with
    deviations along its normals and no actual coordinates gives nominal + deviation × normal
    (:attr:`Actuals.from_deviation`)."""
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
    if kind == "xyzijk" and not _csv_header(p):
        return _paired(read_xyzijk(p, 0.0, units))
    return read_csv_actuals(p, units)


def _csv_header(path: Path) -> bool:
    """Whether the file's first line reads as a CSV header (letters and a comma)."""
    with open(path, encoding="utf-8", errors="replace") as f:
        first = f.readline()
    return "," in first and re.search(r"[A-Za-z]", first) is not None


#: CSV columns that make a file one of nominal points paired with their actuals or deviations
_PAIRED = set(NORMAL + MEASURED + ("dev",))


def _paired(m: Measurements) -> Actuals:
    """The actual points of paired measurements read with no probe radius: the measured points, or
    nominal + deviation × normal when the file gives deviations only."""
    if m.measured is not None:
        points, from_dev = m.measured, False
    else:
        points, from_dev = m.nominal + m.deviation[:, None] * m.normal, True
    lines = m.lines if m.lines is not None else np.arange(1, len(m) + 1)
    return Actuals(points, lines, m.ids, str(m.source), m.nominal, lines, from_dev)


def read_csv_actuals(path, units: str | None = None) -> Actuals:
    """A CSV of actual points: a header naming ``x,y,z`` (optional ``id``), in mm unless ``units``
    says otherwise. A header that names any of ``i,j,k``, ``mx,my,mz`` or ``dev`` is a file of
    nominal points with their normals and actual points or deviations (:func:`read_csv`): its
    actual points, with its nominals (see :func:`read_actuals`)."""
    src = str(Path(path))
    rows = csv_reader(path)
    try:
        header = [h.strip().lower() for h in next(rows)]
    except StopIteration:
        raise InputError("empty file", src) from None
    if _PAIRED & set(header):
        return _paired(read_csv(path, 0.0, units))
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
    """DMIS output: actual points ``FA(label)=FEAT/POINT,CART,x,y,z[,i,j,k]`` (a trailing ``$``
    continues a statement; the vector, when given, is the probe's and is not used: the CAD face
    gives the normal), each with its nominal ``F(label)=FEAT/POINT,CART,x,y,z[,i,j,k]`` or none.
    Other features (circles, planes …) are not points and are passed over.

    Lengths are in the units of the last ``UNITS/MM|CM|METER|INCH|FEET,…`` statement before each
    point (MM before any, or ``units`` for a file without one; a file's own statement must agree
    with ``units``). Refused, at the statement's line: an unknown unit, a polar point, a point
    without its three coordinates, a repeated label, and a mix of nominal/actual pairs with
    actual-only points or nominals without their actuals. A file whose every actual has its
    nominal gives them as :attr:`Actuals.nominals` (lines: those of the ``FA`` and ``F``
    statements)."""
    points, src = dmis_points(path, units)
    nominal: dict[str, tuple[int, list[float]]] = {}
    actual: dict[str, tuple[int, list[float]]] = {}
    for ln, kind, label, system, rest, k in points:
        statement = f"{kind}({label})=FEAT/POINT"
        table = nominal if kind == "F" else actual
        if label in table:
            raise InputError(
                f"duplicate label {label!r}: {kind}({label}) again (first at line {table[label][0]})", src, ln
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
        table[label] = (ln, [v * k for v in nums[:3]])
    if not actual:
        raise InputError("no FA(label)=FEAT/POINT,CART actual points", src)
    if nominal:
        alone = [lb for lb in actual if lb not in nominal]
        lone = [lb for lb in nominal if lb not in actual]
        if alone or lone:
            if alone:
                lb = next(iter(nominal))
                what = f"F({lb}) is a nominal point while FA({alone[0]}) at line {actual[alone[0]][0]} has none"
            else:
                lb = lone[0]
                what = f"F({lb}) is a nominal point without its actual FA({lb}) while the others are pairs"
            raise InputError(
                f"mixed content: {what}; a file either pairs every nominal with its actual or holds actual points only",
                src,
                nominal[lb][0],
            )
    labels = list(actual)
    return Actuals(
        np.array([actual[lb][1] for lb in labels]),
        np.array([actual[lb][0] for lb in labels]),
        tuple(labels),
        src,
        np.array([nominal[lb][1] for lb in labels]) if nominal else None,
        np.array([nominal[lb][0] for lb in labels]) if nominal else None,
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
    """QIF 3 measurement results: measured points (``PointFeatureActual`` or
    ``PointFeatureMeasurement`` elements, their ``id`` the point's id, with a ``Location`` of three
    numbers) and measured point sets (``MeasuredPointSet``: ``count`` points, their coordinates in
    ``Points`` as 3 × count whitespace-separated numbers; the point k of a set (from 1) has the id
    ``<feature id>[k]``, the feature the measurement that refers to the whole set through its
    ``PointList/WholePointSetId``, else the set's own id). Other actual features are passed over.

    Lengths are in the document's ``FileUnits/PrimaryUnits/LinearUnit`` (``UnitName``; a
    ``UnitConversion`` factor must agree with it), else in ``units`` (mm by default; a declared unit
    must agree); a set's own ``linearUnit`` attribute or ``Units/LinearUnit`` wins for its points.
    A set's ``Normals`` (3 × count numbers) are checked and not used (the CAD face gives the
    normal); its ``Compensated``/``Compensations`` and ``ProbeRadius``/``ProbeRadii`` are kept
    (:attr:`Actuals.compensated`, :attr:`Actuals.probe_radii`).

    Refused, at the element's line and path (a set's point at the line its numbers are on): an
    unknown unit, a point without its ``id`` or without three coordinates, a repeated id or a
    feature item measured twice, a ``count`` that is not the number of points given, a set in
    another coordinate system (``CoordinateSystemId``, ``TranformId``) or in binary
    (``BinaryPoints`` …), a file whose only points are a model ``PointCloud`` (product data, not
    a measurement), and a mix of measured points with a nominal ``Location``
    (``PointFeatureNominal``) and measured points without. When every measured point has its
    nominal, the nominals are given as :attr:`Actuals.nominals` (NaN rows for the points of sets)."""
    root, src = qif_root(path)
    k = qif_scale(root, units, src)

    def child(el, name):
        return next((c for c in el if local_name(c) == name), None)

    def text_of(el, name):
        c = child(el, name)
        return c.text.strip() if c is not None and c.text else None

    def fail(msg, el, line=None):
        raise InputError(f"{_element_path(el)}: {msg}", src, line or el.sourceline or 0)

    nominals: dict[str, Any] = {}
    items: dict[str, str | None] = {}
    found: list[Any] = []  # measured points and measured point sets, in document order
    clouds: list[Any] = []
    whole: dict[str, list[Any]] = {}  # point set id -> the elements whose PointList names it whole
    for el in root.iter():
        name = local_name(el)
        if name == "PointFeatureNominal":
            if child(el, "Location") is not None:
                nominals[el.get("id")] = el
        elif name == "PointFeatureItem":
            items[el.get("id")] = text_of(el, "FeatureNominalId")
        elif name in ("PointFeatureActual", "PointFeatureMeasurement", "MeasuredPointSet"):
            found.append(el)
        elif name == "PointCloud":
            clouds.append(el)
        elif name == "WholePointSetId" and el.text and el.getparent() is not None:
            owner = el.getparent().getparent()
            if owner is not None and owner.get("id"):
                whole.setdefault(el.text.strip(), []).append(owner)
    if not found:
        if clouds:
            fail(
                "the file's only points are a PointCloud, which QIF 3 keeps with the product model "
                "(TopologySet/PointCloudSet), not with the measurement results; export the measured points as "
                "MeasuredPointSet (or PointFeatureActual) elements",
                clouds[0],
            )
        raise InputError("no measured points (PointFeatureActual, PointFeatureMeasurement or MeasuredPointSet)", src)
    ids: dict[str, int] = {}
    by_item: dict[str, int] = {}
    pts: list[list[float]] = []
    lines: list[int] = []
    seq: dict[str, int] = {}
    noms: list[list[float]] = []
    nom_lines: list[int] = []
    comp: list[int] = []
    radii: list[float] = []
    paired: list[tuple[Any, str | None]] = []
    alone: list[tuple[Any, str | None]] = []

    def add_id(pid, el, line):
        if pid in ids:
            fail(f"duplicate id {pid!r} (first at line {ids[pid]})", el, line)
        ids[pid] = line

    for el in found:
        if local_name(el) == "MeasuredPointSet":
            if not el.get("id"):
                fail("a measured point set without its id attribute", el)
            owners = whole.get(el.get("id"), [])
            name = owners[0].get("id") if len(owners) == 1 else el.get("id")
            for p, ln, c, r in _point_set(el, k, child, text_of, fail):
                seq[name] = seq.get(name, 0) + 1  # a feature's points numbered on across its sets
                add_id(f"{name}[{seq[name]}]", el, ln)
                pts.append(p)
                lines.append(ln)
                noms.append([math.nan] * 3)
                nom_lines.append(0)
                comp.append(c)
                radii.append(r)
            continue
        pid = el.get("id")
        if not pid:
            fail("a measured point without its id attribute", el)
        add_id(pid, el, el.sourceline or 0)
        item = text_of(el, "FeatureItemId")
        nid = None
        if item is not None:
            if item in by_item:
                fail(f"feature item {item} measured twice (first at line {by_item[item]})", el)
            by_item[item] = el.sourceline or 0
            nid = items.get(item, item)
        (paired if nid in nominals else alone).append((el, nid))
        pts.append(_location(el, k, child, fail, "a measured point"))
        lines.append(el.sourceline or 0)
        nom = nominals.get(nid) if nid is not None else None
        noms.append(_location(nom, k, child, fail, "a nominal point") if nom is not None else [math.nan] * 3)
        nom_lines.append(nom.sourceline or 0 if nom is not None else 0)
        comp.append(-1)
        radii.append(math.nan)
    if paired and alone:
        el, nid = paired[0]
        fail(
            f"mixed content: this measured point has a nominal Location (PointFeatureNominal {nid}) while "
            f"{_element_path(alone[0][0])} at line {alone[0][0].sourceline} has none; a file either pairs every "
            "measured point with its nominal or holds measured points only",
            el,
        )
    said = [c for c in comp if c >= 0]
    stated = [r for r in radii if not math.isnan(r)]
    return Actuals(
        np.asarray(pts),
        np.asarray(lines),
        tuple(ids),
        src,
        np.asarray(noms) if paired else None,
        np.asarray(nom_lines) if paired else None,
        compensated=np.asarray(comp, dtype=np.int8) if said else None,
        probe_radii=np.asarray(radii) if stated else None,
    )


def _location(el, k: float, child, fail, what: str) -> list[float]:
    """The ``Location`` (three numbers) of a QIF point element, times ``k`` (mm per unit)."""
    loc = child(el, "Location")
    if loc is None:
        fail(f"{what} without its Location", el)
    parts = (loc.text or "").split()
    if len(parts) != 3:
        fail(f"Location needs three coordinates x y z, got {len(parts)} numbers", loc)
    return [_qif_number(v, loc.sourceline or 0, "Location", fail, loc) * k for v in parts]


def _qif_number(s: str, line: int, what: str, fail, el) -> float:
    """``s`` as a number, else ``fail`` at ``line``."""
    try:
        return float(s)
    except ValueError:
        fail(f"{what}: expected a number, got {s!r}", el, line)
    raise AssertionError  # fail raises


def _count(el, fail) -> int | None:
    """The ``count`` attribute of a QIF array element (None when it has none)."""
    v = el.get("count")
    if v is None:
        return None
    if not v.strip().isdigit():
        fail(f"count={v!r} is not a number of points", el)
    return int(v)


def _numbers(el, what: str, fail) -> list[tuple[float, int]]:
    """The whitespace-separated numbers of a QIF list element, each with the line it is on."""
    text = el.text or ""
    out = []
    for m in re.finditer(r"\S+", text):
        line = (el.sourceline or 0) + text.count("\n", 0, m.start())
        out.append((_qif_number(m.group(), line, what, fail, el), line))
    return out


_BOOL = {"true": 1, "1": 1, "false": 0, "0": 0}


def _point_set(ms, k: float, child, text_of, fail):
    """The points of a QIF 3 ``MeasuredPointSet``: (xyz mm, line, compensated 1/0/-1, probe radius
    mm or NaN) for each, after checking its count, units, frame and lists."""
    given = _count(ms, fail)
    if given is None:
        fail("a measured point set without its count attribute", ms)
    count = int(given)  # type: ignore[arg-type]
    for frame in ("CoordinateSystemId", "TranformId"):
        c = child(ms, frame)
        if c is not None:
            fail(
                f"the points are given in another frame ({frame} {(c.text or '').strip()}); export them in the "
                "part's coordinate system",
                c,
            )
    pts_el = child(ms, "Points")
    if pts_el is None:
        binary = next((b for b in ms if local_name(b).startswith("Binary")), None)
        if binary is not None:
            fail(f"{local_name(binary)}: binary arrays are not read; export the point set as text (Points)", binary)
        fail("a measured point set without its Points", ms)
    for b in ms:
        if local_name(b) in ("BinaryNormals", "BinaryCompensated", "BinaryProbeRadii"):
            fail(f"{local_name(b)}: binary arrays are not read; export the point set as text", b)
    scale = _set_scale(ms, pts_el, k, child, text_of, fail)
    xyz = _triples(pts_el, count, ms, fail)
    normals = child(ms, "Normals")
    if normals is not None:
        _triples(normals, count, ms, fail)
    flags = [-1] * count
    c = child(ms, "Compensated")
    if c is not None:
        v = (c.text or "").strip().lower()
        if v not in _BOOL:
            fail(f"Compensated must be true or false, got {v!r}", c)
        flags = [_BOOL[v]] * count
    c = child(ms, "Compensations")
    if c is not None:
        vs = (c.text or "").split()
        if len(vs) != count or any(v.lower() not in _BOOL for v in vs):
            fail(f"Compensations needs {count} true/false values (count={count}), got {len(vs)} words", c)
        flags = [_BOOL[v.lower()] for v in vs]
    radii = [math.nan] * count
    c = child(ms, "ProbeRadius")
    if c is not None:
        radii = [_qif_number((c.text or "").strip(), c.sourceline or 0, "ProbeRadius", fail, c) * scale] * count
    c = child(ms, "ProbeRadii")
    if c is not None:
        vs = _numbers(c, "ProbeRadii", fail)
        if len(vs) != count:
            fail(f"ProbeRadii needs {count} numbers (count={count}), got {len(vs)}", c)
        radii = [v * scale for v, _ in vs]
    return [([v * scale for v in p], ln, f, r) for (p, ln), f, r in zip(xyz, flags, radii)]


def _triples(el, count: int, ms, fail) -> list[tuple[list[float], int]]:
    """The 3-vectors of a QIF list element holding ``count`` of them (3 × count numbers), each with
    the line its first number is on; the element's own ``count``, when given, must agree."""
    name = local_name(el)
    own = _count(el, fail)
    if own is not None and own != count:
        fail(f"{name} count={own} disagrees with the point set's count={count}", el)
    nums = _numbers(el, name, fail)
    if len(nums) != 3 * count:
        extra = "" if len(nums) % 3 == 0 else " (not a multiple of 3: a coordinate is missing)"
        fail(
            f"{name} holds {len(nums)} numbers{extra}, the count={count} of "
            f"{name if own is not None else local_name(ms)} needs 3 × {count} = {3 * count}",
            el,
        )
    return [([nums[i][0], nums[i + 1][0], nums[i + 2][0]], nums[i][1]) for i in range(0, len(nums), 3)]


def _set_scale(ms, pts_el, k: float, child, text_of, fail) -> float:
    """Millimetres per unit of a point set: its own ``linearUnit`` attribute (on the set or on its
    ``Points``) or ``Units/LinearUnit/UnitName``, else the document's ``k``."""
    said = [(el.get("linearUnit"), el) for el in (ms, pts_el) if el.get("linearUnit")]
    u = child(ms, "Units")
    lu = child(u, "LinearUnit") if u is not None else None
    if lu is not None and text_of(lu, "UnitName"):
        said.append((text_of(lu, "UnitName"), lu))
    mm = None
    for name, el in said:
        if name.strip().lower() not in UNITS_MM:
            fail(f"linear unit {name!r}: unknown length unit; expected one of {', '.join(UNITS_MM)}", el)
        v = UNITS_MM[name.strip().lower()]
        if mm is not None and v != mm:
            fail(f"linear unit {name!r} disagrees with the point set's other unit ({mm:g} mm)", el)
        mm = v
    return k if mm is None else mm
