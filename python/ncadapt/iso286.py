"""ISO 286 limits and fits: standard tolerance grades and fundamental deviations.

The numbers are the tables of ISO 286-1:2010 (Tables 1–5: standard tolerances IT01–IT18 and the
fundamental deviations of holes A–U and shafts a–u for nominal sizes up to 3150 mm), entered as
data; the standard derives them from formulas but rounds the results by rules of its own, so
the tables, not the formulas, are the reference. Sizes belong to the range "above a up to and
including b". Values are µm in the tables and mm at the interface.

    >>> tolerance("40H6")
    (0.0, 0.016)
    >>> it(40, 9)
    0.062

Rules taken from the standard:

- holes A–H: EI = −es of the same shaft letter; JS/js: ±IT/2 (the standard allows rounding odd
  IT values of js7–js11 down to even; not done here);
- holes K, M, N up to IT8 and P–U up to IT7: ES = −ei of the shaft letter + Δ (Δ = IT_n − IT_(n−1)
  of the size range, tabulated), sizes up to 500 mm; above those grades ES = −ei without Δ
  (K above IT8: ES = 0, defined up to 3 mm only);
- M6 above 250 up to 315 mm: ES = −9 µm (the standard's special case);
- j/J only for the grades the standard tabulates (j5–j8, J6–J8, sizes up to 500 mm);
- A, B, a, b not for sizes up to 1 mm; IT14–IT18 not for sizes up to 1 mm; t/T from 24 mm;
- IT01 and IT0 only up to 500 mm.
"""

from __future__ import annotations

import math
import re

from .errors import InputError

__all__ = ["it", "tolerance", "deviations", "parse", "GRADES", "HOLE_LETTERS", "SHAFT_LETTERS"]

MAX_SIZE = 3150.0

# main size ranges (upper limits, mm) of Table 1
MAIN = (3, 6, 10, 18, 30, 50, 80, 120, 180, 250, 315, 400, 500, 630, 800, 1000, 1250, 1600, 2000, 2500, 3150)
# intermediate ranges of Tables 2–5
SUB = (
    3,
    6,
    10,
    14,
    18,
    24,
    30,
    40,
    50,
    65,
    80,
    100,
    120,
    140,
    160,
    180,
    200,
    225,
    250,
    280,
    315,
    355,
    400,
    450,
    500,
    560,
    630,
    710,
    800,
    900,
    1000,
    1120,
    1250,
    1400,
    1600,
    1800,
    2000,
    2240,
    2500,
    2800,
    3150,
)

