"""ISO 286 tables: values printed in the standard, and the pressfit package where it covers them."""

from __future__ import annotations

import itertools

import pytest

from ncadapt import InputError, iso286


@pytest.mark.parametrize(
    "designation, limits",
    [
        # anchors from the ISO 286-2 tables
        ("40H6", (0.0, 0.016)),
        ("40H9", (0.0, 0.062)),
        ("25H6", (0.0, 0.013)),
        ("25H9", (0.0, 0.052)),
        # ISO 286-2:1988/Cor.1:2006 corrected values: A13 315–355, E8 80–120, R10 18–30, f9 250–315
        ("340A13", (1.200, 2.090)),
        ("100E8", (0.072, 0.126)),
        ("25R10", (-0.112, -0.028)),
        ("300f9", (-0.186, -0.056)),
        # ISO 286-2 tables (holes with Δ, special cases, large sizes)
        ("50K7", (-0.018, 0.007)),
        ("25N7", (-0.028, -0.007)),
        ("25P7", (-0.035, -0.014)),
        ("25S7", (-0.048, -0.027)),
        ("25M7", (-0.021, 0.0)),
        ("100K6", (-0.018, 0.004)),
        ("40T7", (-0.064, -0.039)),
        ("300M6", (-0.041, -0.009)),
        ("2K7", (-0.010, 0.0)),
        ("40js6", (-0.008, 0.008)),
        ("20j6", (-0.004, 0.009)),
        ("30H7", (0.0, 0.021)),
        ("30g6", (-0.020, -0.007)),
        ("600N7", (-0.114, -0.044)),
        ("2000u6", (2.000, 2.092)),
    ],
)
def test_standard_values(designation, limits):
    assert iso286.tolerance(designation) == pytest.approx(limits, abs=1e-9)


def test_it_grades():
    assert iso286.it(40, 6) == 0.016 and iso286.it(40, "IT9") == 0.062
    assert iso286.it(1, "01") == 0.0003 and iso286.it(3150, 18) == 33.0
    assert iso286.it(3, 7) == 0.010 and iso286.it(3.001, 7) == 0.012  # ranges are "above a up to b"
    # every row grows with size, every column with grade (a typing slip breaks one of these)
    for g in iso286.GRADES:
        row = iso286.IT[g]
        assert all(a <= b for a, b in zip(row, row[1:])), g
    for a, b in zip(iso286.GRADES, iso286.GRADES[1:]):
        assert all(x < y for x, y in zip(iso286.IT[a], iso286.IT[b])), (a, b)
    # from IT6 on the series is geometric, ratio 10^(1/5): IT(n+5) = 10 IT(n) up to the standard's
    # rounding (IT11 = 75 against 10 IT6 = 80 for 3–6 mm is the largest, 6 %)
    for n in range(6, 14):
        for i in range(21):
            assert iso286.IT[str(n + 5)][i] == pytest.approx(10 * iso286.IT[str(n)][i], rel=0.065), (n, i)


def test_equal_to_pressfit_where_it_covers():
    """pressfit (v0.1) covers H5–H11 holes and shafts c–u, grades 5–11, up to 500 mm."""
    pressfit = pytest.importorskip("pressfit")
    sizes = [
        1,
        2.5,
        3,
        4,
        6,
        8,
        10,
        12,
        16,
        18,
        20,
        24,
        28,
        30,
        35,
        45,
        50,
        60,
        75,
        90,
        110,
        130,
        150,
        170,
        190,
        210,
        240,
        260,
        300,
        330,
        380,
        420,
        480,
        500,
    ]
    letters = ["c", "d", "e", "f", "g", "h", "js", "k", "m", "n", "p", "s", "u"]
    n = 0
    for size, letter, grade in itertools.product(sizes, letters, range(5, 12)):
        f = pressfit.fit(f"H{grade}/{letter}{grade}", size)
        assert iso286.deviations(size, "H", grade) == pytest.approx(
            (f.hole_ei_um / 1000, f.hole_es_um / 1000), abs=1e-9
        )
        assert iso286.deviations(size, letter, grade) == pytest.approx(
            (f.shaft_ei_um / 1000, f.shaft_es_um / 1000), abs=1e-9
        ), (size, letter, grade)
        n += 1
    assert n == len(sizes) * len(letters) * 7


def test_holes_mirror_shafts():
    """A–H: EI = −es; P–U above IT7: ES = −ei (ISO 286-1 rules), over every tabulated range."""
    for size in (5, 15, 27, 45, 70, 110, 170, 240, 300, 380, 480):
        for letter in "abcdefgh":
            lo, hi = iso286.deviations(size, letter, 9)
            assert iso286.deviations(size, letter.upper(), 9)[0] == pytest.approx(-hi, abs=1e-12)
        for letter in "prsu":
            assert iso286.deviations(size, letter.upper(), 8)[1] == pytest.approx(
                -iso286.deviations(size, letter, 8)[0]
            )


@pytest.mark.parametrize(
    "bad, what",
    [
        ("40X6", "unknown fundamental deviation"),
        ("H6", "cannot read"),
        ("40H19", "unknown tolerance grade"),
        ("4000H7", "3150"),
        ("0H7", "above 0"),
        ("20t6", "24 mm"),
        ("600c11", "500 mm"),
        ("0.5a11", "1 mm"),
        ("40K9", "3 mm"),
        ("40j9", "not tabulated"),
        ("40Hh6", "mixed-case"),
        ("600IT01", "unknown fundamental deviation"),
    ],
)
def test_bad_designations(bad, what):
    with pytest.raises(InputError, match=what):
        iso286.tolerance(bad)
    with pytest.raises(InputError):
        iso286.it(600, "01")
