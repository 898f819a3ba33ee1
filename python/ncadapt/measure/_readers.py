"""Readers of measured points: CSV, DMIS, PC-DMIS XYZIJK text, QIF 3."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from .._io import csv_reader, plain_csv, read_text
from ..errors import InputError
from ._core import Measurements, from_arrays

#: Millimetres per unit of the length units measurement files declare (DMIS UNITS/…, QIF
#: LinearUnit UnitName) or ``--units`` names.
UNITS_MM = {
    "mm": 1.0,
    "millimeter": 1.0,
    "millimetre": 1.0,
    "cm": 10.0,
    "meter": 1000.0,
    "metre": 1000.0,
    "m": 1000.0,
    "inch": 25.4,
    "in": 25.4,
    "feet": 304.8,
    "foot": 304.8,
    "ft": 304.8,
}

NOMINAL = ("x", "y", "z")
NORMAL = ("i", "j", "k")
MEASURED = ("mx", "my", "mz")


def _text(path) -> tuple[str, str]:
    p = Path(path)
    return read_text(p), str(p)


def _number(s: str, src: str, line: int, what: str) -> float:
    try:
        return float(s)
    except ValueError:
        raise InputError(f"{what}: expected a number, got {s.strip()!r}", src, line) from None


def _scale(units: str | None) -> float:
    """Millimetres per unit of a file without units of its own (mm unless ``units`` says)."""
    return UNITS_MM[units] if units else 1.0


def _lengths(a: np.ndarray, has_m: bool, k: float) -> np.ndarray:
    """Rows x,y,z,i,j,k,(mx,my,mz | dev) with the lengths multiplied by ``k`` (not the normal)."""
    a = a.copy()
    a[:, 0:3] *= k
    a[:, 6:] *= k
    return a


def read_csv(path, probe_radius: float = 0.0, units: str | None = None) -> Measurements:
    """CSV with a header naming ``x,y,z,i,j,k`` and ``mx,my,mz`` or ``dev`` (optional ``id``), in
    mm unless ``units`` says otherwise."""
    src = str(Path(path))
    rows = csv_reader(path)
    try:
        header = [h.strip().lower() for h in next(rows)]
    except StopIteration:
        raise InputError("empty file", src) from None
    cols = {h: k for k, h in enumerate(header)}
    missing = [c for c in NOMINAL + NORMAL if c not in cols]
    has_m = all(c in cols for c in MEASURED)
    if missing or not (has_m or "dev" in cols):
        raise InputError(
            f"header must name x,y,z,i,j,k and mx,my,mz or dev (optional id); got {','.join(header)}", src, 1
        )
    if has_m and "dev" in cols:
        raise InputError("header names both mx,my,mz and dev; give one", src, 1)
    want = NOMINAL + NORMAL + (MEASURED if has_m else ("dev",))
    fast = plain_csv(rows.text, len(header), [cols[c] for c in want], cols.get("id")) if rows.delimiter == "," else None
    if fast is not None:
        a, ids, lines = fast
        a = _lengths(a, has_m, _scale(units))
        return from_arrays(
            a[:, 0:3],
            a[:, 3:6],
            measured=a[:, 6:9] if has_m else None,
            deviation=None if has_m else a[:, 6],
            ids=ids,
            probe_radius=probe_radius,
            lines=lines,
            source=src,
        )
    values, ids, lines = [], [], []
    for row in rows:
        line = rows.line_num
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise InputError(f"{len(row)} fields, the header has {len(header)}", src, line)
        values.append([_number(row[cols[c]], src, line, c) for c in want])
        if "id" in cols:
            ids.append(row[cols["id"]].strip())
        lines.append(line)
    if not values:
        raise InputError("no points", src)
    a = _lengths(np.array(values), has_m, _scale(units))
    return from_arrays(
        a[:, 0:3],
        a[:, 3:6],
        measured=a[:, 6:9] if has_m else None,
        deviation=None if has_m else a[:, 6],
        ids=ids or None,
        probe_radius=probe_radius,
        lines=lines,
        source=src,
    )


def read_xyzijk(path, probe_radius: float = 0.0, units: str | None = None) -> Measurements:
    """PC-DMIS XYZIJK text: ``x y z i j k`` and a deviation (7 numbers) or the measured point
    (9 numbers) per row, separated by blanks or commas. Lines that do not start with a number
    (headers, comments) are skipped; every point row must have the same count."""
    text, src = _text(path)
    values, lines, width = [], [], None
    for ln, raw in enumerate(text.splitlines(), 1):
        parts = [p for p in re.split(r"[\s,;]+", raw.strip()) if p]
        if not parts or not re.match(r"^[-+]?(\d|\.\d)", parts[0]):
            continue
        if len(parts) not in (7, 9):
            raise InputError(
                f"expected 7 (x y z i j k dev) or 9 (x y z i j k mx my mz) numbers, got {len(parts)}", src, ln
            )
        if width is None:
            width = len(parts)
        elif len(parts) != width:
            raise InputError(f"{len(parts)} numbers where earlier rows have {width}", src, ln)
        values.append([_number(p, src, ln, "value") for p in parts])
        lines.append(ln)
    if not values:
        raise InputError("no point rows (x y z i j k ...)", src)
    a = _lengths(np.array(values), width == 9, _scale(units))
    return from_arrays(
        a[:, 0:3],
        a[:, 3:6],
        measured=a[:, 6:9] if width == 9 else None,
        deviation=a[:, 6] if width == 7 else None,
        probe_radius=probe_radius,
        lines=lines,
        source=src,
    )


_DMIS = re.compile(r"^\s*(FA|F)\(([^)]*)\)\s*=\s*FEAT\s*/\s*POINT\s*,\s*(\w+)\s*,(.*)$", re.I)
_DMIS_UNITS = re.compile(r"^\s*UNITS\s*/\s*(\w+)", re.I)
# DMIS length units (ANSI/DMIS 105.2 UNITS statement); MM when a file has no UNITS statement
_DMIS_LENGTH = {"MM": 1.0, "CM": 10.0, "METER": 1000.0, "INCH": 25.4, "FEET": 304.8}


def dmis_statements(path) -> tuple[list[tuple[int, str]], str]:
    """The statements of a DMIS file with the line each starts on (a trailing ``$`` continues a
    statement on the next line), and the file's name for messages."""
    text, src = _text(path)
    statements: list[tuple[int, str]] = []
    buf, start = "", 0
    for ln, raw in enumerate(text.splitlines(), 1):
        s = raw.rstrip()
        if not buf:
            start = ln
        if s.endswith("$"):
            buf += s[:-1]
            continue
        statements.append((start, buf + s))
        buf = ""
    if buf:
        raise InputError("statement continued with $ at the end of the file", src, start)
    return statements, src