# Table 1: standard tolerances, µm, per main range (IT01 and IT0 up to 500 mm only)
IT = {
    "01": (0.3, 0.4, 0.4, 0.5, 0.6, 0.6, 0.8, 1, 1.2, 2, 2.5, 3, 4),
    "0": (0.5, 0.6, 0.6, 0.8, 1, 1, 1.2, 1.5, 2, 3, 4, 5, 6),
    "1": (0.8, 1, 1, 1.2, 1.5, 1.5, 2, 2.5, 3.5, 4.5, 6, 7, 8, 9, 10, 11, 13, 15, 18, 22, 26),
    "2": (1.2, 1.5, 1.5, 2, 2.5, 2.5, 3, 4, 5, 7, 8, 9, 10, 11, 13, 15, 18, 21, 25, 30, 36),
    "3": (2, 2.5, 2.5, 3, 4, 4, 5, 6, 8, 10, 12, 13, 15, 16, 18, 21, 24, 29, 35, 41, 50),
    "4": (3, 4, 4, 5, 6, 7, 8, 10, 12, 14, 16, 18, 20, 22, 25, 28, 33, 39, 46, 55, 68),
    "5": (4, 5, 6, 8, 9, 11, 13, 15, 18, 20, 23, 25, 27, 32, 36, 40, 47, 55, 65, 78, 96),
    "6": (6, 8, 9, 11, 13, 16, 19, 22, 25, 29, 32, 36, 40, 44, 50, 56, 66, 78, 92, 110, 135),
    "7": (10, 12, 15, 18, 21, 25, 30, 35, 40, 46, 52, 57, 63, 70, 80, 90, 105, 125, 150, 175, 210),
    "8": (14, 18, 22, 27, 33, 39, 46, 54, 63, 72, 81, 89, 97, 110, 125, 140, 165, 195, 230, 280, 330),
    "9": (25, 30, 36, 43, 52, 62, 74, 87, 100, 115, 130, 140, 155, 175, 200, 230, 260, 310, 370, 440, 540),
    "10": (40, 48, 58, 70, 84, 100, 120, 140, 160, 185, 210, 230, 250, 280, 320, 360, 420, 500, 600, 700, 860),
    "11": (60, 75, 90, 110, 130, 160, 190, 220, 250, 290, 320, 360, 400, 440, 500, 560, 660, 780, 920, 1100, 1350),
    "12": (
        100,
        120,
        150,
        180,
        210,
        250,
        300,
        350,
        400,
        460,
        520,
        570,
        630,
        700,
        800,
        900,
        1050,
        1250,
        1500,
        1750,
        2100,
    ),
    "13": (
        140,
        180,
        220,
        270,
        330,
        390,
        460,
        540,
        630,
        720,
        810,
        890,
        970,
        1100,
        1250,
        1400,
        1650,
        1950,
        2300,
        2800,
        3300,
    ),
    "14": (
        250,
        300,
        360,
        430,
        520,
        620,
        740,
        870,
        1000,
        1150,
        1300,
        1400,
        1550,
        1750,
        2000,
        2300,
        2600,
        3100,
        3700,
        4400,
        5400,
    ),
    "15": (
        400,
        480,
        580,
        700,
        840,
        1000,
        1200,
        1400,
        1600,
        1850,
        2100,
        2300,
        2500,
        2800,
        3200,
        3600,
        4200,
        5000,
        6000,
        7000,
        8600,
    ),
    "16": (
        600,
        750,
        900,
        1100,
        1300,
        1600,
        1900,
        2200,
        2500,
        2900,
        3200,
        3600,
        4000,
        4400,
        5000,
        5600,
        6600,
        7800,
        9200,
        11000,
        13500,
    ),
    "17": (
        1000,
        1200,
        1500,
        1800,
        2100,
        2500,
        3000,
        3500,
        4000,
        4600,
        5200,
        5700,
        6300,
        7000,
        8000,
        9000,
        10500,
        12500,
        15000,
        17500,
        21000,
    ),
    "18": (
        1400,
        1800,
        2200,
        2700,
        3300,
        3900,
        4600,
        5400,
        6300,
        7200,
        8100,
        8900,
        9700,
        11000,
        12500,
        14000,
        16500,
        19500,
        23000,
        28000,
        33000,
    ),
}
GRADES = tuple(IT)

