"""Tolerances and defaults of ncadapt, with where they come from."""

#: Millimetres per inch (exact, by the 1959 international yard and pound agreement).
MM_PER_INCH = 25.4

#: Largest coordinate or length read from a file or an option, mm. No machine tool has an axis
#: of a kilometre (the largest gantry mills travel some 60 m); a value beyond this is not a
#: position in millimetres, and bounding it keeps every square and sum of them finite.
COORD_MAX = 1e6

#: Default chord tolerance for linearising arcs, mm. 2 µm is below the form tolerance of
#: precision milling (IT5 on 10–18 mm is 8 µm, ISO 286-1) and near a probe's repeatability.
CHORD_TOL = 0.002

#: Default longest segment of a corrected move, mm: a correction field varies little within 1 mm.
MAX_SEGMENT = 1.0

#: Accepted ranges of the sampling options, mm. A chord tolerance below 1 nm or a segment below
#: 1 µm is finer than any machine moves; a chord tolerance above 10 mm is no tolerance (a very
#: long segment just means "do not split"). With the
#: engine's bound of 1,000,000 pieces per block (``MAX_PIECES_PER_BLOCK``) these keep a correction's
#: memory and time proportional to the program.
CHORD_TOL_RANGE = (1e-6, 10.0)
MAX_SEGMENT_RANGE = (1e-3, 1e9)

#: Most pieces one block is cut into; a block that needs more is refused at its line.
MAX_PIECES_PER_BLOCK = 1_000_000

#: What a field does at points outside its measured area: refuse them, hold the nearest value,
#: or extend linearly.
OUTSIDE = ("error", "clamp", "extrapolate")

#: Bytes of a program read, corrected and written at a time (whole lines): memory stays bounded
#: whatever the program's length.
PIECE_BYTES = 1 << 18

#: Default largest displacement ``correct`` writes without refusing, mm.
LIMIT = 0.5

#: Decimals written at least for changed numbers: 4 in millimetres (0.1 µm), 5 in inches.
DECIMALS_MM = 4
DECIMALS_INCH = 5

#: Agreement required between our motion and LinuxCNC's canonical motion, mm.
RS274_TOL_MM = 1e-4