def dmis_units(statement: str, units: str | None, src: str, line: int) -> float | None:
    """Millimetres per length unit of a DMIS ``UNITS/…`` statement (None for any other statement);
    an unknown unit, or one that disagrees with ``units``, is an :class:`InputError`."""
    u = _DMIS_UNITS.match(statement)
    if not u:
        return None
    name = u.group(1).upper()
    if name not in _DMIS_LENGTH:
        raise InputError(f"UNITS/{name}: unknown length unit; expected one of {', '.join(_DMIS_LENGTH)}", src, line)
    if units and _DMIS_LENGTH[name] != _scale(units):
        raise InputError(f"UNITS/{name} disagrees with --units {units}", src, line)
    return _DMIS_LENGTH[name]


def dmis_points(path, units: str | None = None) -> tuple[list[tuple[int, str, str, str, str, float]], str]:
    """The ``F(label)=FEAT/POINT,…`` and ``FA(label)=FEAT/POINT,…`` statements of a DMIS file, each
    as (line, ``F`` or ``FA``, label, coordinate system, the rest of the statement, millimetres per
    unit of the last ``UNITS`` before it — or of ``units`` for a file without one), and the file's
    name for messages."""
    statements, src = dmis_statements(path)
    k = _scale(units)
    out = []
    for ln, st in statements:
        unit = dmis_units(st, units, src, ln)
        if unit is not None:
            k = unit
            continue
        m = _DMIS.match(st)
        if m:
            out.append((ln, m.group(1).upper(), m.group(2).strip(), m.group(3).upper(), m.group(4), k))
    return out, src