# Table 4: shafts a–h, upper deviation es, µm (a, b, c up to 500 mm on the intermediate ranges)
_ES_SUB = {
    "a": (
        -270,
        -270,
        -280,
        -290,
        -290,
        -300,
        -300,
        -310,
        -320,
        -340,
        -360,
        -380,
        -410,
        -460,
        -520,
        -580,
        -660,
        -740,
        -820,
        -920,
        -1050,
        -1200,
        -1350,
        -1500,
        -1650,
    ),
    "b": (
        -140,
        -140,
        -150,
        -150,
        -150,
        -160,
        -160,
        -170,
        -180,
        -190,
        -200,
        -220,
        -240,
        -260,
        -280,
        -310,
        -340,
        -380,
        -420,
        -480,
        -540,
        -600,
        -680,
        -760,
        -840,
    ),
    "c": (
        -60,
        -70,
        -80,
        -95,
        -95,
        -110,
        -110,
        -120,
        -130,
        -140,
        -150,
        -170,
        -180,
        -200,
        -210,
        -230,
        -240,
        -260,
        -280,
        -300,
        -330,
        -360,
        -400,
        -440,
        -480,
    ),
}
_ES_MAIN = {
    "d": (
        -20,
        -30,
        -40,
        -50,
        -65,
        -80,
        -100,
        -120,
        -145,
        -170,
        -190,
        -210,
        -230,
        -260,
        -290,
        -320,
        -350,
        -390,
        -430,
        -480,
        -520,
    ),
    "e": (
        -14,
        -20,
        -25,
        -32,
        -40,
        -50,
        -60,
        -72,
        -85,
        -100,
        -110,
        -125,
        -135,
        -145,
        -160,
        -170,
        -195,
        -220,
        -240,
        -260,
        -290,
    ),
    "f": (-6, -10, -13, -16, -20, -25, -30, -36, -43, -50, -56, -62, -68, -76, -80, -86, -98, -110, -120, -130, -145),
    "g": (-2, -4, -5, -6, -7, -9, -10, -12, -14, -15, -17, -18, -20, -22, -24, -26, -28, -30, -32, -34, -38),
    "h": (0,) * 21,
}
# Table 4: shaft j, lower deviation ei, µm, by grade (up to 500 mm; j8 up to 3 mm)
_J = {
    "5": (-2, -2, -2, -3, -4, -5, -7, -9, -11, -13, -16, -18, -20),
    "6": (-2, -2, -2, -3, -4, -5, -7, -9, -11, -13, -16, -18, -20),
    "7": (-4, -4, -5, -6, -8, -10, -12, -15, -18, -21, -26, -28, -32),
    "8": (-6,),
}
# Table 5: shafts k–u, lower deviation ei, µm
_K = (0, 1, 1, 1, 2, 2, 2, 3, 3, 4, 4, 4, 5)  # IT4–IT7 up to 500 mm; otherwise 0
_EI_MAIN = {
    "m": (2, 4, 6, 7, 8, 9, 11, 13, 15, 17, 20, 21, 23, 26, 30, 34, 40, 48, 58, 68, 76),
    "n": (4, 8, 10, 12, 15, 17, 20, 23, 27, 31, 34, 37, 40, 44, 50, 56, 66, 78, 92, 110, 135),
    "p": (6, 12, 15, 18, 22, 26, 32, 37, 43, 50, 56, 62, 68, 78, 88, 100, 120, 140, 170, 195, 240),
}
_EI_SUB = {
    "r": (
        10,
        15,
        19,
        23,
        23,
        28,
        28,
        34,
        34,
        41,
        43,
        51,
        54,
        63,
        65,
        68,
        77,
        80,
        84,
        94,
        98,
        108,
        114,
        126,
        132,
        150,
        155,
        175,
        185,
        210,
        220,
        250,
        260,
        300,
        330,
        370,
        400,
        440,
        460,
        550,
        580,
    ),
    "s": (
        14,
        19,
        23,
        28,
        28,
        35,
        35,
        43,
        43,
        53,
        59,
        71,
        79,
        92,
        100,
        108,
        122,
        130,
        140,
        158,
        170,
        190,
        208,
        232,
        252,
        280,
        310,
        340,
        380,
        430,
        470,
        520,
        580,
        640,
        720,
        820,
        920,
        1000,
        1100,
        1250,
        1400,
    ),
    "t": (
        None,
        None,
        None,
        None,
        None,
        None,
        41,
        48,
        54,
        66,
        75,
        91,
        104,
        122,
        134,
        146,
        166,
        180,
        196,
        218,
        240,
        268,
        294,
        330,
        360,
        400,
        450,
        500,
        560,
        620,
        680,
        780,
        840,
        960,
        1050,
        1200,
        1350,
        1500,
        1650,
        1900,
        2100,
    ),
    "u": (
        18,
        23,
        28,
        33,
        33,
        41,
        48,
        60,
        70,
        87,
        102,
        124,
        144,
        170,
        190,
        210,
        236,
        258,
        284,
        315,
        350,
        390,
        435,
        490,
        540,
        600,
        660,
        740,
        840,
        940,
        1050,
        1150,
        1300,
        1450,
        1600,
        1850,
        2000,
        2300,
        2500,
        2900,
        3200,
    ),
}
# Table 3: holes J (ES, µm, up to 500 mm), the K/M/N constants x in "−x + Δ", and Δ
_J_HOLE = {
    "6": (2, 5, 5, 6, 8, 10, 13, 16, 18, 22, 25, 29, 33),
    "7": (4, 6, 8, 10, 12, 14, 18, 22, 26, 30, 36, 39, 43),
    "8": (6, 10, 12, 15, 20, 24, 28, 34, 41, 47, 55, 60, 66),
}
_DELTA = {  # Δ for IT3..IT8, µm, per main range up to 500 mm
    "3": (0, 1, 1, 1, 1.5, 1.5, 2, 2, 3, 3, 4, 4, 5),
    "4": (0, 1.5, 1.5, 2, 2, 3, 3, 4, 4, 4, 4, 5, 5),
    "5": (0, 1, 2, 3, 3, 4, 5, 5, 6, 6, 7, 7, 7),
    "6": (0, 3, 3, 3, 4, 5, 6, 7, 7, 9, 9, 11, 13),
    "7": (0, 4, 6, 7, 8, 9, 11, 13, 15, 17, 20, 21, 23),
    "8": (0, 6, 7, 9, 12, 14, 16, 19, 23, 26, 29, 32, 34),
}

SHAFT_LETTERS = ("a", "b", "c", "d", "e", "f", "g", "h", "js", "j", "k", "m", "n", "p", "r", "s", "t", "u")
HOLE_LETTERS = tuple(s.upper() for s in SHAFT_LETTERS)

_DESIGNATION = re.compile(
    r"^\s*(?:[Ø⌀]\s*)?(?P<size>\d+(?:[.,]\d+)?)\s*(?P<letter>[A-Za-z]{1,2})\s*(?P<grade>0?1|\d{1,2})\s*$"
)


def _range(size: float, limits) -> int:
    if not (isinstance(size, (int, float)) and math.isfinite(size)) or not 0 < size <= MAX_SIZE:
        raise InputError(f"nominal size must be above 0 up to and including {MAX_SIZE:g} mm, got {size!r}")
    for i, upper in enumerate(limits):
        if size <= upper:
            return i
    raise AssertionError("unreachable")


def _grade(grade) -> str:
    g = str(grade).upper().removeprefix("IT")
    if g in ("00", "001"):
        g = "01"
    if g not in IT:
        raise InputError(f"unknown tolerance grade {grade!r}: ISO 286 has IT01, IT0, IT1 … IT18")
    return g


def _it_um(size: float, grade) -> float:
    g = _grade(grade)
    row = IT[g]
    i = _range(size, MAIN)
    if i >= len(row):
        raise InputError(f"IT{g} is defined up to {MAIN[len(row) - 1]} mm, not for {size:g} mm")
    if int(g) >= 14 and g != "01" and size <= 1:
        raise InputError(f"IT{g} is not used for sizes up to 1 mm")
    return float(row[i])


def it(size: float, grade) -> float:
    """The standard tolerance IT``grade`` (1–18, "01", "0", "IT7" …) for a nominal size, in mm."""
    return _it_um(size, grade) / 1000.0


def _shaft_um(size: float, letter: str, grade: str) -> tuple[float, float]:
    """(ei, es) of a shaft, µm."""
    t = _it_um(size, grade)
    g = int(grade) if grade not in ("01", "0") else 0
    if letter in ("a", "b") and size <= 1:
        raise InputError(f"fundamental deviation {letter} is not used for sizes up to 1 mm")
    if letter in _ES_SUB or letter in _ES_MAIN:
        if letter in _ES_SUB:
            i = _range(size, SUB)
            if i >= len(_ES_SUB[letter]):
                raise InputError(f"fundamental deviation {letter} is defined up to 500 mm, not for {size:g} mm")
            es = _ES_SUB[letter][i]
        else:
            es = _ES_MAIN[letter][_range(size, MAIN)]
        return es - t, float(es)
    if letter == "js":
        return -t / 2, t / 2
    if letter == "j":
        row = _J.get(grade)
        i = _range(size, MAIN)
        if row is None or i >= len(row):
            raise InputError(
                f"j{grade} is not tabulated by ISO 286 for {size:g} mm (j5, j6, j7 up to 500 mm, j8 up to 3 mm)"
            )
        return float(row[i]), row[i] + t
    if letter == "k":
        i = _range(size, MAIN)
        ei = _K[i] if (4 <= g <= 7 and i < len(_K)) else 0
        return float(ei), ei + t
    if letter in _EI_MAIN:
        ei = _EI_MAIN[letter][_range(size, MAIN)]
        return float(ei), ei + t
    if letter in _EI_SUB:
        sub = _EI_SUB[letter][_range(size, SUB)]
        if sub is None:
            raise InputError(f"fundamental deviation {letter} starts above 24 mm, not for {size:g} mm")
        return float(sub), sub + t
    raise InputError(f"unknown shaft letter {letter!r}; supported: {', '.join(SHAFT_LETTERS)}")