def read_dmis(path, probe_radius: float = 0.0, units: str | None = None) -> Measurements:
    """DMIS: nominal ``F(label)=FEAT/POINT,CART,x,y,z,i,j,k`` and actual ``FA(label)=…`` statements,
    a trailing ``$`` continuing a statement. Every nominal needs its actual and vice versa (a file
    of actuals only goes with a CAD nominal: :func:`~ncadapt.measure.read_dmis_actuals`).

    Lengths are in the units of the last ``UNITS/MM|CM|METER|INCH|FEET,…`` statement before them
    (MM before any, or ``units`` for a file without one: a file's own statement must agree with
    ``units``). Polar points (``FEAT/POINT,POL``) are refused."""
    points, src = dmis_points(path, units)
    nominal: dict[str, tuple[int, list[float]]] = {}
    actual: dict[str, tuple[int, list[float]]] = {}
    for ln, kind, label, system, rest, k in points:
        if system != "CART":
            raise InputError(
                f"FEAT/POINT,{system}: only Cartesian (CART) points are read; export the points in CART", src, ln
            )
        nums = [_number(v, src, ln, "coordinate") for v in rest.split(",") if v.strip()]
        if len(nums) != 6:
            raise InputError(f"FEAT/POINT needs x,y,z,i,j,k (6 numbers), got {len(nums)}", src, ln)
        nums = [v * k for v in nums[:3]] + nums[3:]
        table = nominal if kind == "F" else actual
        if label in table:
            raise InputError(f"duplicate id {label!r} (first at line {table[label][0]})", src, ln)
        table[label] = (ln, nums)
    if not nominal:
        said = (
            f"; it holds actual points only ({len(actual)} FA(label)): give the CAD model as the nominal (--nominal)"
            if actual
            else ""
        )
        raise InputError(f"no F(label)=FEAT/POINT,CART nominal points{said}", src)
    for a, b, what in ((nominal, actual, "actual FA"), (actual, nominal, "nominal F")):
        for label, (ln, _) in a.items():
            if label not in b:
                raise InputError(f"point {label!r} has no {what}({label}) statement", src, ln)
    labels = list(nominal)
    nom = np.array([nominal[k][1] for k in labels])
    act = np.array([actual[k][1] for k in labels])
    return from_arrays(
        nom[:, :3],
        nom[:, 3:],
        measured=act[:, :3],
        ids=labels,
        probe_radius=probe_radius,
        lines=[nominal[k][0] for k in labels],
        source=src,
    )


def qif_root(path):
    """The root element of a QIF (XML) file, parsed by lxml without entity expansion, DTD or
    network (a measurement file cannot make the reader fetch or inline anything else), and the
    file's name for messages."""
    from lxml import etree

    src = str(path)
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False)
    try:
        root = etree.parse(str(path), parser).getroot()
    except OSError as e:
        raise InputError(f"not a readable QIF (XML) file: {e}", src) from None
    except etree.XMLSyntaxError as e:
        line, col = e.position if e.position else (0, 0)
        msg = re.sub(r",? line \d+, column \d+$", "", e.msg or "")
        raise InputError(f"not well-formed XML (QIF): {msg}", src, line or 0, col or 0) from None
    if root is None:
        raise InputError("not a QIF (XML) document: no root element", src)
    return root, src


def local_name(el) -> str:
    """An XML element's name without its namespace ('' for a comment or a processing instruction)."""
    from lxml import etree

    return etree.QName(el).localname if isinstance(el.tag, str) else ""


def qif_scale(root, units: str | None, src: str) -> float:
    """Millimetres per length unit of a QIF document: its ``FileUnits/PrimaryUnits/LinearUnit``
    (``UnitName`` mm, cm, m, in, ft …; a ``UnitConversion/Factor`` to an ``SIUnitName`` of metre
    must agree with it), else ``units`` (mm by default). An unknown unit, a factor that disagrees
    or a unit that disagrees with ``units`` is an :class:`InputError` at the element's line."""
    for el in root.iter():
        parent = el.getparent()
        if local_name(el) != "LinearUnit" or parent is None or local_name(parent) != "PrimaryUnits":
            continue
        kids = {local_name(c): c for c in el if local_name(c)}
        name = (kids["UnitName"].text or "").strip() if "UnitName" in kids else ""
        if name.lower() not in UNITS_MM:
            raise InputError(
                f"LinearUnit {name!r}: unknown length unit; expected one of {', '.join(UNITS_MM)}", src, el.sourceline
            )
        mm = UNITS_MM[name.lower()]
        conv = kids.get("UnitConversion")
        factor = next((c for c in conv if local_name(c) == "Factor"), None) if conv is not None else None
        si = (kids["SIUnitName"].text or "").strip().lower() if "SIUnitName" in kids else ""
        if factor is not None and si in ("meter", "metre"):
            f = _number(factor.text or "", src, factor.sourceline, "UnitConversion Factor")
            if not math.isclose(f * 1000.0, mm, rel_tol=1e-6):
                raise InputError(
                    f"LinearUnit {name!r} ({mm:g} mm) disagrees with its UnitConversion Factor {f:g} m",
                    src,
                    factor.sourceline,
                )
        if units and mm != _scale(units):
            raise InputError(f"LinearUnit {name!r} disagrees with --units {units}", src, el.sourceline)
        return mm
    return _scale(units)


def read_qif(path, probe_radius: float = 0.0, units: str | None = None) -> Measurements:
    """QIF 3 results: ``PointFeatureNominal`` (``Location``, ``Normal``) and the measured point
    (``PointFeatureActual``, or ``PointFeatureMeasurement``, with its ``Location``) that refers to
    it through its feature item. A file of measured points only goes with a CAD nominal
    (:func:`~ncadapt.measure.read_qif_actuals`).

    Lengths are in the document's ``FileUnits/PrimaryUnits/LinearUnit`` (its ``UnitName``: mm, cm,
    m, in, ft …), else in ``units`` (mm by default); a declared unit must agree with ``units``."""
    root, src = qif_root(path)
    local = local_name
    k = qif_scale(root, units, src)

    def child(el, name):
        for c in el:
            if isinstance(c.tag, str) and local(c) == name:
                return c
        return None

    def vec(el, name, owner):
        c = child(el, name)
        if c is None:
            raise InputError(f"{local(owner)} has no {name}", src, owner.sourceline)
        parts = (c.text or "").split()
        if len(parts) != 3:
            raise InputError(f"{name} needs 3 numbers, got {len(parts)}", src, c.sourceline)
        v = [_number(p, src, c.sourceline, name) for p in parts]
        return v if name == "Normal" else [x * k for x in v]

    def ref(el, name):
        c = child(el, name)
        return c.text.strip() if c is not None and c.text else None

    nominals, items, measured = {}, {}, {}
    point_sets = 0
    for el in root.iter():
        if not isinstance(el.tag, str):
            continue
        name = local(el)
        point_sets += name == "MeasuredPointSet"
        if name == "PointFeatureNominal":
            nominals[el.get("id")] = (el.sourceline, vec(el, "Location", el), vec(el, "Normal", el))
        elif name == "PointFeatureItem":
            items[el.get("id")] = ref(el, "FeatureNominalId")
        elif name in ("PointFeatureActual", "PointFeatureMeasurement"):
            fid = ref(el, "FeatureItemId")
            if fid in measured:
                raise InputError(f"feature item {fid} measured twice", src, el.sourceline)
            measured[fid] = (el.sourceline, vec(el, "Location", el))
    if not nominals:
        held = [f"{len(measured)} measured points"] if measured else []
        held += [f"{point_sets} measured point sets"] if point_sets else []
        said = (
            f"; it holds measured points only ({', '.join(held)}): give the CAD model as the nominal (--nominal)"
            if held
            else ""
        )
        raise InputError(f"no PointFeatureNominal elements{said}", src)
    by_nominal = {}
    for fid, (ln, loc) in measured.items():
        nid = items.get(fid, fid)
        if nid not in nominals:
            raise InputError(f"measurement of feature item {fid} refers to no PointFeatureNominal", src, ln)
        by_nominal[nid] = loc
    rows = []  # in the document order of the nominals
    for nid, nom in nominals.items():
        if nid not in by_nominal:
            raise InputError(f"nominal point {nid} has no measurement", src, nom[0])
        rows.append((nid, nom, by_nominal[nid]))
    return from_arrays(
        [r[1][1] for r in rows],
        [r[1][2] for r in rows],
        measured=[r[2] for r in rows],
        ids=[r[0] for r in rows],
        probe_radius=probe_radius,
        lines=[r[1][0] for r in rows],
        source=src,
    )