def _hole_um(size: float, letter: str, grade: str) -> tuple[float, float]:
    """(EI, ES) of a hole, µm."""
    t = _it_um(size, grade)
    g = int(grade) if grade not in ("01", "0") else 0
    low = letter.lower()
    if letter in ("A", "B", "C", "D", "E", "F", "G", "H"):
        _, es = _shaft_um(size, low, grade)
        return -es, -es + t
    if letter == "JS":
        return -t / 2, t / 2
    i = _range(size, MAIN)
    small = i < 13  # up to 500 mm: Δ applies
    if letter == "J":
        row = _J_HOLE.get(grade)
        if row is None or not small:
            raise InputError(f"J{grade} is not tabulated by ISO 286 for {size:g} mm (J6, J7, J8 up to 500 mm)")
        return row[i] - t, float(row[i])
    delta = _DELTA[grade][i] if (small and grade in _DELTA) else 0.0
    if letter in ("K", "M", "N"):
        x = {"K": _K, "M": _EI_MAIN["m"], "N": _EI_MAIN["n"]}[letter]
        if not small:  # above 500 mm: one value for all grades, no Δ
            es = {"K": 0, "M": -_EI_MAIN["m"][i], "N": -_EI_MAIN["n"][i]}[letter]
        elif g <= 8:
            es = -x[i] + delta if size > 3 else -x[i]
            if letter == "M" and grade == "6" and 250 < size <= 315:
                es = -9.0  # the standard's special case
        elif letter == "K":
            if size > 3:
                raise InputError(f"K{grade} (above IT8) is defined by ISO 286 only up to 3 mm, not for {size:g} mm")
            es = 0.0
        elif letter == "M":
            es = -x[i]
        else:
            es = -x[i] if size <= 3 else 0.0
        return es - t, float(es)
    ei_shaft, _ = _shaft_um(size, low, grade)
    es = -ei_shaft + (delta if g <= 7 else 0.0)
    return es - t, float(es)


def parse(designation: str) -> tuple[float, str, str]:
    """``"40H6"``, ``"40 h6"``, ``"Ø25 js7"`` → (size, letter, grade). Upper case letters are holes."""
    m = _DESIGNATION.match(str(designation))
    if not m:
        raise InputError(f"cannot read the tolerance designation {designation!r}; expected e.g. '40H6' or '25 g6'")
    letter = m.group("letter")
    if not (letter.isupper() or letter.islower()) and letter not in ("Js", "jS"):
        raise InputError(f"mixed-case letter in {designation!r}; holes are upper case (H7), shafts lower case (g6)")
    if letter in ("Js", "jS"):
        letter = "JS"
    if letter not in HOLE_LETTERS and letter not in SHAFT_LETTERS:
        raise InputError(
            f"unknown fundamental deviation {letter!r} in {designation!r}; "
            f"holes: {', '.join(HOLE_LETTERS)}; shafts: {', '.join(SHAFT_LETTERS)}"
        )
    return float(m.group("size").replace(",", ".")), letter, _grade(m.group("grade"))


def deviations(size: float, letter: str, grade) -> tuple[float, float]:
    """(lower, upper) limit deviations, mm, of a hole (upper-case letter) or a shaft (lower-case)."""
    g = _grade(grade)
    if letter in HOLE_LETTERS:
        lo, hi = _hole_um(size, letter, g)
    elif letter in SHAFT_LETTERS:
        lo, hi = _shaft_um(size, letter, g)
    else:
        raise InputError(f"unknown fundamental deviation {letter!r}")
    return round(lo / 1000.0, 7) + 0.0, round(hi / 1000.0, 7) + 0.0  # + 0.0: no -0.0


def tolerance(designation: str) -> tuple[float, float]:
    """(lower, upper) limit deviations in mm of a designation such as ``"40H6"`` or ``"25g6"``."""
    try:
        return deviations(*parse(designation))
    except InputError as err:
        if str(designation) in err.message:
            raise
        raise InputError(f"{designation}: {err.message}") from None