def sniffed(path, units: str | None) -> tuple[Path, str]:
    """The file ``path`` with the kind of its contents (:func:`sniff`), after checking ``units``
    names a length unit and the file exists."""
    if units is not None and units not in UNITS_MM:
        raise ValueError(f"units must be one of {', '.join(UNITS_MM)}, got {units!r}")
    p = Path(path)
    if not p.is_file():
        raise InputError("no such file", str(p))
    return p, sniff(p)


def read(path, probe_radius: float = 0.0, units: str | None = None) -> Measurements:
    """Read measurements, choosing the reader from the file's contents. ``units`` (mm, inch …):
    the length unit of a file that does not declare one (CSV, XYZIJK; DMIS and QIF without a
    units statement); a file that declares one must agree. Results are in mm. An ncadapt probe plan
    (:func:`ncadapt.probing.plan_text`) is read with the probe log it names."""
    p, kind = sniffed(path, units)
    if kind == "plan":  # an ncadapt probe plan: its nominal points with the probe log it names
        from ..probing import read_log_with_plan

        if units not in (None, "mm"):
            raise InputError(f"a probe plan and its log are in mm; --units {units} disagrees", str(p), 1)
        return read_log_with_plan(p, probe_radius=probe_radius)
    reader = {"qif": read_qif, "dmis": read_dmis, "csv": read_csv}.get(kind, read_xyzijk)
    return reader(p, probe_radius, units)


def sniff(path) -> str:
    """Which kind of measurement file ``path`` is, from its contents: ``plan`` (an ncadapt probe
    plan), ``qif`` (XML), ``dmis`` (a point feature anywhere — a long header may come first — or a
    DMIS header statement), ``csv`` (a header naming x) or ``xyzijk``."""
    from ..probing import is_plan

    data = Path(path).read_bytes()
    head = data[:4096].decode("utf-8", "replace").lstrip("\ufeff").lstrip()
    if is_plan(head):
        return "plan"
    if head.startswith("<"):
        return "qif"
    if re.search(rb"FEAT\s*/\s*POINT", data, re.I) or re.match(r"(DMISMN|DMISMD)\s*/", head, re.I):
        return "dmis"
    first = head.splitlines()[0] if head else ""
    if re.search(r"[A-Za-z]", first) and "," in first and re.search(r"\bx\b", first, re.I):
        return "csv"
    return "xyzijk"
