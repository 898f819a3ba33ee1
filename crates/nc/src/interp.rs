//! Modal interpreter: RS274/NGC as LinuxCNC reads it, for the subset that can be corrected exactly.
//!
//! The interpreter walks the lexed lines once, keeps the modal state (motion, plane, units,
//! distance modes, work offset, feed, spindle, tool) and records every block that changes the
//! position. Constructs it cannot follow faithfully are reported with their line and never guessed:
//! positions they make uncertain become NaN, and the blocks they affect are marked unsupported.

use crate::error::NcError;
use crate::lex::{Lexed, Opaque, Word};

/// Number of tracked axes.
pub const NAXES: usize = 9;
/// Axis letters in their index order.
pub const AXES: [u8; NAXES] = *b"XYZABCUVW";
/// Millimetres per inch.
pub const MM_PER_INCH: f64 = 25.4;

/// The controller a program is written for, where it changes how a block is read.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Dialect {
    /// LinuxCNC's RS274NGC, as `rs274` reads it.
    #[default]
    LinuxCnc,
    /// Fanuc-family controls and Haas: a number without a decimal point counts least input
    /// increments on length and angle words (`X10` is 0.010 mm), unless a machine parameter
    /// (Fanuc 3401#0 DPI) says otherwise; the G98/G99 mode a program starts in is the control's;
    /// canned cycles are a modal group of their own (09), so G80 leaves the G0/G1/G2/G3 that was
    /// in force before them.
    Fanuc,
    /// grbl (no canned cycles of its own).
    Grbl,
    /// Marlin (3D printer G-code; no canned cycles).
    Marlin,
    /// LinuxCNC on a lathe: no Y axis (Y is 0, the tool in the plane through the spindle's
    /// axis); G7/G8 say whether X is a diameter or a radius.
    LinuxCncLathe,
    /// A Fanuc-family lathe (Haas lathes alike) in G-code system A: X is a diameter, U and W
    /// are increments of X and Z, G90/G92/G94 and G70–G76 are turning cycles; no Y axis.
    FanucLathe,
}

impl Dialect {
    /// The dialect of a name (`linuxcnc`, `fanuc`, `grbl`, `marlin`), as `--dialect` gives it.
    pub fn from_name(name: &str) -> Result<Self, NcError> {
        Ok(match name {
            "linuxcnc" => Dialect::LinuxCnc,
            "fanuc" => Dialect::Fanuc,
            "grbl" => Dialect::Grbl,
            "marlin" => Dialect::Marlin,
            "linuxcnc-lathe" => Dialect::LinuxCncLathe,
            "fanuc-lathe" => Dialect::FanucLathe,
            _ => {
                return Err(NcError::Usage(format!(
                    "the engine reads the dialects linuxcnc, fanuc, grbl, marlin, linuxcnc-lathe and fanuc-lathe; got {name:?}"
                )))
            }
        })
    }

    /// Whether a number without a decimal point on a length or angle word is ambiguous (counted
    /// in least input increments, or in units, as a machine parameter says).
    pub fn point_matters(self) -> bool {
        self.is_fanuc()
    }

    /// A Fanuc-family control, mill or lathe.
    pub fn is_fanuc(self) -> bool {
        matches!(self, Dialect::Fanuc | Dialect::FanucLathe)
    }

    /// LinuxCNC, mill or lathe.
    pub fn is_linuxcnc(self) -> bool {
        matches!(self, Dialect::LinuxCnc | Dialect::LinuxCncLathe)
    }

    /// A lathe: no Y axis (Y is 0 throughout).
    pub fn lathe(self) -> bool {
        matches!(self, Dialect::LinuxCncLathe | Dialect::FanucLathe)
    }

    /// The canned-cycle retract mode (true: G98) a program that states neither G98 nor G99 runs
    /// in, when the dialect makes it certain: LinuxCNC's `rs274` reads G99.
    pub fn default_retract(self) -> Option<bool> {
        if self.is_linuxcnc() {
            Some(false)
        } else {
            None
        }
    }
}

/// Words whose value is a length or an angle counted in least input increments on a Fanuc-family
/// control when written without a decimal point: the axes, the arc centre and radius, and a
/// canned cycle's R plane (Fanuc's "decimal point programming" addresses, F excepted: a feed
/// does not change the path). In a canned-cycle block Q (the peck depth) is one too and K is
/// not (Fanuc's number of repeats); elsewhere Q is not (a lathe cycle's last block number).
const INCREMENT_WORDS: &[u8] = b"XYZABCUVWIJKR";

/// What a recorded block does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Motion {
    Rapid = 0,
    Feed = 1,
    ArcCw = 2,
    ArcCcw = 3,
    /// Changes the position in a way the engine does not trace (G28, G53, canned cycle, ...).
    Other = 4,
    /// LinuxCNC's cubic spline G5 (a Bézier from the start by I J, to the end by P Q).
    Spline = 5,
    /// LinuxCNC's quadratic spline G5.1 (a Bézier through the control point start + I J).
    QSpline = 6,
}

impl Motion {
    pub fn is_arc(self) -> bool {
        matches!(self, Motion::ArcCw | Motion::ArcCcw)
    }

    /// A spline, G5 or G5.1 ([`Interp::splines`] holds its control points).
    pub fn is_spline(self) -> bool {
        matches!(self, Motion::Spline | Motion::QSpline)
    }

    /// An arc or a spline: a curve (a straight move is neither).
    pub fn is_curve(self) -> bool {
        self.is_arc() || self.is_spline()
    }
}

/// A coordinate rotation in force (Fanuc's G68 in G17): the programmed X Y (mm, with the
/// offsets, as an unrotated move's end) turned by the angle about the centre `c`, given the
/// same way.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rotation {
    pub cos: f64,
    pub sin: f64,
    pub c: [f64; 2],
}

impl Rotation {
    /// Where a programmed point `p` is (the frame's coordinates).
    #[inline]
    pub fn to_frame(&self, p: [f64; 2]) -> [f64; 2] {
        let (x, y) = (p[0] - self.c[0], p[1] - self.c[1]);
        [
            self.c[0] + self.cos * x - self.sin * y,
            self.c[1] + self.sin * x + self.cos * y,
        ]
    }

    /// The programmed point that is at `f`.
    #[inline]
    pub fn to_prog(&self, f: [f64; 2]) -> [f64; 2] {
        let (x, y) = (f[0] - self.c[0], f[1] - self.c[1]);
        [
            self.c[0] + self.cos * x + self.sin * y,
            self.c[1] - self.sin * x + self.cos * y,
        ]
    }
}

/// [`Record::rot`] of a move under no rotation.
pub const NO_ROT: u32 = u32::MAX;

/// A spline block (LinuxCNC's G5 or G5.1): the control points between its start and its end, in
/// the XY plane (mm, the frame of [`Record::end`]): a G5's two, a G5.1's one (twice). Its motion
/// is LinuxCNC's arcs of the curve ([`crate::spline`]).
#[derive(Clone, Copy, Debug)]
pub struct Spline {
    /// Index of its record in the run.
    pub rec: u32,
    pub ctrl: [[f64; 2]; 2],
    /// A G5 without I and J: its first control point is the start plus LinuxCNC's register, the
    /// last G5's -P -Q (the output must have set the same register).
    pub continued: bool,
}

/// Plane index: 0 = G17 (XY), 1 = G18 (ZX), 2 = G19 (YZ).
/// For each plane: the first and second in-plane axes and the normal axis, as indices into AXES.
pub const PLANE_AXES: [[usize; 3]; 3] = [[0, 1, 2], [2, 0, 1], [1, 2, 0]];

/// One block that changes the position.
#[derive(Clone, Debug)]
pub struct Record {
    /// 0-based line index.
    pub line: u32,
    pub motion: Motion,
    /// 0 = XY, 1 = ZX, 2 = YZ.
    pub plane: u8,
    /// Program units are inches.
    pub inch: bool,
    /// G91.
    pub incremental: bool,
    /// G90.1 (absolute arc centres).
    pub arc_absolute: bool,
    /// Can be corrected: supported, start and end known.
    pub supported: bool,
    /// Bit i set when axis AXES[i] is written in the block.
    pub named: u16,
    /// End position, mm (degrees for A, B, C); NaN where unknown.
    pub end: [f64; NAXES],
    /// Arc centre in the plane's (first, second) coordinates, mm.
    pub center: [f64; 2],
    /// Arc turns (P word), 1 for an ordinary arc.
    pub turns: u32,
    /// A move of a canned cycle: 0 = not one, [`CYCLE_MOVE`], or [`CYCLE_BOTTOM`] for the feed to
    /// the bottom of a hole (the hole's sample point; its displacement moves the whole hole).
    pub cycle: u8,
    /// Index into [`Interp::frames`]: the offsets of the program's coordinates in this block.
    pub frame: u32,
    /// Index into [`Interp::comps`] for a move under cutter radius compensation (or the move
    /// that ends it), [`NO_COMP`] otherwise.
    pub comp: u32,
    /// G93 (inverse-time feed) in force: the block's F word is the inverse of the move's time in
    /// minutes, so each piece the move is cut into needs its own F.
    pub inverse_time: bool,
    /// Lathe diameter mode (LinuxCNC's G7, a Fanuc lathe's X): the X word is twice the X
    /// coordinate (`end[0]` is the radius).
    pub diameter: bool,
    /// Radius compensation in G18 or G19 in force (a lathe's tool nose radius, or a cutter's
    /// outside G17): the radius (mm), 0 without. The move is corrected on the programmed
    /// contour, which the control offsets in the record's plane; the field must not vary within
    /// the radius by more than half the chord tolerance.
    pub nose: f64,
    /// Why the move must stay one move (0: it need not): [`WHOLE_NOSE`], [`WHOLE_CONTOUR`].
    pub whole: u8,
    /// Index into [`Interp::rotations`] of the coordinate rotation its X and Y are written
    /// under ([`NO_ROT`]: none): its end and centre are where the rotation puts them.
    pub rot: u32,
    /// Before the first move that gives X and Y after G68 or G69 (a move naming neither): a
    /// corrected X or Y is written with the other, absolute (how a control takes a coordinate
    /// left out across the change is its setting).
    pub xy_both: bool,
}

/// [`Record::whole`] of the move that starts or ends radius compensation in G18/G19 (the first
/// in the plane after G41/G42 or G40): the control goes between the programmed and the offset
/// point along it.
pub const WHOLE_NOSE: u8 = 1;
/// [`Record::whole`] of the first or last block of a roughing cycle's contour (numbered P or Q):
/// the pieces after the last's line would not belong to the contour, and the first's would move
/// the point the cycle roughs from.
pub const WHOLE_CONTOUR: u8 = 2;
/// [`Record::whole`] of a spindle-synchronised move (LinuxCNC's G33): each block synchronises
/// anew with the spindle, so cut in pieces each would start its thread again.
pub const WHOLE_SYNC: u8 = 3;

/// A Fanuc lathe's roughing cycle (G71/G72 with P and Q) whose contour, the blocks numbered P
/// through Q right after it, is being read: corrected where it is (the control roughs along it
/// and G70 finishes along it), the cycle's blocks copied.
#[derive(Clone, Copy, Debug)]
struct Contour {
    code: i32,
    p: f64,
    q: f64,
    /// The next block is the contour's first (it must be numbered P).
    first: bool,
    /// The block numbered Q has been read: the control is back at the cycle's start.
    done: bool,
    /// The cycle's start (mm), where the control goes back to after it.
    start: [f64; NAXES],
}

/// [`Record::comp`] of a move without cutter radius compensation.
pub const NO_COMP: u32 = u32::MAX;

/// Where the tool centre is, under cutter radius compensation (G41/G42), relative to the
/// programmed point of a move, as LinuxCNC puts it: the contour offset by the tool radius to the
/// side, the first move from the programmed start to the offset end, the move after G40 from the
/// offset to the programmed end. The field is evaluated at the tool centre.
#[derive(Clone, Debug, Default)]
pub struct Comp {
    /// The tool radius, mm.
    pub radius: f64,
    /// A straight move: the tool centre's offset (X, Y, mm) from the programmed point at the
    /// block's start and end, linear in between.
    pub start: [f64; 2],
    pub end: [f64; 2],
    /// An arc: the offset is this (mm) times the unit vector from the arc's centre to the point.
    pub radial: f64,
    /// An arc that starts compensation (LinuxCNC's `convert_arc_comp1`): the tool goes from the
    /// programmed start along another arc to the end's offset point: its centre (X, Y), its
    /// radius, and the angles (rad) of its start and end about that centre, the sweep signed as
    /// the arc turns. The tool centre at a fraction t of the programmed arc's sweep is at the same
    /// fraction of this one's.
    pub entry: Option<([f64; 2], f64, f64, f64)>,
    /// An inside corner before the move with an arc on either side: the controller meets the
    /// offset circle there, which only the moves written whole keep.
    pub arc_corner: bool,
    /// The move after G40 that ends compensation, from the offset point.
    pub exit: bool,
    /// The tool centre around the corner before the move (X, Y offsets from the block's start
    /// point, mm): first where the move before ended, whose displacement the corner gets, then
    /// the arc the controller adds about an outside corner, or the point where the two offset
    /// paths meet at an inside one, and where this move starts. Empty without a corner.
    pub corner: Vec<[f64; 2]>,
    /// At an inside corner before the move: how far (mm) the tool stops short of the offset
    /// ends there, along the move before and along this one (0 elsewhere). A piece the
    /// corrected program cuts next to the corner must be longer.
    pub trim: f64,
    /// At a turn under 0.05 rad before the move (which the controller neither rounds nor trims):
    /// how far apart (mm) the offset ends meet; the tool goes straight from the move before's
    /// offset end to this move's, so a move cut in pieces would take another path (0 elsewhere).
    pub kink: f64,
}

/// Tool length offsets of a tool table (or at a program's start): unknown along Z.
const UNKNOWN_LENGTH: [f64; NAXES] = {
    let mut t = [0.0; NAXES];
    t[2] = f64::NAN;
    t
};

/// [`Record::cycle`] of a move of a canned cycle.
pub const CYCLE_MOVE: u8 = 1;
/// [`Record::cycle`] of the feed that ends at the bottom of a hole.
pub const CYCLE_BOTTOM: u8 = 2;
/// [`Record::cycle`] of a Fanuc lathe's G90/G94 box cycle ([`LatheBox`]): its corner (a feed
/// record, moved as a whole by the field there) and the return to its start (the last record of
/// the block).
pub const CYCLE_LATHE: u8 = 3;
/// [`Record::cycle`] of a Fanuc lathe's roughing cycle block (G71/G72 with its contour after it):
/// where the output stands there is where the control goes back to after the contour.
pub const CYCLE_CONTOUR_START: u8 = 4;
/// [`Record::cycle`] of the return to a roughing cycle's start after its contour (the block
/// numbered Q): the output is back where it stood at the cycle's block.
pub const CYCLE_CONTOUR_BACK: u8 = 5;

/// A Fanuc lathe's turning (G90) or facing (G94) cycle block of G-code system A: from its start
/// A (where the tool stands) a rapid to the cut, a feed along Z (G90) or X (G94) to the corner,
/// a feed back out along the other axis, and a rapid back to A. Its two cuts meet at the corner,
/// which the field moves as a whole (the block's X and Z rewritten); the field must not vary
/// along the cuts by more than the chord tolerance.
///
/// Its grooving and threading cycles (G74, G75, G76: [`LATHE_CUTS`]) are records of the same
/// shape: the end of the cut (X, Z) and the return to the start. They cut within the rectangle
/// between the start and that end, which the field moves as one: the end is moved by the field
/// there, and the start too (the thread's phase and the groove's place are reckoned from it), so
/// the output must stand at the start so moved when the cycle begins.
#[derive(Clone, Copy, Debug)]
pub struct LatheBox {
    /// 0-based line.
    pub line: u32,
    /// 900 (G90), 940 (G94), or one of [`LATHE_CUTS`].
    pub code: i32,
    /// The start A (mm): radius, Y 0, Z.
    pub start: [f64; 3],
    /// How far (mm) beyond the rectangle the cycle may cut, in X (radius) and Z: a thread's taper,
    /// a groove's clearance or relief.
    pub margin: [f64; 2],
    /// The state in force before the block: a move the output adds before a grooving or
    /// threading cycle (to its moved start) is written in it.
    pub before: Before,
}

/// The modal state in force before a block (see [`LatheBox::before`]).
#[derive(Clone, Copy, Debug)]
pub struct Before {
    /// The motion in force: G0 or G1; None for another (an arc, a cycle, G33, none), in which no
    /// move can be added.
    pub motion: Option<Motion>,
    pub incremental: bool,
    pub inch: bool,
    /// Lathe diameter mode: X words are diameters.
    pub diameter: bool,
    /// The program's origin (mm): work offset and G92/G52 shifts.
    pub off: [f64; NAXES],
}

/// [`LatheBox::code`] of a Fanuc lathe's face grooving (G74), grooving (G75) and threading (G76)
/// cycles.
pub const LATHE_CUTS: [i32; 3] = [740, 750, 760];

/// What a grooving or threading cycle ([`LATHE_CUTS`]) is called in messages.
pub fn lathe_cut_name(code: i32) -> &'static str {
    match code {
        740 => "face grooving cycle G74",
        750 => "grooving cycle G75",
        _ => "threading cycle G76",
    }
}

/// The axis bits ([`Record::named`]) of a Fanuc lathe's X, Z, U and W.
const LATHE_XZ: u16 = 1 | (1 << 2) | (1 << 6) | (1 << 8);

/// A canned-cycle block as the interpreter read it: what the emitter needs to rewrite it. Its
/// holes are the ends of its [`CYCLE_BOTTOM`] records.
#[derive(Clone, Debug)]
pub struct Cycle {
    /// 0-based line index.
    pub line: u32,
    /// The cycle's G code × 10 (810 for G81).
    pub code: i32,
    /// Retract to the initial level (G98) rather than to the R plane (G99).
    pub g98: bool,
    /// The first cycle block since a motion that is not a cycle: the initial level (LinuxCNC's
    /// `cycle_il`) is the Z before it.
    pub sets_level: bool,
    /// R plane and bottom of its holes, mm.
    pub r: f64,
    pub bottom: f64,
    /// Peck depth (program units) and dwell (seconds), as in force for the block.
    pub q: f64,
    pub p: f64,
    /// Repeats (L).
    pub repeats: u32,
    /// R and Z as in force for the block (program units; written or kept from the block before,
    /// relative in G91), the input's numbers a copied block relies on.
    pub r_word: f64,
    pub z_word: f64,
    /// Neither G98 nor G99 is stated before the block and the dialect does not make its initial
    /// mode certain: the controller decides how the tool retracts (`g98` is then a guess).
    pub retract_unknown: bool,
    /// LinuxCNC's two choices for the block, as the program's numbers make them: the tool rises
    /// to the R plane first (the initial level is below it), and it reaches the first hole at
    /// the height it is at (above the R plane) rather than at the retract level.
    pub choices: (bool, bool),
}

/// One step of a canned cycle as LinuxCNC runs it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CycleStep {
    /// A move (rapid or feed) to a point (program units); `true` for the feed to a hole's bottom.
    Move(Motion, [f64; 3], bool),
    /// A dwell of the block's P seconds.
    Dwell,
}

/// Where a hole of a cycle block is and its R plane and bottom (program units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hole {
    pub x: f64,
    pub y: f64,
    pub r: f64,
    pub bottom: f64,
}

/// Canned cycles whose motion the engine follows (G17 only): G73, G74, G81–G86, G89.
pub fn cycle_traced(code: i32) -> bool {
    matches!(code, 730 | 740 | 810 | 820 | 830 | 840 | 850 | 860 | 890)
}

/// The distance G73 and G83 back off above the last peck: LinuxCNC's `G83_RAPID_DELTA`, 0.010
/// inch, times 25.4 in millimetre programs (program units).
pub fn peck_clearance(inch: bool) -> f64 {
    if inch {
        0.010
    } else {
        0.010 * 25.4
    }
}

/// The steps of one canned-cycle block in the XY plane, as LinuxCNC's `convert_cycle_xy` and
/// `CYCLE_MACRO` make them (linuxcnc-uspace 2.9, `interp_cycles.cc`), in program units: from
/// `cur`, with the initial level `level`, one hole per repeat (all with the same R plane and
/// bottom when read from a program; the emitter may give each its own). `choices` imposes
/// [`Cycle::choices`] (else they are made from the numbers). Returns the position after the
/// block and the choices made.
pub fn cycle_steps(
    code: i32,
    g98: bool,
    q: f64,
    rapid_delta: f64,
    cur: [f64; 3],
    level: f64,
    holes: &[Hole],
    choices: Option<(bool, bool)>,
    out: &mut Vec<CycleStep>,
) -> ([f64; 3], (bool, bool)) {
    let r0 = holes[0].r;
    let mut old_cc = level;
    let mut current_cc = cur[2];
    // below the R plane: straight up to it first
    let rise = choices.map_or(old_cc < r0, |c| c.0);
    if rise {
        out.push(CycleStep::Move(Motion::Rapid, [cur[0], cur[1], r0], false));
        old_cc = r0;
        current_cc = r0;
    }
    let mut end = cur;
    let from_current = choices.map_or(current_cc > r0, |c| c.1);
    let mv = |out: &mut Vec<CycleStep>, m: Motion, x: f64, y: f64, z: f64| {
        out.push(CycleStep::Move(m, [x, y, z], false))
    };
    for (k, h) in holes.iter().enumerate() {
        let (x, y, r, cc) = (h.x, h.y, h.r, h.bottom);
        let clear = if g98 { old_cc } else { r };
        if k == 0 && from_current {
            mv(out, Motion::Rapid, x, y, current_cc);
            mv(out, Motion::Rapid, x, y, r);
        } else {
            mv(out, Motion::Rapid, x, y, clear);
            if clear > r {
                mv(out, Motion::Rapid, x, y, r);
            }
        }
        let bottom = CycleStep::Move(Motion::Feed, [x, y, cc], true);
        match code {
            730 | 830 => {
                let mut depth = r - q;
                while depth > cc {
                    mv(out, Motion::Feed, x, y, depth);
                    if code == 830 {
                        mv(out, Motion::Rapid, x, y, r);
                    }
                    mv(out, Motion::Rapid, x, y, depth + rapid_delta);
                    depth -= q;
                }
                out.push(bottom);
                mv(out, Motion::Rapid, x, y, clear);
            }
            740 | 840 => {
                out.push(bottom);
                out.push(CycleStep::Dwell);
                mv(out, Motion::Feed, x, y, clear);
            }
            850 => {
                out.push(bottom);
                mv(out, Motion::Feed, x, y, r);
                mv(out, Motion::Rapid, x, y, clear);
            }
            820 | 860 => {
                out.push(bottom);
                out.push(CycleStep::Dwell);
                mv(out, Motion::Rapid, x, y, clear);
            }
            890 => {
                out.push(bottom);
                out.push(CycleStep::Dwell);
                mv(out, Motion::Feed, x, y, clear);
            }
            _ => {
                out.push(bottom);
                mv(out, Motion::Rapid, x, y, clear);
            }
        }
        end = [x, y, clear];
    }
    (end, (rise, from_current))
}

/// A construct the engine does not interpret, with the line where it appears.
#[derive(Clone, Debug, PartialEq)]
pub struct Unsupported {
    pub line: u32,
    pub col: u32,
    pub construct: String,
    /// Motion blocks it affects (including its own line when that one moves).
    pub blocks: u32,
}

/// A remark on something kept but not corrected (G53 moves, block delete, ...).
#[derive(Clone, Debug, PartialEq)]
pub struct Note {
    pub line: u32,
    pub message: String,
}

/// Modal summary of a whole program, for `inspect`.
#[derive(Clone, Debug, Default)]
pub struct Summary {
    pub inch_lines: u32,
    pub mm_lines: u32,
    pub planes: [u32; 3],
    pub counts: [u32; 7],
    pub work_offsets: Vec<u16>,
    pub tools: Vec<u32>,
    pub block_delete_lines: u32,
    /// 0-based line where the program ends (M2/M30/closing %), if it does.
    pub end_line: Option<u32>,
}

/// The result of interpreting a program.
#[derive(Clone, Debug, Default)]
pub struct Interp {
    pub records: Vec<Record>,
    /// For every line, the index of its record or u32::MAX.
    pub line_record: Vec<u32>,
    pub unsupported: Vec<Unsupported>,
    pub notes: Vec<Note>,
    pub summary: Summary,
    /// Position before the first record (all NaN at a program's start: a program does not know
    /// where the machine is).
    pub origin: [f64; NAXES],
    /// Line index (0-based, from the program's start) of `line_record[0]`.
    pub line_base: usize,
    /// The canned-cycle blocks whose motion is traced, in line order.
    pub cycles: Vec<Cycle>,
    /// A Fanuc lathe's G90/G94 box cycles of the run, in line order.
    pub boxes: Vec<LatheBox>,
    /// Offsets of the program's coordinates (mm; degrees for A, B, C) from the frame positions
    /// are kept in — the program's coordinates where its moves began, which a field is measured
    /// in: a number written `v` (absolute) is the position `v·unit + offset`. Set by G92, G52,
    /// G92.1/.2/.3 and G10 L2/L20 on the system in force; NaN where the program does not tell.
    /// The first is the offsets at the start of the run.
    pub frames: Vec<[f64; NAXES]>,
    /// Lines of G92 and G10 L20 after the first move, with the frame they set: their offsets
    /// depend on where the tool is, which the correction moves, so the emitter rewrites their
    /// words to set the same offsets in the corrected program. (line, frame, inch)
    pub frame_lines: Vec<(u32, u32, bool)>,
    /// The dialect the program was read in.
    pub dialect: Dialect,
    /// Cutter radius compensation of the run's moves ([`Record::comp`]).
    pub comps: Vec<Comp>,
    /// Moves under radius compensation in G18/G19 that turn from the move before into an inside
    /// corner ([`Record::nose`]): (record, 1/cos(turn/2), the most a corner where the control
    /// meets the two offset paths multiplies their error by; R·tan(turn/2), how far short of the
    /// corner the tool stops on both moves, which the pieces next to it must be longer than).
    pub nose_corners: Vec<(u32, f64, f64)>,
    /// The splines of the run (G5, G5.1), in record order.
    pub splines: Vec<Spline>,
    /// The coordinate rotations of the run's moves ([`Record::rot`]).
    pub rotations: Vec<Rotation>,
}

impl Interp {
    /// The spline of record `ri` ([`Interp::splines`]), if it is one.
    pub fn spline(&self, ri: usize) -> Option<&Spline> {
        let sp = &self.splines;
        sp.binary_search_by_key(&(ri as u32), |s| s.rec)
            .ok()
            .map(|k| &sp[k])
    }
}

/// Modal conditions under which motion blocks cannot be corrected, with the line that set them.
#[derive(Clone, Copy, Debug, Default)]
struct Active {
    canned: Option<(u32, usize)>,
    cutter_comp: Option<(u32, usize)>,
    shift: Option<(u32, usize)>,
    rotation: Option<(u32, usize)>,
    scaling: Option<(u32, usize)>,
    polar: Option<(u32, usize)>,
    diameter: Option<(u32, usize)>,
    inverse_fanuc: Option<(u32, usize)>,
    /// G91 on a Fanuc lathe: another G-code system than A, or not one at all.
    system: Option<(u32, usize)>,
    flow: Option<(u32, usize)>,
    /// A work coordinate system other than the one the program's moves began in.
    wcs: Option<(u32, usize)>,
}

impl Active {
    fn first(&self) -> Option<usize> {
        self.flow
            .or(self.shift)
            .or(self.rotation)
            .or(self.scaling)
            .or(self.polar)
            .or(self.diameter)
            .or(self.cutter_comp)
            .or(self.canned)
            .or(self.inverse_fanuc)
            .or(self.system)
            .or(self.wcs)
            .map(|(_, idx)| idx)
    }
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Mode {
    Motion(Motion),
    Canned(i32),
    /// G38.2–G38.5: probing moves, which stop where the probe trips (copied, not traced).
    Probe,
    None,
}

#[derive(Debug)]
struct State {
    pos: [f64; NAXES],
    mode: Mode,
    plane: u8,
    inch: bool,
    incremental: bool,
    arc_absolute: bool,
    active: Active,
    cyc: CycleModal,
    /// The work coordinate system in force (G54 = 540, ...), and the one the first move was in.
    wcs: i32,
    wcs_moves: Option<i32>,
    /// The offsets in force ([`Interp::frames`]), the offsets the G92/G52 register at zero would
    /// give (G92.1, G92.2) and the ones G92.3 restores; NaN where unknown.
    off: [f64; NAXES],
    off_base: [f64; NAXES],
    off_saved: [f64; NAXES],
    /// Index of `off` in the current run's frames.
    frame: u32,
    dialect: Dialect,
    /// The last of G0, G1, G2, G3 (Fanuc's group 01, which a canned cycle leaves as it is).
    g01: Option<Motion>,
    /// G93: each feed move's F is the inverse of its time in minutes.
    inverse_time: bool,
    /// X words are diameters (LinuxCNC's G7; a Fanuc lathe's always).
    diameter: bool,
    /// Whether X is a diameter is known: on a LinuxCNC lathe once the program states G7 or G8
    /// (before, it is the machine's start-up setting).
    diameter_known: bool,
    /// The tool length offsets in force, per axis (mm): G43.1's words, 0 after G49, NaN after
    /// G43/G43.2 (the tool table's) and at the start.
    tlo: [f64; NAXES],
    /// Cutter radius compensation in force (G41/G42 with a known radius).
    comp: Option<CompOn>,
    /// Radius compensation in G18/G19 in force (a lathe's nose radius, a cutter's outside G17): the radius, mm.
    nose: Option<f64>,
    /// The next move in the plane starts or ends that compensation ([`WHOLE_NOSE`]).
    nose_edge: bool,
    /// LinuxCNC's G33 in force: the feed moves are synchronised with the spindle ([`WHOLE_SYNC`]).
    sync: bool,
    /// The modal state as the block being read began.
    before: Before,
    /// Under that compensation: the direction (in the plane's coordinates) the last move in the
    /// plane ended in; None before the first.
    nose_dir: Option<[f64; 2]>,
    /// Its side: 1 left of the path (G41), -1 right (G42), in the plane's coordinates.
    nose_side: f64,
    /// The block being read is the first or the last of a roughing cycle's contour
    /// ([`WHOLE_CONTOUR`]).
    contour_edge: bool,
    /// The roughing cycle whose contour is being read, and the (P, Q) of those read (a G70
    /// finishes along one of them).
    contour: Option<Contour>,
    contours: Vec<(f64, f64)>,
    /// Whether the plane is known: on a LinuxCNC lathe once the program states it (before, it
    /// is the machine's start-up setting; a Fanuc lathe starts in G18, a mill in G17).
    plane_known: bool,
    /// A Fanuc lathe's G71/G72/G73 with P and Q: the blocks after it through the one numbered Q
    /// are its contour, which the control runs inside the cycle (not followed): (Q, the
    /// cycle's unsupported construct).
    contour_until: Option<(f64, usize)>,
    /// The X (radius) and Z (mm) of the last G90/G94 box cycle block: modal while the cycle is,
    /// and whether a block of it gave R (a taper, modal too).
    box_xz: [f64; 2],
    box_taper: bool,
    /// After G40: the offset the tool centre stands at until the move that ends compensation.
    comp_exit: Option<[f64; 2]>,
    /// LinuxCNC's register a G5 without I and J takes its first control point from (offsets as
    /// written: the last G5's -P -Q); None where the program has not set it (G87 sets it
    /// too, from its I J).
    spline_ij: Option<[f64; 2]>,
    /// Inside LinuxCNC's NURBS (after G5.2, before G5.3): its unsupported construct.
    nurbs_open: Option<usize>,
    /// The coordinate rotation in force (Fanuc's G68), and its index in the run's rotations.
    rot: Option<Rotation>,
    rot_idx: Option<u32>,
    /// Under a rotation: the programmed X Y of where the tool is (mm, with the offsets), which
    /// a move that leaves one out keeps; and whether a move since G68 or G69 gave both (before
    /// one does, how the control takes the one left out is its setting: refused).
    prog_xy: [f64; 2],
    rot_first: bool,
    /// After G40 ending compensation the engine did not follow: the move that ends it is not
    /// corrected either (the blocker stays until a move in the plane).
    comp_unfollowed_exit: bool,
    /// The tool a T word selected, and the one M6 loaded.
    tool_next: Option<u32>,
    tool_loaded: Option<u32>,
    /// Tool diameters (tool number, mm) of the tool table the caller gave.
    tools: std::sync::Arc<Vec<(u32, f64)>>,
}

/// Cutter radius compensation in force.
#[derive(Clone, Copy, Debug)]
struct CompOn {
    /// Tool radius (mm), positive with the tool left of the contour (G41), negative right.
    r: f64,
    /// The tool centre's offset and the contour's direction at the end of the last move in the
    /// plane; None before the first (the entry move).
    last: Option<([f64; 2], [f64; 2])>,
    /// The last move in the plane was an arc that started compensation.
    after_entry_arc: bool,
    /// The last move in the plane was an arc: its centre and its offset circle's radius.
    last_arc: Option<([f64; 2], f64)>,
}

/// What canned cycles keep from block to block, as LinuxCNC keeps it.
#[derive(Clone, Copy, Debug, Default)]
struct CycleModal {
    /// The initial level (mm), set by the first cycle block after another motion.
    level: Option<f64>,
    /// The cycle code of the last cycle block, 0 after any other motion: R, Z, Q and P may be
    /// left out only in a block of the same cycle.
    last: i32,
    /// R and Z as last written (program units; relative in G91), Q and P.
    r: f64,
    z: f64,
    q: f64,
    p: f64,
    /// G98 (true) or G99 (false) once the program sets one.
    g98: Option<bool>,
    /// The program's cycles have been noted as read in rs274's default retract mode.
    noted_default: bool,
    /// A cycle of the current run was read in a retract mode the program does not state and the
    /// dialect does not make certain: the height after the run is unknown.
    unknown_run: bool,
}

fn code(w: &Word) -> i32 {
    crate::lex::round(w.value * 10.0) as i32
}

fn g_name(c: i32) -> String {
    if c % 10 == 0 {
        format!("G{}", c / 10)
    } else {
        format!("G{}.{}", c / 10, c % 10)
    }
}

fn ierr(line: usize, col: usize, msg: impl Into<String>) -> NcError {
    NcError::Interpret {
        line: line + 1,
        col: col + 1,
        message: msg.into(),
    }
}

/// How far an R-format arc's radius may fall short of half the chord (LinuxCNC's
/// RADIUS_TOLERANCE: 0.00005 inch, 0.00127 mm; the same length in both units).
const ARC_ABS_TOL_MM: f64 = 0.00005 * MM_PER_INCH;
/// Radius mismatch LinuxCNC 2.9 accepts between the start and end of a centre-format arc (a
/// spiral): refused when the difference exceeds 100 × the absolute tolerance, or exceeds it and
/// 0.1 % of the radius. The absolute tolerances are those `rs274` (linuxcnc-uspace 2.9) applies
/// without an INI file, in program units, measured at its accept/refuse boundary and held by
/// `tests/test_nc_parity.py`.
const SPIRAL_ABS_TOL_MM: f64 = 0.028_284_271;
const SPIRAL_ABS_TOL_INCH: f64 = 0.002_828_427;
const SPIRAL_REL_TOL: f64 = 0.001;
/// Radii below this are a zero-radius arc (LinuxCNC's radius tolerance).
const ARC_MIN_RADIUS_MM: f64 = 0.00127;

/// Interpret a lexed program (LinuxCNC's RS274NGC).
pub fn interpret(lx: &Lexed) -> Result<Interp, NcError> {
    interpret_as(lx, Dialect::LinuxCnc)
}

/// Interpret a lexed program written for `dialect`.
pub fn interpret_as(lx: &Lexed, dialect: Dialect) -> Result<Interp, NcError> {
    Interpreter::with_dialect(dialect).run_all(lx)
}

/// The interpreter's state between runs of lines: a program read piece by piece (a stream) is
/// interpreted run by run, each continuing where the one before ended.
#[derive(Debug)]
pub struct Interpreter {
    st: State,
    /// Constructs reported once with every block they affect (E words, unknown M codes).
    grouped: Vec<(String, usize)>,
    first_content_seen: bool,
    percent_open: bool,
    /// Unsupported constructs, notes and the summary of every run so far.
    pub unsupported: Vec<Unsupported>,
    pub notes: Vec<Note>,
    pub summary: Summary,
}

impl Default for Interpreter {
    fn default() -> Self {
        Self::new()
    }
}

impl Interpreter {
    /// The state at the start of a program (no motion mode, every position unknown).
    pub fn new() -> Self {
        Self::with_dialect(Dialect::LinuxCnc)
    }

    /// The state at the start of a program written for `dialect`.
    pub fn with_dialect(dialect: Dialect) -> Self {
        let mut pos = [f64::NAN; NAXES];
        if dialect.lathe() {
            pos[1] = 0.0;
        }
        Interpreter {
            st: State {
                pos,
                mode: Mode::None,
                plane: if dialect == Dialect::FanucLathe { 1 } else { 0 },
                inch: false,
                incremental: false,
                arc_absolute: false,
                active: Active::default(),
                cyc: CycleModal::default(),
                wcs: 540,
                wcs_moves: None,
                off: [0.0; NAXES],
                off_base: [f64::NAN; NAXES],
                off_saved: [f64::NAN; NAXES],
                frame: 0,
                dialect,
                g01: None,
                inverse_time: false,
                diameter: dialect == Dialect::FanucLathe,
                diameter_known: dialect != Dialect::LinuxCncLathe,
                tlo: UNKNOWN_LENGTH,
                comp: None,
                nose: None,
                nose_edge: false,
                nose_dir: None,
                nose_side: 1.0,
                sync: false,
                before: Before {
                    motion: None,
                    incremental: false,
                    inch: false,
                    diameter: false,
                    off: [0.0; NAXES],
                },
                contour_edge: false,
                contour: None,
                contours: Vec::new(),
                plane_known: dialect != Dialect::LinuxCncLathe,
                contour_until: None,
                box_xz: [f64::NAN; 2],
                box_taper: false,
                comp_exit: None,
                spline_ij: None,
                nurbs_open: None,
                rot: None,
                rot_idx: None,
                prog_xy: [f64::NAN; 2],
                rot_first: false,
                comp_unfollowed_exit: false,
                tool_next: None,
                tool_loaded: None,
                tools: Default::default(),
            },
            grouped: Vec::new(),
            first_content_seen: false,
            percent_open: false,
            unsupported: Vec::new(),
            notes: Vec::new(),
            summary: Summary::default(),
        }
    }

    /// The tool table for cutter radius compensation: (tool number, diameter mm). G41/G42 with
    /// a D word take tool D's diameter, without one the loaded tool's (T…M6); G41.1/G42.1 their D.
    pub fn with_tools(mut self, tools: std::sync::Arc<Vec<(u32, f64)>>) -> Self {
        self.st.tools = tools;
        self
    }

    /// Interpret a whole lexed program: one run, with what the interpreter gathered.
    pub fn run_all(mut self, lx: &Lexed) -> Result<Interp, NcError> {
        let mut it = self.run(lx, 0)?;
        it.unsupported = self.unsupported;
        it.notes = self.notes;
        it.summary = self.summary;
        Ok(it)
    }

    /// The program has ended (M2, M30 or a closing `%`): later lines are not read.
    pub fn ended(&self) -> bool {
        self.summary.end_line.is_some()
    }

    /// Interpret the lines of `lx`, the program's lines from `line_base` on. The records of the
    /// run come back (their `line` counts from the program's start; `origin` is the position
    /// before the run); unsupported constructs, notes and the summary accumulate in `self`.
    pub fn run(&mut self, lx: &Lexed, line_base: usize) -> Result<Interp, NcError> {
        let nlines = lx.lines.len();
        let mut out = Interp {
            records: Vec::with_capacity(nlines),
            line_record: vec![u32::MAX; nlines],
            origin: self.st.pos,
            line_base,
            cycles: Vec::new(),
            boxes: Vec::new(),
            frames: vec![self.st.off],
            frame_lines: Vec::new(),
            dialect: self.st.dialect,
            comps: Vec::new(),
            nose_corners: Vec::new(),
            splines: Vec::new(),
            rotations: Vec::new(),
            unsupported: std::mem::take(&mut self.unsupported),
            notes: std::mem::take(&mut self.notes),
            summary: std::mem::take(&mut self.summary),
        };
        self.st.frame = 0;
        self.st.rot_idx = None;
        let r = if out.summary.end_line.is_some() {
            Ok(())
        } else {
            self.lines(lx, line_base, &mut out)
        };
        self.unsupported = std::mem::take(&mut out.unsupported);
        self.notes = std::mem::take(&mut out.notes);
        self.summary = std::mem::take(&mut out.summary);
        r.map(|_| out)
    }

    fn lines(&mut self, lx: &Lexed, line_base: usize, out: &mut Interp) -> Result<(), NcError> {
        let nlines = lx.lines.len();
        let st = &mut self.st;
        let grouped = &mut self.grouped;
        let first_content_seen = &mut self.first_content_seen;
        let percent_open = &mut self.percent_open;
        for lj in 0..nlines {
            let li = line_base + lj;
            let line = &lx.lines[lj];
            if st.dialect.lathe() {
                st.pos[1] = 0.0;
            }
            let words = lx.line_words(lj);
            st.before = Before {
                motion: match st.mode {
                    Mode::Motion(m @ (Motion::Rapid | Motion::Feed)) if !st.sync => Some(m),
                    _ => None,
                },
                incremental: st.incremental,
                inch: st.inch,
                diameter: st.diameter,
                off: st.off,
            };
            if line.percent {
                if !*first_content_seen {
                    *percent_open = true;
                    *first_content_seen = true;
                    continue;
                } else if *percent_open {
                    out.summary.end_line = Some(li as u32);
                    break;
                }
                continue;
            }
            if let Some(e) = line.error {
                return Err(lx.errors[e as usize].clone());
            }
            if words.is_empty() && line.opaque.is_none() {
                continue;
            }
            *first_content_seen = true;
            // a Fanuc lathe's roughing cycle contour, read as moves from the cycle's start
            if let Some(c) = st.contour.as_mut() {
                let numbered = |v: f64| words.iter().any(|w| w.letter == b'N' && w.value == v);
                if c.done {
                    // back at the cycle's start (the output at its own, where it stood as the
                    // cycle began: [`CYCLE_CONTOUR_BACK`])
                    st.pos = c.start;
                    st.pos[1] = 0.0; // (a lathe's Y)
                    st.contour = None;
                    st.contour_edge = false;
                    // (the control comes back from the contour's end: no corner with it)
                    st.nose_dir = None;
                    push_record(out, st, li, Motion::Other, false, 0, [0.0; 2], 1);
                    out.records.last_mut().unwrap().cycle = CYCLE_CONTOUR_BACK;
                } else {
                    let (cycle, p, q) = (c.code, c.p, c.q);
                    let named = |l: &[u8]| words.iter().any(|w| l.contains(&w.letter));
                    let why = if c.first && !numbered(p) {
                        Some(format!(
                            "the contour of {} P{p} Q{q} does not follow it from block N{p}",
                            g_name(cycle)
                        ))
                    } else if c.first && !(named(b"X") && named(b"Z")) {
                        Some(format!("the first block of the contour of {} names X and Z (absolute) here: adding the one it leaves out would change the cycle's type (I or II), and increments from the cycle's start would make G70's contour depend on where G70 starts", g_name(cycle)))
                    } else {
                        None
                    };
                    // the program goes on, or ends, before the block numbered Q: the control
                    // alarms at the cycle
                    let ends = words.iter().any(|w| {
                        (w.letter == b'M' && matches!(w.value as i32, 2 | 30 | 99))
                            || (w.letter == b'G' && matches!(code(w), 700 | 710 | 720))
                    });
                    if ends && !numbered(q) && why.is_none() {
                        return Err(ierr(
                            li,
                            0,
                            format!("the contour of {} P{p} Q{q} has no block numbered Q{q} before this one", g_name(cycle)),
                        ));
                    }
                    let first = std::mem::replace(&mut c.first, false);
                    if let Some(why) = why {
                        let idx = push_unsupported(out, li, 0, &why);
                        st.contour = None;
                        st.contour_until = Some((q, idx));
                        // (a G70 along it is not followed either)
                        st.contours.retain(|&pq| pq != (p, q));
                    } else if numbered(q) {
                        c.done = true;
                        st.contour_edge = true;
                    } else if first {
                        st.contour_edge = true;
                    }
                }
            }
            // a contour not followed: run inside the cycle, copied here
            if let Some((q, idx)) = st.contour_until {
                if words.iter().any(|w| w.letter == b'N' && w.value == q) {
                    st.contour_until = None;
                }
                st.pos = [f64::NAN; NAXES];
                push_record(out, st, li, Motion::Other, false, 0, [0.0; 2], 1);
                out.unsupported[idx].blocks += 1;
                continue;
            }
            if line.block_delete {
                out.summary.block_delete_lines += 1;
            }
            let col = |w: &Word| (w.start - line.start) as usize;

            if let Some((kind, at)) = line.opaque {
                let c = (at - line.start) as usize;
                let construct = match kind {
                    Opaque::Expression => "parameters or expressions (# or [ ])",
                    Opaque::OWordFlow => "O-word subroutine or control flow",
                    Opaque::GrblSetting => {
                        "grbl setting ($n=, $RST=, $N0=): it changes how the machine runs what follows"
                    }
                    Opaque::GrblOther => continue, // moves nothing: copied
                    Opaque::GrblMove => {
                        // homing or a jog: copied; where it leaves the machine is not traced
                        st.pos = [f64::NAN; NAXES];
                        push_record(out, st, li, Motion::Other, false, 0, [0.0; 2], 1);
                        out.notes.push(Note {
                            line: li as u32,
                            message: "grbl homing or jog ($H, $J=): kept as written, not corrected; the axes it moves are unknown afterwards".into(),
                        });
                        continue;
                    }
                };
                if kind == Opaque::GrblSetting {
                    push_unsupported(out, li, c, construct);
                    continue;
                }
                let idx = push_unsupported(out, li, c, construct);
                if kind == Opaque::OWordFlow && st.active.flow.is_none() {
                    st.active.flow = Some((li as u32, idx));
                }
                // an assignment alone moves nothing; anything else may move any axis
                let assignment_only = words.is_empty() && kind == Opaque::Expression;
                if !assignment_only {
                    st.pos = [f64::NAN; NAXES];
                    push_record(out, st, li, Motion::Other, false, 0, [0.0; 2], 1);
                    out.unsupported[idx].blocks += 1;
                }
                continue;
            }

            // gather words
            let mut gs: [(i32, usize); 32] = [(0, 0); 32];
            let mut ng = 0usize;
            let mut axis: [Option<f64>; NAXES] = [None; NAXES];
            let mut axis_col = 0usize;
            let mut ijk: [Option<f64>; 3] = [None; 3];
            let mut r: Option<(f64, usize)> = None;
            let mut p: Option<f64> = None;
            let mut ms: [(i32, usize); 8] = [(0, 0); 8];
            let mut nm = 0usize;
            let mut named: u16 = 0;
            let mut l_word: Option<f64> = None;
            let mut q_word: Option<f64> = None;
            let mut e_word: Option<usize> = None;
            let mut e_value: Option<f64> = None;
            let mut d_word: Option<f64> = None;
            // LinuxCNC's polar distance @ and angle ^ (degrees), with the column of the first
            let mut polar: [Option<f64>; 2] = [None; 2];
            let mut polar_col = 0usize;
            let mut seen: u32 = 0;
            let mut wcol = [0usize; 26];
            for w in words {
                // LinuxCNC reads each letter once per block (G and M words excepted)
                if w.letter.is_ascii_uppercase() && !matches!(w.letter, b'G' | b'M') {
                    let bit = 1u32 << (w.letter - b'A');
                    wcol[(w.letter - b'A') as usize] = col(w);
                    if seen & bit != 0 {
                        return Err(ierr(
                            li,
                            col(w),
                            format!("more than one {} word in one block", w.letter as char),
                        ));
                    }
                    seen |= bit;
                }
                match w.letter {
                    b'G' if ng < gs.len() => {
                        // (a G code has one decimal at most: G5.09 is no G5.1)
                        let tenths = w.value * 10.0;
                        if (tenths - crate::lex::round(tenths)).abs() > 1e-6 {
                            return Err(ierr(
                                li,
                                col(w),
                                format!("G-code out of range: G{} (as rs274)", w.value),
                            ));
                        }
                        gs[ng] = (code(w), col(w));
                        ng += 1;
                    }
                    b'M' if nm < ms.len() => {
                        ms[nm] = (crate::lex::round(w.value) as i32, col(w));
                        nm += 1;
                    }
                    b'G' | b'M' => {
                        return Err(ierr(
                            li,
                            col(w),
                            format!("too many {} words in one block", w.letter as char),
                        ));
                    }
                    b'X' | b'Y' | b'Z' | b'A' | b'B' | b'C' | b'U' | b'V' | b'W' => {
                        let k = axis_index(w.letter).unwrap();
                        if axis[k].is_none() {
                            axis_col = col(w);
                        }
                        axis[k] = Some(w.value);
                        named |= 1 << k;
                    }
                    b'I' => ijk[0] = Some(w.value),
                    b'J' => ijk[1] = Some(w.value),
                    b'K' => ijk[2] = Some(w.value),
                    b'R' => r = Some((w.value, col(w))),
                    b'P' => p = Some(w.value),
                    b'L' => l_word = Some(w.value),
                    b'Q' => q_word = Some(w.value),
                    b'E' => {
                        e_word = Some(col(w));
                        e_value = Some(w.value);
                    }
                    b'D' => d_word = Some(w.value),
                    b'@' | b'^' => {
                        let k = (w.letter == b'^') as usize;
                        if polar[k].is_some() {
                            return Err(ierr(
                                li,
                                col(w),
                                format!("more than one {} word in one block", w.letter as char),
                            ));
                        }
                        if polar.iter().all(|v| v.is_none()) {
                            polar_col = col(w);
                        }
                        polar[k] = Some(w.value);
                    }
                    b'T' => {
                        let t = w.value.round() as u32;
                        st.tool_next = Some(t);
                        if !out.summary.tools.contains(&t) {
                            out.summary.tools.push(t);
                        }
                    }
                    _ => {}
                }
            }

            // polar coordinates stand for X and Y (read below, once the block's units are known)
            let polar_used = polar.iter().any(|v| v.is_some());
            if polar_used {
                if axis[0].is_some() || axis[1].is_some() {
                    return Err(ierr(
                        li,
                        polar_col,
                        "polar coordinates (@ ^) and X or Y in one block; give one or the other",
                    ));
                }
                named |= 0b11;
            }

            // on a Fanuc-family control a length or angle written without a decimal point counts
            // least input increments unless a machine parameter says otherwise: which one, the
            // program does not tell (zero is zero either way; G65's words are a macro's arguments)
            if st.dialect.point_matters() && !gs[..ng].iter().any(|&(c, _)| c == 650) {
                let cycle = gs[..ng].iter().any(|&(c, _)| cycle_code(c))
                    || (matches!(st.mode, Mode::Canned(_))
                        && !gs[..ng]
                            .iter()
                            .any(|&(c, _)| matches!(c, 0 | 10 | 20 | 30 | 800)));
                // a lathe's grooving and threading cycles: A the tool's angle, P and Q integers
                // (Fanuc's parameters and depths in least increments, Haas's method and start
                // angle), K a length (the thread's height, the groove's step)
                let lathe_cut = st.dialect == Dialect::FanucLathe
                    && gs[..ng].iter().any(|&(c, _)| matches!(c, 740 | 750 | 760));
                if let Some(w) = words.iter().find(|w| {
                    w.decimals < 0
                        && w.value != 0.0
                        && match w.letter {
                            b'A' | b'P' | b'Q' if lathe_cut => false,
                            b'K' if lathe_cut => true,
                            b'Q' => cycle,
                            b'K' => !cycle,
                            l => INCREMENT_WORDS.contains(&l),
                        }
                }) {
                    let text = format!("{}{}", w.letter as char, w.value);
                    let dwell =
                        gs[..ng].iter().any(|&(c, _)| c == 40) && matches!(w.letter, b'X' | b'U');
                    if dwell {
                        return Err(ierr(
                            li,
                            col(w),
                            format!(
                                "{text} has no decimal point: a Fanuc/Haas control reads a dwell's time written so in least input increments ({text} = {:.3} s) unless parameter 3401#0 (DPI) is set, and the program does not say which; write the point ({text}.) if {text} means {} seconds",
                                w.value * 0.001,
                                w.value
                            ),
                        ));
                    }
                    return Err(ierr(
                        li,
                        col(w),
                        format!(
                            "{text} has no decimal point: a Fanuc/Haas control reads it in least input increments ({text} = {:.3} mm in a metric program, {:.4} inch in an inch one) unless parameter 3401#0 (DPI) is set, and the program does not say which; write the point ({text}.) if {text} means {} units",
                            w.value * 0.001,
                            w.value * 0.0001,
                            w.value
                        ),
                    ));
                }
            }
            // two codes of one modal group in a block are an error, as in LinuxCNC
            for a in 0..ng {
                for b in a + 1..ng {
                    if let (Some(ga), Some(gb)) = (g_group(gs[a].0), g_group(gs[b].0)) {
                        if ga == gb && gs[a].0 != 800 && gs[b].0 != 800 {
                            return Err(ierr(
                                li,
                                gs[b].1,
                                format!(
                                    "{} and {} are of one modal group; a block may have one",
                                    g_name(gs[a].0),
                                    g_name(gs[b].0)
                                ),
                            ));
                        }
                    }
                }
            }
            if nm > 4 {
                return Err(ierr(li, ms[4].1, "more than four M words in one block"));
            }
            for a in 0..nm {
                for b in a + 1..nm {
                    let (ma, mb) = (ms[a].0, ms[b].0);
                    if let (Some(ga), Some(gb)) = (m_group(ma), m_group(mb)) {
                        if ga == gb {
                            return Err(ierr(
                                li,
                                ms[b].1,
                                format!(
                                    "M{ma} and M{mb} are of one modal group; a block may have one"
                                ),
                            ));
                        }
                    }
                }
            }
            // axis words used by a code other than a motion (G10, G28, G30, G43.1, G52, G92, an M code
            // the engine does not know, ...) do not move along the motion mode
            if named != 0
                && gs[..ng]
                    .iter()
                    .any(|&(c, _)| matches!(c, 100 | 280 | 300 | 431 | 520 | 920 | 500))
            {
                if let Some(&(c, gc)) = gs[..ng]
                    .iter()
                    .find(|&&(c, _)| g_group(c) == Some(1) && c != 800)
                {
                    let user = gs[..ng]
                        .iter()
                        .find(|&&(c, _)| matches!(c, 100 | 280 | 300 | 431 | 520 | 920 | 500))
                        .unwrap()
                        .0;
                    return Err(ierr(
                        li,
                        gc,
                        format!(
                            "{} and {} in one block both use the axis words",
                            g_name(user),
                            g_name(c)
                        ),
                    ));
                }
            }
            // an E word: a 3D printer's extruder axis (LinuxCNC reads E only for M66/M67/M68 and the
            // G70/G76 cycles); `G92 E0` alone resets the extruder and moves nothing
            let g92_e_only = e_word.is_some() && named == 0 && ng == 1 && gs[0].0 == 920;
            if g92_e_only {
                ng = 0;
            }
            let mut e_construct: Option<usize> = None;
            if let Some(ec) = e_word {
                let e_reader = ms[..nm].iter().any(|&(m, _)| matches!(m, 66..=68))
                    || gs[..ng].iter().any(|&(c, _)| matches!(c, 700 | 760))
                    || (st.dialect.is_fanuc() && gs[..ng].iter().any(|&(c, _)| c == 1870));
                if !e_reader && !g92_e_only {
                    e_construct = Some(grouped_unsupported(
                        out,
                        grouped,
                        li,
                        ec,
                        "E word (a 3D printer's extruder axis, not RS274NGC)",
                    ));
                }
            }
            // M codes the engine does not know may do anything, also with the axis words of the block
            let mut unknown_m: Option<usize> = None;
            for &(m, mc) in &ms[..nm] {
                if m_group(m).is_none() && !matches!(m, 98 | 99) && !copied_m(st.dialect, m) {
                    unknown_m = Some(grouped_unsupported(
                        out,
                        grouped,
                        li,
                        mc,
                        &format!("M code M{m} the engine does not know"),
                    ));
                    break;
                }
            }

            // modal and non-modal G codes, in LinuxCNC's order of execution
            let mut motion_word: Option<(Mode, usize)> = None;
            // LinuxCNC's G33 in the block (a feed synchronised with the spindle)
            let mut sync_word = false;
            let mut g53 = false;
            let mut nonmodal_axis_user: Option<(i32, usize)> = None;
            let mut home: Option<(i32, usize)> = None;
            // G92, G52, G92.1/.2/.3, G10 L2/L20 on the system in force: the offsets they set
            let mut frame_code: Option<(i32, usize)> = None;
            // G43, G43.1, G43.2 or G49 in the block
            let mut tool_length: Option<i32> = None;
            // G41, G41.1, G42 or G42.1 turning compensation on
            let mut comp_code: Option<(i32, usize)> = None;
            // Fanuc's G68 (its X Y the centre, R the angle)
            let mut rot_word: Option<usize> = None;
            let mut plane_word = false;
            if ms[..nm].iter().any(|&(m, _)| m == 6) {
                st.tool_loaded = st.tool_next;
            }
            let mut unit_change = None;
            let mut untraced: Option<usize> = None;
            // a lathe's roughing or finishing cycle whose contour the engine corrects: its
            // block moves nothing here (its U and W are allowances)
            let mut cycle_line = false;
            // compensation on as the block begins (a change of plane is checked against it
            // whatever the order of the block's words, as LinuxCNC sets the plane before G40)
            let comp_at_start = st.comp.is_some()
                || st.nose.is_some()
                || (st.active.cutter_comp.is_some() && !st.comp_unfollowed_exit);
            // a Fanuc lathe's grooving or threading cycle block ([`LatheCut`]): its code and column
            let mut lathe_cut: Option<(i32, usize)> = None;
            for &(c, gc) in &gs[..ng] {
                match c {
                    // a Fanuc lathe in G-code system A: G90, G92 and G94 are its turning,
                    // threading and facing cycles (group 01, refused when a block runs one),
                    // G70–G76 its multiple repetitive cycles, G98/G99 feed per minute and per
                    // revolution, and there is no G91 (U and W are the increments)
                    900 | 920 | 940 if st.dialect == Dialect::FanucLathe => {
                        motion_word = Some((Mode::Canned(c), gc))
                    }
                    // a roughing cycle with its contour right after it, and G70 finishing along
                    // one read: the cycles' blocks copied, the contour corrected where it is
                    710 | 720
                        if st.dialect == Dialect::FanucLathe
                            && st.contour.is_none()
                            && p.is_some()
                            && q_word.is_some() =>
                    {
                        let (p, q) = (p.unwrap_or_default(), q_word.unwrap_or_default());
                        st.contour = Some(Contour {
                            code: c,
                            p,
                            q,
                            first: true,
                            done: false,
                            start: st.pos,
                        });
                        st.contours.push((p, q));
                        cycle_line = true;
                    }
                    700 if st.dialect == Dialect::FanucLathe
                        && st
                            .contours
                            .contains(&(p.unwrap_or(f64::NAN), q_word.unwrap_or(f64::NAN))) =>
                    {
                        cycle_line = true;
                    }
                    // the first block of the two-block form (Fanuc: G71 U depth R retract): it
                    // sets the cycle's parameters and moves nothing
                    710 | 720
                        if st.dialect == Dialect::FanucLathe
                            && p.is_none()
                            && q_word.is_none()
                            && named & !((1 << 6) | (1 << 8)) == 0 =>
                    {
                        cycle_line = true;
                    }
                    // grooving (G74 face, G75 outside/inside) and threading (G76): the block
                    // with X/Z (U/W) runs the cycle, one without sets its parameters (the first
                    // block of Fanuc's two-block form), copied
                    740 | 750 | 760
                        if st.dialect == Dialect::FanucLathe
                            && named & LATHE_XZ == 0
                            && axis[3].is_none() =>
                    {
                        cycle_line = true;
                    }
                    740 | 750 | 760 if st.dialect == Dialect::FanucLathe => {
                        if c == 760 {
                            // (a Haas G76's A is the tool tip's angle)
                            axis[3] = None;
                            named &= !(1 << 3);
                        }
                        lathe_cut = Some((c, gc));
                    }
                    700 | 710 | 720 | 730 | 740 | 750 | 760
                        if st.dialect == Dialect::FanucLathe =>
                    {
                        let idx =
                            push_unsupported(out, li, gc, &format!("lathe cycle {}", g_name(c)));
                        untraced = Some(idx);
                        if matches!(c, 710 | 720 | 730) && p.is_some() {
                            if let Some(q) = q_word {
                                st.contour_until = Some((q, idx));
                            }
                        }
                    }
                    980 | 990 if st.dialect == Dialect::FanucLathe => {}
                    910 if st.dialect == Dialect::FanucLathe => {
                        if st.active.system.is_none() {
                            let idx = push_unsupported(
                                out,
                                li,
                                gc,
                                "G91 on a Fanuc lathe: G-code system A has none (U and W are the increments), and in systems B and C the turning cycles are other codes; which system the control runs, the program does not tell",
                            );
                            st.active.system = Some((li as u32, idx));
                        }
                    }
                    0 => motion_word = Some((Mode::Motion(Motion::Rapid), gc)),
                    10 => motion_word = Some((Mode::Motion(Motion::Feed), gc)),
                    20 => motion_word = Some((Mode::Motion(Motion::ArcCw), gc)),
                    30 => motion_word = Some((Mode::Motion(Motion::ArcCcw), gc)),
                    50 if st.dialect.is_linuxcnc() => {
                        motion_word = Some((Mode::Motion(Motion::Spline), gc))
                    }
                    51 if st.dialect.is_linuxcnc() => {
                        motion_word = Some((Mode::Motion(Motion::QSpline), gc))
                    }
                    // (G80 is handled below; its group shares no conflict with the other motions)
                    // a dwell: on a Fanuc-family control its time is P, or X (U on a lathe),
                    // which then moves nothing; LinuxCNC and grbl want P, and move other axis
                    // words of the block in the modal motion after it
                    40 if st.dialect.is_fanuc() => {
                        let time: &[usize] = if st.dialect.lathe() { &[0, 6] } else { &[0] };
                        for &k in time {
                            axis[k] = None;
                            named &= !(1 << k);
                        }
                        if named != 0 {
                            return Err(ierr(
                                li,
                                gc,
                                "axis words in a G04 block: its X (or U on a lathe) is the dwell time, and a Fanuc-family control moves no axis in it",
                            ));
                        }
                    }
                    40 if p.is_none() && !matches!(st.dialect, Dialect::Marlin) => {
                        return Err(ierr(li, gc, "dwell time missing with G4 (its P word)"));
                    }
                    40 => {}
                    170 | 180 | 190 => {
                        plane_word = true;
                        let plane = ((c - 170) / 10) as u8;
                        // (after G40 compensation is off, before the move that ends it)
                        if plane != st.plane && comp_at_start {
                            // LinuxCNC and Fanuc (alarm PS0037) refuse it too
                            return Err(ierr(
                                li,
                                gc,
                                "a change of plane with cutter compensation on (G40 first)",
                            ));
                        }
                        st.plane = plane;
                        st.plane_known = true;
                    }
                    200 => unit_change = Some(true),
                    210 => unit_change = Some(false),
                    900 => st.incremental = false,
                    910 => st.incremental = true,
                    901 => st.arc_absolute = true,
                    911 => st.arc_absolute = false,
                    400 => {
                        // compensation the engine did not follow still puts the tool at the
                        // offset until the move that ends it, which stays as written too
                        st.nose_edge |= st.nose.take().is_some();
                        st.comp_unfollowed_exit = st.active.cutter_comp.is_some();
                        if !st.comp_unfollowed_exit {
                            st.active.cutter_comp = None;
                        }
                        if let Some(on) = st.comp.take() {
                            st.comp_exit = on.last.map(|(o, _)| o);
                        }
                    }
                    410 | 411 | 420 | 421
                        if st.active.cutter_comp.is_none()
                            && st.comp.is_none()
                            && st.nose.is_none()
                            && (st.dialect.is_linuxcnc() || st.dialect.is_fanuc()) =>
                    {
                        comp_code = Some((c, gc));
                    }
                    410 | 411 | 420 | 421 => {
                        if st.comp.is_some() {
                            return Err(ierr(
                                li,
                                gc,
                                "cutter compensation turned on when it is on; G40 first",
                            ));
                        }
                        if st.active.cutter_comp.is_none() {
                            let idx = push_unsupported(
                                out,
                                li,
                                gc,
                                &format!("cutter compensation {}", g_name(c)),
                            );
                            st.active.cutter_comp = Some((li as u32, idx));
                        }
                    }
                    // tool length: program coordinates are the tool tip's, so a new length moves the
                    // tip's coordinates where the tool stands (by the table's length: unknown here;
                    // G43.1's words give it; G49 takes it off)
                    430 | 432 | 490 | 431 => tool_length = Some(c),
                    // Fanuc's extended work systems G54.1 P1…, Haas's G154 P1…: one code each
                    541 | 1540 if st.dialect.is_fanuc() => {
                        let n = p.filter(|v| v.fract() == 0.0 && (1.0..=300.0).contains(v));
                        let Some(n) = n else {
                            return Err(ierr(
                                li,
                                gc,
                                format!(
                                    "{} needs P, the number of the extended work system (1-300)",
                                    g_name(c)
                                ),
                            ));
                        };
                        set_wcs(out, st, li, gc, EXTENDED_WCS + n as i32);
                    }
                    540 | 550 | 560 | 570 | 580 | 590 | 591 | 592 | 593 => {
                        set_wcs(out, st, li, gc, c)
                    }
                    530 => g53 = true,
                    610 | 611 | 640 => {} // path control
                    940 | 950 => {
                        st.inverse_time = false;
                        st.active.inverse_fanuc = None;
                    }
                    930 => {
                        st.inverse_time = true;
                        // a Fanuc reads an arc's F under G93 as feed / radius, and an F without a
                        // point by a parameter (Haas: 1/time for every move): which, the
                        // program does not tell
                        if st.dialect.point_matters() && st.active.inverse_fanuc.is_none() {
                            let idx = push_unsupported(
                                out,
                                li,
                                gc,
                                "inverse-time feed G93 on a Fanuc-family control (an arc's F is feed / radius on a Fanuc, 1/time on a Haas)",
                            );
                            st.active.inverse_fanuc = Some((li as u32, idx));
                        }
                    }
                    960 | 970 => {} // spindle mode
                    980 => st.cyc.g98 = Some(true),
                    990 => st.cyc.g98 = Some(false),
                    // G80 beside another motion code leaves that one in force, as in LinuxCNC
                    800 => {
                        if motion_word.is_none() {
                            motion_word = Some((Mode::None, gc));
                        }
                    }
                    730 | 740 | 760 | 810 | 820 | 830 | 840 | 850 | 860 | 870 | 880 | 890 | 841
                    | 842 => {
                        motion_word = Some((Mode::Canned(c), gc));
                    }
                    70 | 80 if st.dialect.is_linuxcnc() => {
                        st.diameter = c == 70;
                        st.diameter_known = true;
                    }
                    80 => st.active.diameter = None,
                    70 => {
                        if st.active.diameter.is_none() {
                            let idx = push_unsupported(out, li, gc, "lathe diameter mode G7");
                            st.active.diameter = Some((li as u32, idx));
                        }
                    }
                    920 | 520 | 921 | 922 | 923 => frame_code = Some((c, gc)),
                    // Fanuc/Haas: G10 L20 sets an extended work offset (G54.1 P… / G154 P…), a
                    // system the engine does not follow (its moves are refused): the systems in
                    // use stay as they are. G10 L2 P0 sets the external offset, which moves every
                    // system: not followed
                    100 if st.dialect.is_fanuc()
                        && l_word == Some(20.0)
                        && r.is_none()
                        && p.is_some_and(|v| v.fract() == 0.0 && v >= 1.0) =>
                    {
                        // on the extended system in force: its origin set in machine coordinates
                        let here = p.is_some_and(|v| st.wcs == EXTENDED_WCS + v as i32);
                        frame_code = Some((if here { 1002 } else { 1000 }, gc));
                    }
                    100 if st.dialect.is_fanuc() && l_word == Some(2.0) && p == Some(0.0) => {
                        let idx = push_unsupported(
                            out,
                            li,
                            gc,
                            "external work offset G10 L2 P0 (Fanuc: it moves every work system)",
                        );
                        if st.active.shift.is_none() {
                            st.active.shift = Some((li as u32, idx));
                        }
                        nonmodal_axis_user = Some((c, idx));
                    }
                    // G10 L2/L20 on the work system in force (P0 or its number), without a rotation
                    100 if matches!(l_word, Some(l) if l == 2.0 || l == 20.0)
                        && r.is_none()
                        && p.is_some_and(|v| v == 0.0 || wcs_number(st.wcs) == Some(v)) =>
                    {
                        frame_code = Some((if l_word == Some(2.0) { 1002 } else { 1020 }, gc));
                    }
                    // on another system: the moves in it would be refused (one system per field)
                    100 if matches!(l_word, Some(l) if l == 2.0 || l == 20.0)
                        && r.is_none()
                        && p.is_some_and(|v| v.fract() == 0.0 && (1.0..=9.0).contains(&v)) =>
                    {
                        frame_code = Some((1000, gc));
                    }
                    100 => {
                        let l = l_word.unwrap_or(0.0).round() as i32;
                        let idx =
                            push_unsupported(out, li, gc, &format!("offset setting G10 L{l}"));
                        if matches!(l, 1 | 10 | 11) {
                            // a tool table entry set in the program: its diameter is no longer
                            // the table's (every tool's, when P is not a tool number)
                            let tools: Vec<(u32, f64)> = match p {
                                Some(v) if v >= 0.0 && v.fract() == 0.0 => st
                                    .tools
                                    .iter()
                                    .copied()
                                    .filter(|&(n, _)| n != v as u32)
                                    .collect(),
                                _ => Vec::new(),
                            };
                            st.tools = std::sync::Arc::new(tools);
                        }
                        if matches!(l, 2 | 20) && st.active.shift.is_none() {
                            st.active.shift = Some((li as u32, idx));
                        }
                        nonmodal_axis_user = Some((c, idx));
                    }
                    280 | 300 => home = Some((c, gc)),
                    // G28.1 / G30.1 store the position and move nothing; with axis words LinuxCNC's
                    // reading is not the documented one, so those are reported
                    281 | 301 if named != 0 => {
                        let idx = push_unsupported(
                            out,
                            li,
                            gc,
                            &format!("{} with axis words", g_name(c)),
                        );
                        nonmodal_axis_user = Some((c, idx));
                    }
                    281 | 301 => {}
                    680 if st.dialect == Dialect::Fanuc => rot_word = Some(gc),
                    680 => {
                        let idx = push_unsupported(out, li, gc, "coordinate rotation G68");
                        st.active.rotation = Some((li as u32, idx));
                    }
                    690 if line.block_delete
                        && (st.rot.is_some() || st.active.rotation.is_some()) =>
                    {
                        let idx = push_unsupported(out, li, gc, "G69 on a block-delete line (/): whether it runs is the machine's switch");
                        st.rot = None;
                        st.active.rotation = Some((li as u32, idx));
                        st.pos[0] = f64::NAN;
                        st.pos[1] = f64::NAN;
                    }
                    690 => {
                        if st.active.rotation.take().is_some() {
                            // the moves under a rotation not followed were read unrotated: where
                            // the tool is, is not known
                            st.pos[0] = f64::NAN;
                            st.pos[1] = f64::NAN;
                        }
                        if st.rot.take().is_some() {
                            st.rot_idx = None;
                            st.rot_first = true;
                        }
                    }
                    510 => {
                        let idx = push_unsupported(out, li, gc, "scaling G51");
                        st.active.scaling = Some((li as u32, idx));
                    }
                    // G50 with axis words is a Fanuc lathe's coordinate setting; alone, scaling off
                    500 if named != 0 => {
                        let idx =
                            push_unsupported(out, li, gc, "coordinate setting G50 (Fanuc lathe)");
                        if st.active.shift.is_none() {
                            st.active.shift = Some((li as u32, idx));
                        }
                        nonmodal_axis_user = Some((c, idx));
                    }
                    // a probing move stops where the probe trips: copied, its axes unknown after it
                    382..=385 => motion_word = Some((Mode::Probe, gc)),
                    500 => st.active.scaling = None,
                    160 => {
                        let idx = push_unsupported(out, li, gc, "polar coordinates G16");
                        st.active.polar = Some((li as u32, idx));
                    }
                    150 => st.active.polar = None,
                    // Fanuc/Haas modes of the look-ahead and smoothing (AI contour control G05.1
                    // Q, high-speed G05 P, Haas G187 P E): the programmed path is the same, so
                    // they are copied (LinuxCNC's G5/G5.1 are splines, with axis words)
                    51 if st.dialect.is_fanuc() && q_word.is_some() && named == 0 => {}
                    50 if st.dialect.is_fanuc() && p.is_some() && named == 0 => {}
                    1870 if st.dialect.is_fanuc() && named == 0 => {}
                    330 if st.dialect.is_linuxcnc() => {
                        motion_word = Some((Mode::Motion(Motion::Feed), gc));
                        sync_word = true;
                    }
                    _ => {
                        let what = match c {
                            50..=53 => "spline",
                            330 | 331 => "spindle-synchronised motion",
                            171 | 181 | 191 => "UVW plane",
                            700 | 710 | 720 | 711 | 721 | 712 | 722 => "lathe cycle",
                            _ => "unknown G code",
                        };
                        // (LinuxCNC's NURBS: its control points on the lines up to G5.3, which
                        // ends the one construct)
                        let idx = match st.nurbs_open.take().filter(|_| c == 53) {
                            Some(idx) => idx,
                            None => push_unsupported(out, li, gc, &format!("{what} {}", g_name(c))),
                        };
                        // these may move the machine somewhere the engine does not trace
                        untraced = Some(idx);
                        if c == 52 && st.dialect.is_linuxcnc() {
                            st.nurbs_open = Some(idx);
                        }
                    }
                }
            }
            for &(m, mc) in &ms[..nm] {
                match m {
                    98 | 99 => {
                        let idx = push_unsupported(out, li, mc, &format!("subprogram M{m}"));
                        if st.active.flow.is_none() {
                            st.active.flow = Some((li as u32, idx));
                        }
                    }
                    _ => {}
                }
            }
            if let Some(inch) = unit_change {
                st.inch = inch;
            }
            if let (Some(c), Some(_)) = (st.contour.as_mut(), untraced) {
                // a roughing cycle's block with a code the engine does not trace: where the
                // control is as the cycle begins, and so after it, is not known
                if c.first {
                    c.start = [f64::NAN; NAXES];
                }
            }
            if cycle_line && untraced.is_none() {
                if st.contour.as_ref().is_some_and(|c| c.first) {
                    // where the output stands as the roughing cycle begins: it goes back there
                    push_record(out, st, li, Motion::Other, false, 0, [0.0; 2], 1);
                    out.records.last_mut().unwrap().cycle = CYCLE_CONTOUR_START;
                }
                continue;
            }
            // a new tool offset (a Fanuc lathe's T, LinuxCNC's M6) under nose radius compensation:
            // its nose radius is another, which the check does not follow
            let new_tool = if st.dialect == Dialect::FanucLathe {
                seen & (1 << (b'T' - b'A')) != 0
            } else {
                ms[..nm].iter().any(|&(m, _)| m == 6)
            };
            if st.nose.is_some() && new_tool && st.active.cutter_comp.is_none() {
                comp_not_followed(
                    out,
                    st,
                    li,
                    0,
                    "a tool offset changed under radius compensation in G18/G19 (a lathe's nose radius, a cutter's outside G17): its radius is not followed",
                );
            }
            if untraced.is_none() {
                untraced = lathe_words(out, grouped, st, li, &mut axis, &mut named, &wcol)?;
            }
            if st.diameter && untraced.is_none() {
                let why = if polar_used {
                    Some((polar_col, "polar coordinates (@ ^) in lathe diameter mode"))
                } else if axis[0].is_some() && (frame_code.is_some() || tool_length == Some(431)) {
                    Some((axis_col, "an offset on X (G92, G52, G10, G43.1) in lathe diameter mode: whether its X is a diameter is not followed"))
                } else {
                    None
                };
                if let Some((c, why)) = why {
                    untraced = Some(push_unsupported(out, li, c, why));
                    // (kept as written, the offsets it sets on the axes it names are the
                    // machine's from here: the program's numbers no longer tell where they are)
                    if !polar_used {
                        let mut off = st.off;
                        for (k, o) in off.iter_mut().enumerate() {
                            if named & (1 << k) != 0 {
                                *o = f64::NAN;
                            }
                        }
                        set_offsets(out, st, off);
                    }
                }
            }
            if st.inch {
                out.summary.inch_lines += 1;
            } else {
                out.summary.mm_lines += 1;
            }
            // (axis words of G28/G30, G53, G10/G92 or G43.1 are no move in a work system)
            if st.wcs_moves.is_none()
                && (named != 0 || motion_word.is_some())
                && home.is_none()
                && nonmodal_axis_user.is_none()
                && frame_code.is_none()
                && tool_length != Some(431)
                && !g53
            {
                st.wcs_moves = Some(st.wcs);
            }
            if let Some((m, mc)) = motion_word {
                if let Mode::Canned(c) = m {
                    if st.mode != m {
                        st.box_xz = [f64::NAN; 2];
                        st.box_taper = false;
                    }
                    // cycles the engine does not follow stay reported until G80 (a Fanuc
                    // lathe's G90/G92/G94, which run only with axis words, where a block runs one)
                    if lathe_modal_cycle(st.dialect, c) {
                        st.active.canned = None;
                    } else if let Some(why) = cycle_refused(st.dialect, c) {
                        let idx = push_unsupported(out, li, mc, &why);
                        st.active.canned = Some((li as u32, idx));
                    } else {
                        st.active.canned = None;
                    }
                } else {
                    st.active.canned = None;
                    st.box_xz = [f64::NAN; 2];
                    st.box_taper = false;
                    // any other motion ends the cycles' initial level and sticky words
                    st.cyc.level = None;
                    st.cyc.last = 0;
                    // after cycles in a retract mode the controller chose, the height is its
                    if std::mem::take(&mut st.cyc.unknown_run) {
                        st.pos[2] = f64::NAN;
                    }
                }
                st.mode = m;
                st.sync = sync_word;
                match m {
                    Mode::Motion(mo) => st.g01 = Some(mo),
                    // (of group 01 itself: no G0/G1/G2/G3 is in force after them)
                    Mode::Canned(c) if lathe_modal_cycle(st.dialect, c) => st.g01 = None,
                    // on a Fanuc control G80 cancels the cycles' group 09 only: the motion of group
                    // 01 in force before them is again
                    Mode::None if st.dialect.is_fanuc() => {
                        st.mode = st.g01.map_or(Mode::None, Mode::Motion);
                    }
                    _ => {}
                }
            }
            // words no code of the block uses are an error, as in LinuxCNC (its check_other_codes):
            // on a Fanuc control R, I, K on a G1 round or chamfer the corner, which a split move
            // would put in the wrong place
            // a Haas lathe's taper on a G90 (I) or G94 (K): a taper like Fanuc's R
            if st.dialect == Dialect::FanucLathe
                && matches!(
                    motion_word.map_or(st.mode, |(m, _)| m),
                    Mode::Canned(900 | 940)
                )
                && (ijk[0].is_some() || ijk[2].is_some())
                && (named != 0 || motion_word.is_some())
            {
                st.box_taper = true;
                seen &= !((1 << (b'I' - b'A')) | (1 << (b'K' - b'A')));
            }
            if lathe_cut.is_some() {
                // (their depths, increments, taper, clearance and angles)
                seen &= !CHECKED_WORDS;
            }
            // a control point of LinuxCNC's NURBS (G5.2 … G5.3, not followed): its X Y P are the
            // NURBS's, the motion the control's
            if let (Some(idx), 0) = (st.nurbs_open, ng) {
                untraced = Some(idx);
            }
            let sync_block = motion_word.map_or(st.sync, |_| sync_word);
            if sync_block && motion_word.is_none() {
                seen &= !(1 << (b'K' - b'A')); // (a G33's pitch, on each of its blocks)
            }
            if untraced.is_none() && unknown_m.is_none() && seen & CHECKED_WORDS != 0 {
                let to_be = match motion_word {
                    Some((m, _)) => Some(m),
                    // axis words for the modal motion, or centre words alone for a modal arc (a
                    // full circle)
                    None if (named != 0
                        || (ijk.iter().any(|v| v.is_some())
                            && matches!(st.mode, Mode::Motion(m) if m.is_arc())))
                        && nonmodal_axis_user.is_none()
                        && home.is_none() =>
                    {
                        Some(st.mode)
                    }
                    None => None,
                };
                let (mut gcodes, mut mcodes) = ([0i32; 32], [0i32; 8]);
                for (c, g) in gcodes.iter_mut().zip(&gs[..ng]) {
                    *c = g.0;
                }
                for (c, m) in mcodes.iter_mut().zip(&ms[..nm]) {
                    *c = m.0;
                }
                if let Some((letter, users)) =
                    unused_word(seen, to_be, &gcodes[..ng], &mcodes[..nm])
                {
                    return Err(ierr(
                        li,
                        wcol[(letter - b'A') as usize],
                        format!("{} word with no {users} to use it", letter as char),
                    ));
                }
            }
            // a G code the engine does not know may change the motion mode too; for an unknown M code,
            // what it does with the machine, and with the block's axis words, is not known
            if let Some(idx) = untraced.or(unknown_m) {
                st.pos = [f64::NAN; NAXES];
                if untraced.is_some() {
                    st.mode = Mode::None;
                }
                push_record(out, st, li, Motion::Other, false, named, [0.0; 2], 1);
                out.unsupported[idx].blocks += 1;
                if ms[..nm].iter().any(|&(m, _)| m == 2 || m == 30) {
                    out.summary.end_line = Some(li as u32);
                    break;
                }
                continue;
            }

            let unit = if st.inch { MM_PER_INCH } else { 1.0 };
            if let Some((c, gc)) = comp_code {
                comp_on(out, st, li, c, gc, d_word, l_word, unit)?;
            }
            if let Some(c) = tool_length {
                // the lengths in force (mm) after the code: G43.1 its words (others 0), G49 none,
                // G43/G43.2 the tool table's along Z, which the program does not tell (a table's
                // X and Y offsets, a lathe's, are not followed)
                let new = match c {
                    431 => {
                        let mut t = [0.0; NAXES];
                        for (k, v) in axis.iter().enumerate() {
                            if let Some(v) = v {
                                t[k] = v * axis_unit(k, unit);
                            }
                        }
                        t
                    }
                    490 => [0.0; NAXES],
                    _ => UNKNOWN_LENGTH,
                };
                // the tip's coordinates where the tool stands (NaN where a length is unknown)
                for ((p, old), now) in st.pos.iter_mut().zip(st.tlo).zip(new) {
                    *p += old - now;
                }
                st.tlo = new;
                if c == 431 {
                    // its axis words are the lengths, not a move
                    if ms[..nm].iter().any(|&(m, _)| m == 2 || m == 30) {
                        out.summary.end_line = Some(li as u32);
                        break;
                    }
                    continue;
                }
            }
            if polar_used {
                let why = if !st.dialect.is_linuxcnc() {
                    Some("polar coordinates (@ ^), LinuxCNC's: not read in this dialect")
                } else if home.is_some()
                    || g53
                    || nonmodal_axis_user.is_some()
                    || frame_code.is_some()
                {
                    Some("polar coordinates (@ ^) with G28, G30, G53, G10, G52 or G92")
                } else {
                    None
                };
                if let Some(why) = why {
                    let idx = push_unsupported(out, li, polar_col, why);
                    out.unsupported[idx].blocks += 1;
                    st.pos = [f64::NAN; NAXES];
                    push_record(out, st, li, Motion::Other, false, named, [0.0; 2], 1);
                    continue;
                }
                // as LinuxCNC: in the XY plane whatever the plane (rs274 -g of a G18 move with
                // polar words), and an increment not from the origin
                let (cx, cy) = (
                    (st.pos[0] - st.off[0]) / unit,
                    (st.pos[1] - st.off[1]) / unit,
                );
                if st.incremental && cx == 0.0 && cy == 0.0 {
                    return Err(ierr(li, polar_col, POLAR_AT_ORIGIN));
                }
                let [x, y] = polar_xy([cx, cy], polar, st.incremental);
                if st.incremental {
                    axis[0] = Some(x - cx);
                    axis[1] = Some(y - cy);
                } else {
                    axis[0] = Some(x);
                    axis[1] = Some(y);
                }
            }
            // an arc with centre words and no axis words is a full circle back to its start
            let full_circle = named == 0
                && matches!(st.mode, Mode::Motion(m) if m.is_arc())
                && ijk.iter().any(|v| v.is_some());
            // G0 or G1 written without axis words is a move to where the tool is (LinuxCNC traces it)
            let standing = named == 0
                && matches!(
                    motion_word,
                    Some((Mode::Motion(Motion::Rapid | Motion::Feed), _))
                );
            if named == 0 {
                if let Some((Mode::Motion(m), gc)) =
                    motion_word.filter(|_| st.dialect.is_linuxcnc())
                {
                    // (a spline's I J P Q go with its G5 or G5.1, on every block, as rs274 reads them)
                    if m.is_spline() {
                        return Err(ierr(li, gc, "All axes missing with motion code (as rs274)"));
                    }
                }
            }
            if named == 0 && !full_circle && r.is_none() {
                if let Some((Mode::Motion(m), gc)) = motion_word {
                    if m.is_arc() {
                        return Err(ierr(
                            li,
                            gc,
                            "arc with no axis words and no I/J/K or R words",
                        ));
                    }
                }
            }
            let any_axis = named != 0 || full_circle || standing;
            // under compensation (or before the move that ends it) only G0-G3 moves are followed
            // (a lathe's nose radius compensation: its contour cycles too)
            if (st.comp.is_some()
                || st.comp_exit.is_some()
                || (st.nose.is_some() && !st.dialect.lathe()))
                && (frame_code.is_some()
                    || nonmodal_axis_user.is_some()
                    || home.is_some()
                    || g53
                    || polar_used
                    || (any_axis && matches!(st.mode, Mode::Canned(_) | Mode::Probe | Mode::None)))
            {
                let idx = push_unsupported(
                    out,
                    li,
                    axis_col,
                    "a move other than G0, G1, G2 or G3 (a canned cycle, probing, G10, G28, G30, G52, G53, G92, polar coordinates) with cutter compensation on: not treated",
                );
                st.comp = None;
                st.comp_exit = None;
                st.nose = None;
                st.nose_edge = false;
                st.active.cutter_comp = Some((li as u32, idx));
            }

            // Fanuc's coordinate rotation: its X Y the centre (the tool's position where left
            // out), R the angle; moves after it are turned about the centre
            if let Some(gc) = rot_word {
                let why = if st.rot.is_some() || st.active.rotation.is_some() {
                    Some("G68 while a rotation is in force")
                } else if ijk.iter().any(|v| v.is_some()) {
                    Some("G68 with I, J or K: a three-dimensional coordinate conversion (the axis I J K gives), not followed")
                } else if line.block_delete {
                    Some("G68 on a block-delete line (/): whether it runs is the machine's switch")
                } else if st.plane != 0 {
                    Some("coordinate rotation G68 outside the XY plane (G17)")
                } else if r.is_none() {
                    Some("G68 without R: the angle is then the control's setting (parameter 5410)")
                } else if st.incremental {
                    Some("G68 under G91: whether its R and centre are increments is the control's setting (parameter 5400 RIN)")
                } else if named & !0b11 != 0
                    || motion_word.is_some()
                    || frame_code.is_some()
                    || home.is_some()
                    || nonmodal_axis_user.is_some()
                    || comp_code.is_some()
                    || st.comp.is_some()
                    || st.active.cutter_comp.is_some()
                    || st.active.polar.is_some()
                    || st.active.scaling.is_some()
                {
                    Some("G68 with other axis words, a motion, offsets or compensation in the block or in force")
                } else {
                    None
                };
                // (without X Y the centre is where the tool stands, which the correction moves:
                // the output would turn about another point)
                let why = why.or_else(|| {
                    (named & 0b11 != 0b11).then_some("G68 without X and Y turns about where the tool stands, which the correction moves (the output would turn about another point); give the centre, X and Y")
                });
                let c = [0, 1].map(|k| axis[k].map_or(f64::NAN, |v| v * unit + st.off[k]));
                if let Some(why) = why {
                    let idx = push_unsupported(out, li, gc, why);
                    st.active.rotation = Some((li as u32, idx));
                } else {
                    let (sin, cos) = r.unwrap().0.to_radians().sin_cos();
                    st.rot = Some(Rotation { cos, sin, c });
                    st.rot_idx = None;
                    st.rot_first = true;
                    st.prog_xy = [f64::NAN; 2];
                }
                if ms[..nm].iter().any(|&(m, _)| m == 2 || m == 30) {
                    out.summary.end_line = Some(li as u32);
                    break;
                }
                continue;
            }
            // under a rotation the engine follows moves (G0-G3 in G17) alone
            if st.rot.is_some()
                && st.active.rotation.is_none()
                && (frame_code.is_some()
                    || nonmodal_axis_user.is_some()
                    || home.is_some()
                    || g53
                    || polar_used
                    || comp_code.is_some()
                    || st.comp.is_some()
                    || st.nose.is_some()
                    || st.arc_absolute
                    || plane_word
                    || (any_axis && !matches!(st.mode, Mode::Motion(_)))
                    || (any_axis
                        && st.plane != 0
                        && matches!(st.mode, Mode::Motion(m) if m.is_arc())))
            {
                let idx = push_unsupported(
                    out,
                    li,
                    axis_col.max(1),
                    "under a coordinate rotation (G68) only moves G0-G3 are followed (arcs in G17): offsets, G28, G30, G53, canned cycles, probing, cutter compensation, absolute arc centres, a plane code (Fanuc: not to be given under G68) and arcs in G18/G19 are not",
                );
                st.active.rotation = Some((li as u32, idx));
            }

            // offsets: the program's coordinates move, the machine does not
            if let Some((c, gc)) = frame_code {
                if c == 920 && named == 0 {
                    return Err(ierr(li, gc, "G92 with no axis words"));
                }
                frame(out, st, c, &axis, unit);
                if matches!(c, 920 | 1020) && st.wcs_moves.is_some() {
                    out.frame_lines.push((li as u32, st.frame, st.inch));
                }
                if ms[..nm].iter().any(|&(m, _)| m == 2 || m == 30) {
                    out.summary.end_line = Some(li as u32);
                    break;
                }
                continue;
            }
            // non-modal codes that take the axis words
            if let Some((_c, idx)) = nonmodal_axis_user {
                if any_axis || matches!(_c, 280 | 300 | 281 | 301) {
                    st.pos = [f64::NAN; NAXES];
                    push_record(out, st, li, Motion::Other, false, named, [0.0; 2], 1);
                    out.unsupported[idx].blocks += 1;
                }
                continue;
            }
            // G28 / G30: a rapid to the intermediate point the axis words give (in program coordinates,
            // G90/G91 as set), then the axes named (every axis when none is) to the stored reference
            // position, a machine position the program does not know: two moves, as LinuxCNC's rs274
            if let Some((c, gc)) = home {
                if matches!(motion_word, Some((Mode::Motion(_) | Mode::Canned(_), _))) {
                    return Err(ierr(
                        li,
                        gc,
                        format!(
                            "{} and a motion code in one block both use the axis words",
                            g_name(c)
                        ),
                    ));
                }
                st.pos = target(&st.pos, &axis, st.incremental, unit, &st.off);
                push_record(out, st, li, Motion::Other, false, named, [0.0; 2], 1);
                for k in 0..NAXES {
                    if named == 0 || named & (1 << k) != 0 {
                        st.pos[k] = f64::NAN;
                    }
                }
                push_record(out, st, li, Motion::Other, false, named, [0.0; 2], 1);
                out.notes.push(Note {
                line: li as u32,
                message: format!(
                    "{} return to the stored reference position: kept as written, not corrected; the axes it moves are unknown afterwards",
                    g_name(c)
                ),
            });
                if ms[..nm].iter().any(|&(m, _)| m == 2 || m == 30) {
                    out.summary.end_line = Some(li as u32);
                    break;
                }
                continue;
            }
            if !any_axis {
                for &(m, _) in &ms[..nm] {
                    if m == 2 || m == 30 {
                        out.summary.end_line = Some(li as u32);
                    }
                }
                if out.summary.end_line.is_some() {
                    break;
                }
                continue;
            }

            // the target of the axis words
            let mut end = target(&st.pos, &axis, st.incremental && !g53, unit, &st.off);
            // after G68 or G69 the first move naming X or Y must give both, absolute; under a
            // rotation its programmed X Y are turned about the centre
            if named & 0b11 != 0 && !g53 && st.rot_first {
                if named & 0b11 != 0b11 || st.incremental {
                    if st.active.rotation.is_none() {
                        let idx = push_unsupported(out, li, axis_col, "the first move after G68 or G69 that names X or Y leaves one out or is incremental: which programmed coordinate the control takes across the change is its setting; give X and Y, absolute (G90)");
                        st.active.rotation = Some((li as u32, idx));
                    }
                    end[0] = f64::NAN;
                    end[1] = f64::NAN;
                } else {
                    st.rot_first = false;
                }
            }
            if let (Some(rot), false, true) = (st.rot, g53, named & 0b11 != 0) {
                // (the axis words' target from the programmed X Y, not where the tool is)
                let mut from = st.pos;
                (from[0], from[1]) = (st.prog_xy[0], st.prog_xy[1]);
                let t = target(&from, &axis, st.incremental, unit, &st.off);
                let p = [t[0], t[1]];
                if end[0].is_finite() || end[1].is_finite() {
                    let f = rot.to_frame(p);
                    end[0] = f[0];
                    end[1] = f[1];
                }
                st.prog_xy = p;
            }

            if g53 {
                if st.dialect.is_linuxcnc()
                    && !matches!(st.mode, Mode::Motion(Motion::Rapid | Motion::Feed))
                {
                    return Err(ierr(li, axis_col, "Must use G0 or G1 with G53 (as rs274)"));
                }
                let what = "G53 machine-coordinate move: kept as written, not corrected; the axes it moves are unknown afterwards";
                untraced_move(out, st, li, &axis, &mut end, named, what);
                continue;
            }

            let blocker = st.active.first();
            if let Some((c, gc)) = lathe_cut {
                let margin = match c {
                    // a Haas G76's I, Fanuc's R: the taper (radius); G74/G75: a Haas D, Fanuc's
                    // R, the clearance or relief at the bottom
                    760 => [ijk[0].or(r.map(|v| v.0)).unwrap_or(0.0).abs() * unit, 0.0],
                    _ => {
                        let m = d_word.or(r.map(|v| v.0)).unwrap_or(0.0).abs() * unit;
                        [m, m]
                    }
                };
                lathe_cut_block(
                    out,
                    st,
                    li,
                    c,
                    gc,
                    &end,
                    named,
                    margin,
                    blocker.or(e_construct),
                );
            } else {
                match st.mode {
                    Mode::Probe => {
                        let what = "G38 probing move: kept as written, not corrected; the axes it moves are unknown afterwards (it stops where the probe trips)";
                        untraced_move(out, st, li, &axis, &mut end, named, what);
                    }
                    Mode::None => {
                        // (a Fanuc-family control keeps group 01 across a canned cycle and G80)
                        let why = if st.g01.is_some() && st.dialect.is_linuxcnc() {
                            "axis words with no motion mode after G80 (RS274NGC); a Fanuc-family control keeps the G0 or G1 in force before the cycle: if the program was written for one, --dialect fanuc reads it so"
                        } else {
                            "axis words with no motion mode (G80 or none yet)"
                        };
                        let idx = push_unsupported(out, li, axis_col, why);
                        out.unsupported[idx].blocks += 1;
                        st.pos = [f64::NAN; NAXES];
                        push_record(out, st, li, Motion::Other, false, named, [0.0; 2], 1);
                    }
                    Mode::Canned(c) => {
                        // (LinuxCNC's G87 keeps its I J in the register a G5 reads)
                        if c == 870 {
                            st.spline_ij = None;
                        }
                        let words = CycleWords {
                            axis: &axis,
                            r,
                            q: q_word,
                            p,
                            l: l_word,
                            polar: polar_used.then_some(polar),
                            col: motion_word.map_or(axis_col, |(_, c)| c),
                            ijk,
                            e: e_value,
                        };
                        let mut blocked = blocker.or(e_construct);
                        if st.inverse_time && blocked.is_none() {
                            // rs274 stops there: "Cannot feed with zero feed rate"
                            let idx = push_unsupported(
                                out,
                                li,
                                words.col,
                                "canned cycle under inverse-time feed G93 (LinuxCNC refuses it)",
                            );
                            blocked = Some(idx);
                        }
                        canned(out, st, li, c, &words, blocked, unit)?;
                    }
                    Mode::Motion(m) => {
                        let mut center = [0.0; 2];
                        let mut turns = 1u32;
                        let gcol = motion_word.map_or(axis_col, |(_, c)| c);
                        let spline = if m.is_spline() {
                            spline_block(st, li, gcol, m, &end, named, ijk, p, q_word, unit, &wcol)?
                        } else {
                            None
                        };
                        let mut spline_blocker = None;
                        if m.is_spline()
                            && (st.comp_exit.is_some() || st.active.cutter_comp.is_some())
                        {
                            // after G40 LinuxCNC's current point is the tool's, which the spline
                            // would start from
                            let idx = push_unsupported(out, li, gcol, "a spline (G5, G5.1) right after cutter compensation, before the move that ends it: LinuxCNC starts it from the tool's offset point");
                            spline_blocker = Some(idx);
                        }
                        if m.is_spline() && spline.is_none() && spline_blocker.is_none() {
                            let idx = push_unsupported(out, li, gcol, "a G5 without I and J: its first control point comes from LinuxCNC's register (the last G5's P and Q, or G87's I and J), which the program has not set before it");
                            spline_blocker = Some(idx);
                        }
                        if m.is_arc() {
                            let [a1, a2, _] = PLANE_AXES[st.plane as usize];
                            let s = [st.pos[a1], st.pos[a2]];
                            let e = [end[a1], end[a2]];
                            // offsets by plane: XY uses I J, ZX uses K I, YZ uses J K
                            let (o1, o2) = match st.plane {
                                0 => (ijk[0], ijk[1]),
                                1 => (ijk[2], ijk[0]),
                                _ => (ijk[1], ijk[2]),
                            };
                            let gcol = motion_word.map_or(axis_col, |(_, c)| c);
                            if let Some(pv) = p {
                                if pv < 1.0 || pv.fract() != 0.0 {
                                    return Err(ierr(
                                        li,
                                        gcol,
                                        format!(
                                            "arc turns P must be a whole number >= 1, got {pv}"
                                        ),
                                    ));
                                }
                                turns = pv as u32;
                            }
                            if let Some((rv, rc)) = r {
                                if o1.is_some() || o2.is_some() {
                                    return Err(ierr(
                                        li,
                                        rc,
                                        "arc with both R and I/J/K; use one form",
                                    ));
                                }
                                let rr = rv * unit;
                                let dx = e[0] - s[0];
                                let dy = e[1] - s[1];
                                let d = (dx * dx + dy * dy).sqrt();
                                if d.is_nan() {
                                    center = [f64::NAN; 2];
                                } else {
                                    if d < 1e-9 {
                                        return Err(ierr(li, rc, "R-format arc with the same start and end point; use I/J/K for a full circle"));
                                    }
                                    let half = d / 2.0;
                                    let mut h2 = rr * rr - half * half;
                                    if h2 < 0.0 {
                                        if rr.abs() < half - ARC_ABS_TOL_MM {
                                            return Err(ierr(li, rc, format!("arc radius {} too small to reach the end point {:.4} away", rv.abs(), d / unit)));
                                        }
                                        h2 = 0.0;
                                    }
                                    let h = h2.sqrt();
                                    let (ux, uy) = (dx / d, dy / d);
                                    let mid = [(s[0] + e[0]) / 2.0, (s[1] + e[1]) / 2.0];
                                    // clockwise minor arcs have their centre to the right of the chord
                                    let right = (m == Motion::ArcCw) == (rr > 0.0);
                                    let (px, py) = if right { (uy, -ux) } else { (-uy, ux) };
                                    center = [mid[0] + h * px, mid[1] + h * py];
                                }
                            } else {
                                if o1.is_none() && o2.is_none() {
                                    return Err(ierr(
                                    li,
                                    gcol,
                                    "arc needs I/J/K (centre) or R (radius) words for its plane",
                                ));
                                }
                                let scale = unit;
                                if st.arc_absolute {
                                    let [a1, a2, _] = PLANE_AXES[st.plane as usize];
                                    center = [
                                        o1.unwrap_or(0.0) * scale + st.off[a1],
                                        o2.unwrap_or(0.0) * scale + st.off[a2],
                                    ];
                                } else {
                                    let mut o = [o1.unwrap_or(0.0), o2.unwrap_or(0.0)];
                                    if let (Some(rot), 0) = (st.rot, st.plane) {
                                        // (offsets in the programmed frame, turned with it)
                                        o = [
                                            rot.cos * o[0] - rot.sin * o[1],
                                            rot.sin * o[0] + rot.cos * o[1],
                                        ];
                                    }
                                    center = [s[0] + o[0] * scale, s[1] + o[1] * scale];
                                }
                                let r1 = ((s[0] - center[0]).powi(2) + (s[1] - center[1]).powi(2))
                                    .sqrt();
                                let r2 = ((e[0] - center[0]).powi(2) + (e[1] - center[1]).powi(2))
                                    .sqrt();
                                let abs_err = (r1 - r2).abs() / unit;
                                let spiral = if st.inch {
                                    SPIRAL_ABS_TOL_INCH
                                } else {
                                    SPIRAL_ABS_TOL_MM
                                };
                                if abs_err > 100.0 * spiral
                                    || (abs_err > spiral
                                        && abs_err * unit / r1.max(r2) > SPIRAL_REL_TOL)
                                {
                                    return Err(ierr(li, gcol, format!(
                                "radius to the end of the arc ({:.4}) differs from radius to its start ({:.4})",
                                r2 / unit, r1 / unit)));
                                }
                                if r1 < ARC_MIN_RADIUS_MM || r2 < ARC_MIN_RADIUS_MM {
                                    return Err(ierr(li, gcol, "arc with zero radius"));
                                }
                            }
                        }
                        // correctable when every axis it moves has a known end (a straight move from an
                        // unknown start is corrected at its end only); arcs need their centre
                        // an arc, and an axis other than XYZ that the block moves, needs its start too: their
                        // pieces are interpolated from it (a move is never changed in kind from an unknown start)
                        let finite = |p: &[f64; NAXES], axes: u16| {
                            let mut bits = axes;
                            let mut ok = true;
                            while bits != 0 {
                                ok &= p[bits.trailing_zeros() as usize].is_finite();
                                bits &= bits - 1;
                            }
                            ok
                        };
                        if st.sync && ijk[2].is_none() {
                            return Err(ierr(
                                li,
                                motion_word.map_or(axis_col, |(_, c)| c),
                                "K word missing with G33 (the pitch, on each of its blocks), as rs274 refuses it",
                            ));
                        }
                        let known = finite(&end, 0b111 | named)
                            && center[0].is_finite()
                            && center[1].is_finite()
                            && (!m.is_curve() || finite(&st.pos, 0b111))
                            && finite(&st.pos, named & !0b111);
                        // LinuxCNC's absolute arc centre (G90.1) in diameter mode: not followed
                        let blocker = blocker.or_else(|| {
                        let why = if st.sync
                            && (st.comp.is_some()
                                || st.nose.is_some()
                                || st.active.cutter_comp.is_some())
                        {
                            Some("spindle-synchronised motion G33 under cutter compensation (LinuxCNC refuses it)")
                        } else if st.sync && st.inverse_time {
                            Some("spindle-synchronised motion G33 under inverse-time feed G93")
                        } else if !m.is_arc() {
                            None
                        } else if st.arc_absolute && st.diameter {
                            Some("an arc with an absolute centre (G90.1) in lathe diameter mode")
                        } else if !st.plane_known {
                            Some("an arc before the program states its plane: on a LinuxCNC lathe the plane a program starts in is the machine's start-up setting (write G18)")
                        } else if st.dialect.lathe() && st.plane != 1 {
                            Some("an arc outside the ZX plane (G18) on a lathe, which has no Y axis")
                        } else {
                            None
                        };
                        why.map(|why| {
                            push_unsupported(out, li, motion_word.map_or(axis_col, |(_, c)| c), why)
                        })
                    });
                        let blocker = blocker.or(spline_blocker);
                        let mut supported = blocker.is_none() && e_construct.is_none();
                        if let Some(idx) = blocker {
                            out.unsupported[idx].blocks += 1;
                        }
                        if let Some(idx) = e_construct {
                            out.unsupported[idx].blocks += 1;
                        }
                        let comp = match comp_move(
                            st,
                            m,
                            &st.pos.clone(),
                            &end,
                            center,
                            named & 0b11 != 0,
                        )
                        .and_then(|c| match c {
                            // (LinuxCNC's entry arc takes all its P turns: not followed)
                            Some(c) if c.entry.is_some() && turns > 1 => Err(
                                "an arc of more than one turn (P) that starts cutter compensation: not followed",
                            ),
                            c => Ok(c),
                        }) {
                            Ok(c) => c,
                            Err(why) => {
                                let idx = push_unsupported(out, li, axis_col, why);
                                out.unsupported[idx].blocks += 1;
                                st.comp = None;
                                st.comp_exit = None;
                                st.active.cutter_comp = Some((li as u32, idx));
                                supported = false;
                                None
                            }
                        };
                        let nose_corner = match nose_turn(st, m, &end, center) {
                            Ok(f) => f,
                            Err(why) => {
                                let idx = push_unsupported(out, li, axis_col, why);
                                out.unsupported[idx].blocks += 1;
                                st.nose = None;
                                st.nose_edge = false;
                                st.active.cutter_comp = Some((li as u32, idx));
                                supported = false;
                                (1.0, 0.0)
                            }
                        };
                        if st.inverse_time && m != Motion::Rapid {
                            let gcol = motion_word.map_or(axis_col, |(_, c)| c);
                            let f = words.iter().find(|w| w.letter == b'F').map(|w| w.value);
                            match f {
                                None => {
                                    let g = match m {
                                        Motion::ArcCw => "G2",
                                        Motion::ArcCcw => "G3",
                                        Motion::Spline => "G5",
                                        Motion::QSpline => "G5.1",
                                        _ => "G1",
                                    };
                                    return Err(ierr(
                                    li,
                                    gcol,
                                    format!(
                                        "F word missing with inverse time {g} move (G93: every G1, G2, G3 gives its time)"
                                    ),
                                ));
                                }
                                Some(v) if !(v > 0.0 && v.is_finite()) => {
                                    return Err(ierr(
                                        li,
                                        wcol[(b'F' - b'A') as usize],
                                        format!("inverse-time feed F{v}: it must be above 0"),
                                    ))
                                }
                                _ => {}
                            }
                        }
                        let leaves = st.comp_unfollowed_exit
                            && (m.is_arc()
                                || (end[0] - st.pos[0]).hypot(end[1] - st.pos[1]) > 1e-9);
                        // the move that ends compensation in G18/G19 is the next; the one that starts
                        // it LinuxCNC's next (which must go further than the radius in the plane, as
                        // rs274 checks), a Fanuc control's next in the plane (a position not known
                        // counts as moving)
                        let mut nose_edge = st.nose_edge;
                        if let (true, Some(r)) = (nose_edge, st.nose) {
                            let (a, b) = if st.plane == 2 { (1, 2) } else { (0, 2) };
                            let along = (end[a] - st.pos[a]).hypot(end[b] - st.pos[b]);
                            // (LinuxCNC compensates nothing with a radius of 0)
                            if st.dialect.is_linuxcnc() && !m.is_arc() && r > 0.0 && along <= r {
                                return Err(ierr(
                                li,
                                axis_col,
                                "the move that starts cutter compensation is not longer than the tool radius in its plane (LinuxCNC refuses it)",
                            ));
                            }
                            nose_edge = m.is_arc() || !(along <= 1e-9);
                        }
                        if nose_edge {
                            st.nose_edge = false;
                        }
                        st.pos = end;
                        push_record(out, st, li, m, supported && known, named, center, turns);
                        out.records.last_mut().unwrap().whole =
                            if std::mem::take(&mut st.contour_edge) {
                                WHOLE_CONTOUR
                            } else if st.sync {
                                WHOLE_SYNC
                            } else if nose_edge {
                                WHOLE_NOSE
                            } else {
                                0
                            };
                        if leaves {
                            st.comp_unfollowed_exit = false;
                            st.active.cutter_comp = None;
                        }
                        if let Some(c) = comp {
                            out.records.last_mut().unwrap().comp = out.comps.len() as u32;
                            out.comps.push(c);
                        }
                        if m.is_spline() {
                            // (a G5 without I J whose register is not known: control points
                            // unknown, continued all the same)
                            let (ctrl, continued) = spline.unwrap_or(([[f64::NAN; 2]; 2], true));
                            out.splines.push(Spline {
                                rec: (out.records.len() - 1) as u32,
                                ctrl,
                                continued,
                            });
                        }
                        if nose_corner.0 > 1.0 {
                            out.nose_corners.push((
                                (out.records.len() - 1) as u32,
                                nose_corner.0,
                                nose_corner.1,
                            ));
                        }
                        let s = &mut out.summary;
                        s.counts[m as usize] += 1;
                        if m.is_arc() {
                            s.planes[st.plane as usize] += 1;
                        }
                    }
                }
            }
            for &(m, _) in &ms[..nm] {
                if m == 2 || m == 30 {
                    out.summary.end_line = Some(li as u32);
                }
            }
            if out.summary.end_line.is_some() {
                break;
            }
        }
        Ok(())
    }
}

/// Modal group of a G code (code × 10) as LinuxCNC groups them; None for codes the engine does
/// not know (those are reported on their own).
fn g_group(c: i32) -> Option<u8> {
    Some(match c {
        0 | 10 | 20 | 30 | 50 | 51 | 52 | 330 | 331 | 382..=385 | 730 | 740 | 760 | 800..=890 => 1,
        170 | 180 | 190 | 171 | 181 | 191 => 2,
        900 | 910 => 3,
        901 | 911 => 4,
        930 | 940 | 950 => 5,
        200 | 210 => 6,
        400 | 410 | 411 | 420 | 421 => 7,
        430 | 431 | 432 | 490 => 8,
        980 | 990 => 10,
        540 | 550 | 560 | 570 | 580 | 590 | 591 | 592 | 593 | 541 | 1540 => 12,
        610 | 611 | 640 => 13,
        960 | 970 => 14,
        70 | 80 => 15,
        40 | 100 | 280 | 281 | 300 | 301 | 520 | 530 | 920 | 921 | 922 | 923 => 0,
        // other dialects' modal codes the engine reports
        500 | 510 => 16,
        680 | 690 => 17,
        150 | 160 => 18,
        _ => return None,
    })
}

/// The index of an axis letter in [`AXES`].
#[inline]
pub fn axis_index(letter: u8) -> Option<usize> {
    match letter {
        b'X' => Some(0),
        b'Y' => Some(1),
        b'Z' => Some(2),
        b'A' => Some(3),
        b'B' => Some(4),
        b'C' => Some(5),
        b'U' => Some(6),
        b'V' => Some(7),
        b'W' => Some(8),
        _ => None,
    }
}

/// The words [`unused_word`] checks (a bit per letter): I J K R P Q L H D.
const CHECKED_WORDS: u32 = {
    let mut m = 0u32;
    let letters = *b"IJKRPQLHD";
    let mut i = 0;
    while i < letters.len() {
        m |= 1 << (letters[i] - b'A');
        i += 1;
    }
    m
};

/// The first of the words I J K R P Q L H D in `seen` (a bit per letter) that no code of the block
/// uses, with the codes that would, as LinuxCNC 2.9 checks them (interp_check.cc). `to_be` is the
/// motion the block runs: its own motion code, or the modal one when it has axis words for it.
fn unused_word(
    seen: u32,
    to_be: Option<Mode>,
    gs: &[i32],
    ms: &[i32],
) -> Option<(u8, &'static str)> {
    let has = |l: u8| seen & (1 << (l - b'A')) != 0;
    let g = |c: i32| gs.contains(&c);
    let m = |f: fn(i32) -> bool| ms.iter().any(|&c| f(c));
    let arc = matches!(to_be, Some(Mode::Motion(Motion::ArcCw | Motion::ArcCcw)));
    let cycle = |cs: &[i32]| matches!(to_be, Some(Mode::Canned(c)) if cs.contains(&c));
    let any_cycle = matches!(to_be, Some(Mode::Canned(_)));
    // codes the engine refuses anyway (splines, threading, G10, rotation G68, scaling G51) use
    // these words too
    // (a spline's I J P Q with its G5 or G5.1 in the block, as rs274 reads them)
    let spline = g(50) || g(51);
    let other = [52, 330, 331, 760, 100, 680, 510, 1870, 541, 1540]
        .iter()
        .any(|&c| g(c));
    let user_m = m(|c| (100..=199).contains(&c));
    let rules: [(u8, bool, &'static str); 9] = [
        (
            b'I',
            arc || spline || cycle(&[760, 870]) || other,
            "G2, G3, G76 or G87",
        ),
        (
            b'J',
            arc || spline || cycle(&[760, 870]) || other,
            "G2, G3, G76 or G87",
        ),
        (
            b'K',
            arc || cycle(&[760, 870]) || other,
            "G2, G3, G76 or G87",
        ),
        (
            b'R',
            arc || any_cycle || other || m(|c| c == 19),
            "G2, G3, canned cycle or G10",
        ),
        (
            b'P',
            // (a P on any canned cycle is kept: Fanuc controls ignore it where the cycle has no dwell)
            arc || spline
                || any_cycle
                || g(40)
                || g(640)
                || other
                || user_m
                || m(|c| (50..=53).contains(&c) || (62..=66).contains(&c) || c == 98 || c == 19),
            "G2, G3, G4, G64, dwell cycle or M code",
        ),
        (
            b'Q',
            cycle(&[730, 760, 830])
                || spline
                || g(640)
                || other
                || user_m
                || m(|c| matches!(c, 19 | 61 | 66..=68)),
            "G64, G73, G83 or M code",
        ),
        (
            b'L',
            any_cycle || g(411) || g(421) || other || m(|c| c == 66 || c == 98),
            "canned cycle, G10 or M code",
        ),
        (
            b'H',
            g(430) || g(432) || cycle(&[760]) || other,
            "G43 or G76",
        ),
        (
            b'D',
            g(410) || g(411) || g(420) || g(421) || g(960) || other,
            "G41, G42 or G96",
        ),
    ];
    rules
        .iter()
        .find(|&&(l, used, _)| has(l) && !used)
        .map(|&(l, _, users)| (l, users))
}

/// M codes of Haas controls (Fanuc dialect) that switch auxiliary equipment and move no axis,
/// from the Haas mill and lathe operator's manuals' M-code lists: chip auger forward and stop
/// (M31, M33), coolant spigot position (M34, M35), air gun on/off (M83, M84), through-spindle
/// coolant on/off (M88, M89). Copied as written.
const HAAS_AUXILIARY_M: [i32; 8] = [31, 33, 34, 35, 83, 84, 88, 89];

/// M codes of a Haas lathe that set how its threading cycles (G76, G92) end and move no axis
/// (the lathe operator's manual: M23 chamfer out of thread on, M24 off). Copied as written.
const HAAS_LATHE_M: [i32; 2] = [23, 24];

/// An M code outside RS274NGC's that the dialect's controls use for equipment moving no axis.
fn copied_m(d: Dialect, m: i32) -> bool {
    (d.is_fanuc() && HAAS_AUXILIARY_M.contains(&m))
        || (d == Dialect::FanucLathe && HAAS_LATHE_M.contains(&m))
}

/// Modal group of an M code as LinuxCNC groups them; None for codes the engine does not know.
fn m_group(m: i32) -> Option<u8> {
    Some(match m {
        0 | 1 | 2 | 30 | 60 => 4,
        3..=5 => 7,
        7..=9 => 8,
        48..=53 => 9,
        6 | 61 => 6,
        19 => 11,
        62..=68 => 5,
        70..=73 => 12,
        100..=199 => 10,
        _ => return None,
    })
}

/// An unsupported construct reported once, its blocks counted over the program.
fn grouped_unsupported(
    out: &mut Interp,
    grouped: &mut Vec<(String, usize)>,
    li: usize,
    col: usize,
    construct: &str,
) -> usize {
    if let Some((_, idx)) = grouped.iter().find(|(c, _)| c == construct) {
        return *idx;
    }
    let idx = push_unsupported(out, li, col, construct);
    grouped.push((construct.to_string(), idx));
    idx
}

fn push_unsupported(out: &mut Interp, li: usize, col: usize, construct: &str) -> usize {
    out.unsupported.push(Unsupported {
        line: li as u32,
        col: col as u32,
        construct: construct.to_string(),
        blocks: 0,
    });
    out.unsupported.len() - 1
}

/// A lathe's axis words: U and W of a Fanuc lathe are increments of X and Z (read into `axis` as
/// the absolute X and Z they reach); a diameter X (LinuxCNC's G7, a Fanuc lathe) is halved into
/// the radius. A Y word on a lathe (the engine takes the tool in the plane through the spindle's
/// axis), and on a Fanuc lathe V, A, B or C (a C axis, or a chamfer by parameter), are refused:
/// the construct is returned.
fn lathe_words(
    out: &mut Interp,
    grouped: &mut Vec<(String, usize)>,
    st: &State,
    li: usize,
    axis: &mut [Option<f64>; NAXES],
    named: &mut u16,
    wcol: &[usize; 26],
) -> Result<Option<usize>, NcError> {
    let fanuc = st.dialect == Dialect::FanucLathe;
    if st.dialect.lathe() {
        let refused: &[u8] = if fanuc { b"YVABC" } else { b"Y" };
        if let Some(&l) = refused
            .iter()
            .find(|&&l| axis[axis_index(l).unwrap()].is_some())
        {
            let why = if l == b'Y' || l == b'V' {
                format!("{} word on a lathe: the engine takes the tool in the plane through the spindle's axis (Y 0); if the program is a mill's, say so (--machine mill)", l as char)
            } else {
                format!("{} word on a Fanuc lathe: a rotary axis, or a chamfer (parameter 3405#4 CCR), which the program does not tell", l as char)
            };
            return Ok(Some(grouped_unsupported(
                out,
                grouped,
                li,
                wcol[(l - b'A') as usize],
                &why,
            )));
        }
    }
    if !st.diameter_known && axis[0].is_some() {
        return Ok(Some(grouped_unsupported(
            out,
            grouped,
            li,
            wcol[(b'X' - b'A') as usize],
            "X before G7 or G8 on a LinuxCNC lathe: whether X is a diameter is the machine's start-up setting (RS274NGC_STARTUP_CODE), which the program does not tell",
        )));
    }
    let unit = if st.inch { MM_PER_INCH } else { 1.0 };
    let dia = if st.diameter { 2.0 } else { 1.0 };
    if fanuc {
        for (inc, abs, scale) in [(6usize, 0usize, dia), (8, 2, 1.0)] {
            let Some(v) = axis[inc] else { continue };
            if axis[abs].is_some() {
                return Err(ierr(
                    li,
                    wcol[(AXES[inc] - b'A') as usize],
                    format!(
                        "{} and {} in one block (an increment and an absolute value of one axis)",
                        AXES[abs] as char, AXES[inc] as char
                    ),
                ));
            }
            // the word the axis stands at, in the program's numbers (NaN where unknown)
            let here = (st.pos[abs] - st.off[abs]) / unit * scale;
            axis[abs] = Some(here + v);
            axis[inc] = None;
            *named = (*named & !(1 << inc)) | (1 << abs);
        }
    }
    if st.diameter {
        if let Some(v) = axis[0] {
            axis[0] = Some(v / 2.0);
        }
    }
    Ok(None)
}

#[allow(clippy::too_many_arguments)]
/// Where the axis words of a block take the axes from `pos`: lengths scaled by `unit` (mm per
/// program unit), rotary words in degrees; added to `pos` when incremental.
fn target(
    pos: &[f64; NAXES],
    axis: &[Option<f64>; NAXES],
    incremental: bool,
    unit: f64,
    off: &[f64; NAXES],
) -> [f64; NAXES] {
    let mut end = *pos;
    for (k, (e, w)) in end.iter_mut().zip(axis).enumerate() {
        if let Some(v) = w {
            *e = if incremental {
                pos[k] + v * axis_unit(k, unit)
            } else {
                v * axis_unit(k, unit) + off[k]
            };
        }
    }
    end
}

/// Millimetres (or degrees) per program unit on axis k (A, B, C are in degrees in either unit).
#[inline]
pub fn axis_unit(k: usize, unit: f64) -> f64 {
    if (3..6).contains(&k) {
        1.0
    } else {
        unit
    }
}

/// LinuxCNC's refusal of an incremental polar step from the origin (its angle is not defined).
const POLAR_AT_ORIGIN: &str =
    "incremental polar coordinates (@ ^) from the origin: the angle to step from is not defined (LinuxCNC refuses them)";

/// Where LinuxCNC's polar words take X and Y (program units), from the current point `cur` in
/// program units: about the program's origin, `polar` the distance `@` and the angle `^`
/// (degrees); a word left out keeps the current point's, and in G91 each word adds to it.
pub fn polar_xy(cur: [f64; 2], polar: [Option<f64>; 2], incremental: bool) -> [f64; 2] {
    let (r0, a0) = (cur[0].hypot(cur[1]), cur[1].atan2(cur[0]).to_degrees());
    let (r, a) = if incremental {
        (r0 + polar[0].unwrap_or(0.0), a0 + polar[1].unwrap_or(0.0))
    } else {
        (polar[0].unwrap_or(r0), polar[1].unwrap_or(a0))
    };
    [r * a.to_radians().cos(), r * a.to_radians().sin()]
}

/// Extended work systems (Fanuc G54.1 P n, Haas G154 P n) are this plus n in the work system
/// codes (G54 … G59.3 are 540 … 593).
pub const EXTENDED_WCS: i32 = 10000;

/// A work system's name: G54 … G59.3, or G54.1 P n for an extended one.
pub fn wcs_name(c: i32) -> String {
    if c >= EXTENDED_WCS {
        format!("G54.1 P{}", c - EXTENDED_WCS)
    } else {
        g_name(c)
    }
}

/// A change of work system (code `c`: 540 … 593, or [`EXTENDED_WCS`] + n).
fn set_wcs(out: &mut Interp, st: &mut State, li: usize, gc: usize, c: i32) {
    let o = c as u16;
    if !out.summary.work_offsets.contains(&o) {
        out.summary.work_offsets.push(o);
    }
    if c != st.wcs {
        // the tool stays where it is; its coordinates in the new system depend
        // on offsets the program does not know
        st.pos = [f64::NAN; NAXES];
    }
    st.wcs = c;
    // a field is measured in one work system's coordinates: moves in another
    // (a second fixture, a second part) are elsewhere on the machine
    match st.wcs_moves {
        Some(first) if first == c => st.active.wcs = None,
        Some(first) if st.active.wcs.is_none() => {
            let idx = push_unsupported(
                out,
                li,
                gc,
                &format!(
                    "work coordinate system {} after moves in {} (a field is in one system's coordinates)",
                    wcs_name(c),
                    wcs_name(first)
                ),
            );
            st.active.wcs = Some((li as u32, idx));
        }
        _ => {}
    }
}

/// The number G10 gives the work system `wcs` (G54 = 1 … G59.3 = 9).
fn wcs_number(wcs: i32) -> Option<f64> {
    [540, 550, 560, 570, 580, 590, 591, 592, 593]
        .iter()
        .position(|&c| c == wcs)
        .map(|i| (i + 1) as f64)
}

/// Apply an offset code (`c`: 920 G92, 520 G52, 921/922/923 G92.1/.2/.3, 1002/1020 G10 L2/L20
/// on the system in force, 1000 G10 on another system) with its axis words, as LinuxCNC: G92 makes
/// the current position read as the words, G52 sets the G92/G52 register to them (the axes it
/// names), G92.1 and G92.2 zero the register (G92.1 its saved copy too), G92.3 restores the saved
/// copy (G92 and G52 save), G10 L20 moves the system's origin so the position reads as the words, G10
/// L2 sets the origin in machine coordinates (unknown here).
///
/// Positions are kept in the frame of the program's coordinates where its moves began (a field
/// is measured there). Before the first move an offset only says where that frame is: the
/// position reads as G92 or G10 L20 give it, and what the register holds is noted for G52 and
/// G92.1 later. After it, each code changes `st.off` (program = frame − off), NaN where the
/// program does not tell (the register's value at the first move, a machine origin).
#[allow(clippy::needless_range_loop)] // (each axis indexes several arrays)
fn frame(out: &mut Interp, st: &mut State, c: i32, axis: &[Option<f64>; NAXES], unit: f64) {
    let fixed = st.wcs_moves.is_some();
    let mut off = st.off;
    let named = |k: usize| axis[k].map(|v| v * axis_unit(k, unit));
    match c {
        // the position reads as the words
        920 | 1020 => {
            for k in 0..NAXES {
                if let Some(v) = named(k) {
                    if fixed {
                        let d = st.pos[k] - v - off[k];
                        off[k] = st.pos[k] - v;
                        if c == 1020 {
                            // the system's origin moved: every offset of the register moves with it
                            st.off_base[k] += d;
                            st.off_saved[k] += d;
                        }
                    } else {
                        st.pos[k] = v;
                        if c == 920 {
                            // the register now holds what makes the position read v: unknown
                            st.off_base[k] = f64::NAN;
                        }
                    }
                }
            }
            if c == 920 {
                st.off_saved = off;
            }
        }
        520 => {
            for k in 0..NAXES {
                if let Some(v) = named(k) {
                    if fixed {
                        off[k] = st.off_base[k] + v;
                    } else {
                        // the program's coordinates move by the change of the register
                        st.pos[k] -= v + st.off_base[k];
                        st.off_base[k] = -v;
                    }
                }
            }
            // the register is saved as G92 saves it
            st.off_saved = off;
        }
        921 | 922 => {
            if fixed {
                off = st.off_base;
            } else {
                for k in 0..NAXES {
                    st.pos[k] -= st.off_base[k];
                }
                st.off_base = [0.0; NAXES];
            }
            if c == 921 {
                st.off_saved = st.off_base;
            }
        }
        923 => {
            if fixed {
                off = st.off_saved;
            } else {
                st.pos = [f64::NAN; NAXES];
                st.off_base = [f64::NAN; NAXES];
            }
        }
        1002 => {
            for k in 0..NAXES {
                if axis[k].is_some() {
                    if fixed {
                        off[k] = f64::NAN;
                        st.off_base[k] = f64::NAN;
                        st.off_saved[k] = f64::NAN;
                    } else {
                        st.pos[k] = f64::NAN;
                    }
                }
            }
        }
        _ => {}
    }
    set_offsets(out, st, off);
}

/// Set the offsets in force, starting a new frame of the run when they change.
fn set_offsets(out: &mut Interp, st: &mut State, off: [f64; NAXES]) {
    let same = off
        .iter()
        .zip(&st.off)
        .all(|(a, b)| a.to_bits() == b.to_bits());
    if !same {
        st.off = off;
        out.frames.push(off);
        st.frame = (out.frames.len() - 1) as u32;
    }
}

/// A canned-cycle G code (× 10): G73, G74, G76, G81–G89.
fn cycle_code(c: i32) -> bool {
    matches!(c, 730 | 740 | 760 | 810..=890) && c % 10 == 0
}

/// A Fanuc lathe's G90, G92 or G94 (G-code system A): a turning, threading or facing cycle of
/// the motion group, which runs in each block with axis words until another motion code.
fn lathe_modal_cycle(d: Dialect, c: i32) -> bool {
    d == Dialect::FanucLathe && matches!(c, 900 | 920 | 940)
}

/// A Fanuc lathe's straight G90 or G94 block ([`LatheBox`]): its corner and the return to its
/// start; X and Z not written are the last box block's (modal). From an unknown start, refused.
fn lathe_box(
    out: &mut Interp,
    st: &mut State,
    li: usize,
    c: i32,
    w: &CycleWords,
    blocked: Option<usize>,
    unit: f64,
) -> Result<(), NcError> {
    let a = st.pos;
    let name = if c == 900 {
        "turning cycle G90"
    } else {
        "facing cycle G94"
    };
    let named = (0..NAXES).fold(0u16, |m, k| m | ((w.axis[k].is_some() as u16) << k));
    let mut corner = a;
    for (k, i) in [(0usize, 0usize), (2, 1)] {
        corner[k] = match w.axis[k] {
            Some(v) => v * unit + st.off[k],
            None => st.box_xz[i],
        };
    }
    let why = if !(a[0].is_finite() && a[2].is_finite()) {
        Some(format!("{name} from a position the program does not tell"))
    } else if !(corner[0].is_finite() && corner[2].is_finite()) {
        Some(format!(
            "{name} without X or Z, which no block of it before gives"
        ))
    } else {
        None
    };
    if let Some(why) = why {
        let idx = push_unsupported(out, li, w.col, &why);
        out.unsupported[idx].blocks += 1;
        st.pos = [f64::NAN; NAXES];
        push_record(out, st, li, Motion::Other, false, named, [0.0; 2], 1);
        return Ok(());
    }
    st.box_xz = [corner[0], corner[2]];
    push_lathe_cycle(out, st, li, c, &corner, named, [0.0; 2], blocked);
    Ok(())
}

/// A Fanuc lathe's grooving or threading cycle block (G74, G75, G76 with X/Z or U/W; see
/// [`LatheBox`]): from the start A where the tool stands, cuts within the rectangle to `end` (X
/// and Z the block leaves out are A's), and back to A. From an unknown start, or under nose
/// radius compensation, refused.
#[allow(clippy::too_many_arguments)]
fn lathe_cut_block(
    out: &mut Interp,
    st: &mut State,
    li: usize,
    c: i32,
    col: usize,
    end: &[f64; NAXES],
    named: u16,
    margin: [f64; 2],
    blocked: Option<usize>,
) {
    let a = st.pos;
    let name = lathe_cut_name(c);
    let why = if !(a[0].is_finite() && a[2].is_finite()) {
        Some(format!("{name} from a position the program does not tell"))
    } else if st.nose.is_some() || st.active.cutter_comp.is_some() {
        Some(format!("{name} under cutter (nose) radius compensation"))
    } else if !(end[0].is_finite() && end[2].is_finite()) {
        Some(format!("{name} to a position the program does not tell"))
    } else {
        None
    };
    let blocked = why
        .map(|why| push_unsupported(out, li, col, &why))
        .or(blocked);
    push_lathe_cycle(out, st, li, c, end, named, margin, blocked);
}

/// The records of a lathe cycle's block ([`LatheBox`]) from where the tool stands: the move to
/// `end` (its corner, or the end of its cut) and the return to the start, where it ends.
#[allow(clippy::too_many_arguments)]
fn push_lathe_cycle(
    out: &mut Interp,
    st: &mut State,
    li: usize,
    c: i32,
    end: &[f64; NAXES],
    named: u16,
    margin: [f64; 2],
    blocked: Option<usize>,
) {
    let a = st.pos;
    if let Some(idx) = blocked {
        out.unsupported[idx].blocks += 1;
    }
    st.pos = *end;
    push_record(
        out,
        st,
        li,
        Motion::Feed,
        blocked.is_none(),
        named,
        [0.0; 2],
        1,
    );
    out.records.last_mut().unwrap().cycle = CYCLE_LATHE;
    st.pos = a;
    push_record(out, st, li, Motion::Other, false, named, [0.0; 2], 1);
    out.records.last_mut().unwrap().cycle = CYCLE_LATHE;
    out.boxes.push(LatheBox {
        line: li as u32,
        code: c,
        start: [a[0], a[1], a[2]],
        margin,
        before: st.before,
    });
    out.summary.counts[Motion::Feed as usize] += 2;
}

/// LinuxCNC's threading cycle G76 (`G76 P Z I J K [R Q H E L]`), as `convert_threading_cycle`
/// runs it: passes from the drive line (X where the tool stands, I to the thread's peak, K its
/// depth; halved in diameter mode) and the start's Z to the block's Z, then a rapid to the block's
/// end. Moved as one ([`LatheBox`]): the rectangle from the start to the end, widened by the
/// depths (X) and by the compound angle's and the taper's run (Z). Its errors are rs274's.
fn linuxcnc_g76(
    out: &mut Interp,
    st: &mut State,
    li: usize,
    w: &CycleWords,
    blocked: Option<usize>,
    unit: f64,
) -> Result<(), NcError> {
    // (where the block is blocked already, by parameters or flow the engine does not follow, its
    // words may not be what the control reads: reported, not an error)
    if (st.comp.is_some() || st.nose.is_some()) && blocked.is_none() {
        return Err(ierr(
            li,
            w.col,
            "Cannot use G76 threading cycle with cutter radius compensation on (rs274)",
        ));
    }
    let [i, j, k] = w.ijk.map(|v| v.unwrap_or(0.0));
    let why = if i == 0.0 {
        Some("In G76, I must not be 0")
    } else if j <= 0.0 {
        Some("In G76, J must be greater than 0")
    } else if k <= j {
        Some("In G76, K must be greater than J")
    } else if w.p.is_none_or(|p| !(p > 0.0)) {
        Some("In G76, P (the pitch) must be greater than 0")
    } else {
        None
    };
    let blocked = match why {
        Some(why) if blocked.is_none() => return Err(ierr(li, w.col, format!("{why} (rs274)"))),
        _ => blocked,
    };
    let end = target(&st.pos, w.axis, st.incremental, unit, &st.off);
    let named = (0..NAXES).fold(0u16, |m, k| m | ((w.axis[k].is_some() as u16) << k));
    let half = if st.diameter { 0.5 } else { 1.0 };
    let q = w.q.filter(|&q| q != -1.0).unwrap_or(0.0).to_radians();
    let margin = [
        (i.abs() + k.abs()) * half * unit,
        (k.abs() * half * q.tan().abs() + w.e.unwrap_or(0.0).abs()) * unit,
    ];
    let col = w.col;
    let why = if named & !0b101 != 0 {
        Some("threading cycle G76 with axis words other than X and Z")
    } else {
        None
    };
    let blocked = why
        .map(|why| push_unsupported(out, li, col, why))
        .or(blocked);
    lathe_cut_block(out, st, li, 760, col, &end, named, margin, blocked);
    // (LinuxCNC's ends at the block's end, not at its start)
    st.pos = end;
    let n = out.records.len();
    out.records[n - 1].end = end;
    Ok(())
}

/// Why the engine does not follow a canned cycle, or None when it does.
fn cycle_refused(d: Dialect, c: i32) -> Option<String> {
    if d == Dialect::FanucLathe {
        return Some(match c {
            900 => "taper turning cycle G90 (R, or I on a Haas: a Fanuc lathe's, G-code system A)"
                .into(),
            920 => "threading cycle G92 (a Fanuc lathe's, G-code system A)".into(),
            940 => "taper facing cycle G94 (R, or K on a Haas: a Fanuc lathe's, G-code system A)"
                .into(),
            _ => format!("canned cycle {} on a lathe", g_name(c)),
        });
    }
    match c {
        760 if !d.is_linuxcnc() => Some("threading cycle G76".into()),
        760 => None,
        870 => Some(
            "canned cycle G87 (back boring, with spindle orientation) the engine does not follow"
                .into(),
        ),
        880 => Some(
            "canned cycle G88 (the operator retracts by hand: the position after it is unknown)"
                .into(),
        ),
        _ if cycle_traced(c) => None,
        _ => Some(format!("canned cycle {}", g_name(c))),
    }
}

/// The words of a canned-cycle block.
struct CycleWords<'a> {
    axis: &'a [Option<f64>; NAXES],
    r: Option<(f64, usize)>,
    q: Option<f64>,
    p: Option<f64>,
    l: Option<f64>,
    /// LinuxCNC's polar words (@ distance, ^ angle) of the block, when it has any: in G91 each of
    /// its L repeats turns and stretches the position about the origin by them.
    polar: Option<[Option<f64>; 2]>,
    /// Where errors point: the cycle's G word, or the first axis word.
    col: usize,
    /// I J K and E (LinuxCNC's G76: the thread's offsets and depths, and its taper's length).
    ijk: [Option<f64>; 3],
    e: Option<f64>,
}

/// A block in canned-cycle mode: its holes traced move by move as LinuxCNC runs them, or, when
/// the engine cannot follow it faithfully, an unsupported construct at its line with every XYZ
/// axis unknown afterwards.
fn canned(
    out: &mut Interp,
    st: &mut State,
    li: usize,
    c: i32,
    w: &CycleWords,
    blocked: Option<usize>,
    unit: f64,
) -> Result<(), NcError> {
    let named = (0..NAXES).fold(0u16, |m, k| m | ((w.axis[k].is_some() as u16) << k));
    // after a cycle the engine does not follow, the height is unknown; in G17 a hole's X and Y
    // are where its words put it (the last of L repeats in G91 is not traced: unknown too)
    let repeats_one = w.l.is_none_or(|l| l == 1.0);
    let unknown_after = |out: &mut Interp, st: &mut State, idx: usize| {
        out.unsupported[idx].blocks += 1;
        let hole = target(&st.pos, w.axis, st.incremental, unit, &st.off);
        let xy_known = st.plane == 0 && (repeats_one || !st.incremental);
        for (k, (q, h)) in st.pos.iter_mut().zip(hole).take(3).enumerate() {
            *q = if k < 2 && xy_known { h } else { f64::NAN };
        }
        push_record(out, st, li, Motion::Other, false, named, [0.0; 2], 1);
    };
    if let Some((_, idx)) = st.active.canned {
        unknown_after(out, st, idx);
        return Ok(());
    }
    if c == 760 && st.dialect.is_linuxcnc() {
        return linuxcnc_g76(out, st, li, w, blocked, unit);
    }
    if lathe_modal_cycle(st.dialect, c) {
        // (R, the taper, is modal like X and Z)
        st.box_taper |= w.r.is_some();
        if c != 920 && !st.box_taper {
            return lathe_box(out, st, li, c, w, blocked, unit);
        }
        // a block the engine does not follow that leaves out X or Z takes them from a box
        // block before, which the correction may have rewritten: not even copied
        if (w.axis[0].is_none() || w.axis[2].is_none()) && st.box_xz.iter().all(|v| v.is_finite()) {
            return Err(ierr(
                li,
                w.col,
                format!(
                    "this {} block leaves out X or Z, which a block before gives, and the correction may rewrite that one: write X and Z in it",
                    g_name(c)
                ),
            ));
        }
        let why = cycle_refused(st.dialect, c).unwrap_or_default();
        let idx = push_unsupported(out, li, w.col, &why);
        unknown_after(out, st, idx);
        return Ok(());
    }
    // in diameter mode a cycle is not traced (its block is copied as written)
    if st.diameter {
        let idx = push_unsupported(out, li, w.col, "canned cycle in lathe diameter mode");
        unknown_after(out, st, idx);
        return Ok(());
    }
    let name = g_name(c);
    let same = st.cyc.last == c;
    // the words LinuxCNC requires, and the values it keeps from the block before
    let r_raw = match w.r {
        Some((v, _)) => v,
        None if same => st.cyc.r,
        None => {
            return Err(ierr(
                li,
                w.col,
                format!("{name} needs an R word (the R plane) in its first block"),
            ))
        }
    };
    let repeats = match w.l {
        None => 1,
        Some(v) if v >= 1.0 && v.fract() == 0.0 && v <= 1e6 => v as u32,
        Some(v) => {
            return Err(ierr(
                li,
                w.col,
                format!("the L word (repeats) of {name} must be a whole number >= 1, got {v}"),
            ))
        }
    };
    let z_raw = match w.axis[2] {
        Some(v) => v,
        None if same => st.cyc.z,
        None => {
            return Err(ierr(
                li,
                w.col,
                format!("{name} needs a Z word (the bottom) in its first block"),
            ))
        }
    };
    let q = match (c, w.q) {
        (730 | 830, Some(v)) => v,
        (730 | 830, None) if same => st.cyc.q,
        (730 | 830, None) => {
            return Err(ierr(
                li,
                w.col,
                format!("{name} needs a Q word (the peck depth)"),
            ))
        }
        _ => w.q.unwrap_or(st.cyc.q),
    };
    if matches!(c, 730 | 830) && !(q > 0.0) {
        return Err(ierr(
            li,
            w.col,
            format!("the Q word (peck depth) of {name} must be > 0, got {q}"),
        ));
    }
    if matches!(c, 820 | 860 | 890) && w.p.is_none() && !same {
        return Err(ierr(
            li,
            w.col,
            format!("{name} needs a P word (the dwell) in its first block"),
        ));
    }
    let p = w.p.unwrap_or(st.cyc.p);
    st.cyc.r = r_raw;
    st.cyc.z = z_raw;
    st.cyc.q = q;
    st.cyc.p = p;
    st.cyc.last = c;
    // what the engine does not follow faithfully is refused at its line
    let col = w.col;
    let refuse = |out: &mut Interp, st: &mut State, why: String| {
        let idx = push_unsupported(out, li, col, &why);
        unknown_after(out, st, idx);
    };
    if st.plane != 0 {
        let plane = ["G17", "G18", "G19"][st.plane as usize];
        refuse(
            out,
            st,
            format!("canned cycle {name} in the {plane} plane (only G17 cycles are followed)"),
        );
        return Ok(());
    }
    if named & !0b111 != 0 {
        refuse(
            out,
            st,
            format!("canned cycle {name} with A B C U V W words"),
        );
        return Ok(());
    }
    // (a polar word from an unknown point gives no finite X, Y)
    let needs = [
        st.incremental || !w.axis[0].is_some_and(f64::is_finite),
        st.incremental || !w.axis[1].is_some_and(f64::is_finite),
        true,
    ];
    if (0..3).any(|k| needs[k] && !st.pos[k].is_finite())
        || st.cyc.level.is_some_and(|v| !v.is_finite())
    {
        refuse(
            out,
            st,
            format!("canned cycle {name} from an unknown position (give X, Y and Z a G0 or G1 move before it)"),
        );
        return Ok(());
    }
    let sets_level = st.cyc.level.is_none();
    if sets_level {
        st.cyc.level = Some(st.pos[2]);
    }
    // the cycle is worked out in the program's coordinates (the offsets of G92 & co. taken off)
    let off = st.off;
    let cur = [
        (st.pos[0] - off[0]) / unit,
        (st.pos[1] - off[1]) / unit,
        (st.pos[2] - off[2]) / unit,
    ];
    let level = (st.cyc.level.unwrap_or(st.pos[2]) - off[2]) / unit;
    let (r, cc, mut aa, mut bb, inc) = if st.incremental {
        let r = r_raw + level;
        (
            r,
            r + z_raw,
            cur[0],
            cur[1],
            [w.axis[0].unwrap_or(0.0), w.axis[1].unwrap_or(0.0)],
        )
    } else {
        (
            r_raw,
            z_raw,
            w.axis[0].unwrap_or(cur[0]),
            w.axis[1].unwrap_or(cur[1]),
            [0.0; 2],
        )
    };
    if r < cc {
        return Err(ierr(
            li,
            w.col,
            format!("the R plane of {name} ({r}) is below its bottom Z ({cc})"),
        ));
    }
    // a block's moves are bounded as a sampled block's pieces are: L repeats of a hole, and the
    // pecks of G73/G83 in each
    let pecks = if matches!(c, 730 | 830) {
        ((r - cc) / q).ceil().max(0.0)
    } else {
        0.0
    };
    let moves = repeats as f64 * (4.0 + 3.0 * pecks);
    if !(moves <= crate::sample::MAX_PIECES_PER_BLOCK) {
        return Err(ierr(
            li,
            w.col,
            format!(
                "{name} with L{repeats} would make {moves:.3e} moves, more than the {:.0} allowed for one block; check its L, Q, R and Z words",
                crate::sample::MAX_PIECES_PER_BLOCK
            ),
        ));
    }
    let retract_unknown = st.cyc.g98.is_none() && st.dialect.default_retract().is_none();
    let g98 = match st.cyc.g98.or(st.dialect.default_retract()) {
        Some(v) if st.cyc.g98.is_some() => v,
        Some(v) => {
            if !st.cyc.noted_default {
                st.cyc.noted_default = true;
                out.notes.push(Note {
                    line: li as u32,
                    message: format!("canned cycle {name} with neither G98 nor G99 set: read as G99 (retract to the R plane), rs274's default; a controller that starts in G98 retracts to the initial level instead"),
                });
            }
            v
        }
        None => {
            if !st.cyc.noted_default {
                st.cyc.noted_default = true;
                out.notes.push(Note {
                    line: li as u32,
                    message: format!("canned cycle {name} with neither G98 nor G99 set: the control's mode decides how the tool retracts (kept as cycle blocks; the height after the cycles is unknown until a move sets Z)"),
                });
            }
            st.cyc.unknown_run = true;
            false
        }
    };
    let mut holes = Vec::with_capacity(repeats.min(1024) as usize);
    for _ in 0..repeats {
        match w.polar {
            // as LinuxCNC: each repeat's polar step is taken from where the one before ended
            Some(polar) if st.incremental => {
                if aa == 0.0 && bb == 0.0 {
                    return Err(ierr(li, w.col, POLAR_AT_ORIGIN));
                }
                [aa, bb] = polar_xy([aa, bb], polar, true)
            }
            _ => {
                aa += inc[0];
                bb += inc[1];
            }
        }
        holes.push(Hole {
            x: aa,
            y: bb,
            r,
            bottom: cc,
        });
    }
    let mut steps = Vec::new();
    let (end, choices) = cycle_steps(
        c,
        g98,
        q,
        peck_clearance(st.inch),
        cur,
        level,
        &holes,
        None,
        &mut steps,
    );
    let supported = blocked.is_none();
    if let Some(idx) = blocked {
        out.unsupported[idx].blocks += 1;
    }
    for s in &steps {
        if let CycleStep::Move(m, p, bottom) = *s {
            for ((q, v), o) in st.pos.iter_mut().zip(p).zip(off) {
                *q = v * unit + o;
            }
            push_record(out, st, li, m, supported && bottom, 0b111, [0.0; 2], 1);
            out.records.last_mut().unwrap().cycle = if bottom { CYCLE_BOTTOM } else { CYCLE_MOVE };
            out.summary.counts[m as usize] += 1;
        }
    }
    for ((q, v), o) in st.pos.iter_mut().zip(end).zip(off) {
        *q = v * unit + o;
    }
    out.cycles.push(Cycle {
        line: li as u32,
        code: c,
        g98,
        sets_level,
        r: r * unit + off[2],
        bottom: cc * unit + off[2],
        q,
        p,
        repeats,
        r_word: r_raw,
        z_word: z_raw,
        retract_unknown,
        choices,
    });
    Ok(())
}

/// A move the engine copies without tracing it (G53, G38): noted, the axes it names unknown
/// after it.
fn untraced_move(
    out: &mut Interp,
    st: &mut State,
    li: usize,
    axis: &[Option<f64>; NAXES],
    end: &mut [f64; NAXES],
    named: u16,
    what: &str,
) {
    out.notes.push(Note {
        line: li as u32,
        message: what.into(),
    });
    for (e, a) in end.iter_mut().zip(axis) {
        if a.is_some() {
            *e = f64::NAN;
        }
    }
    st.pos = *end;
    push_record(out, st, li, Motion::Other, false, named, [0.0; 2], 1);
}

/// The diameter (mm) of tool `t` in the tool table the caller gave.
fn table_diameter(st: &State, t: u32) -> Option<f64> {
    st.tools.iter().find(|&&(n, _)| n == t).map(|&(_, d)| d)
}

/// Compensation the engine does not follow: its moves are unsupported until G40.
fn comp_not_followed(out: &mut Interp, st: &mut State, li: usize, gc: usize, why: &str) {
    let idx = push_unsupported(out, li, gc, why);
    st.active.cutter_comp = Some((li as u32, idx));
}

/// G41/G42 (tool D's diameter from the tool table, or the loaded tool's) or G41.1/G42.1 (D the
/// diameter): compensation followed when the radius is known: in the XY plane as LinuxCNC offsets
/// the path ([`comp_move`]); in G18/G19 (a lathe's nose radius, or a cutter outside G17) by the
/// bound on the field's change within the radius ([`Record::nose`]). Otherwise an unsupported
/// construct that blocks the moves until G40.
#[allow(clippy::too_many_arguments)]
fn comp_on(
    out: &mut Interp,
    st: &mut State,
    li: usize,
    c: i32,
    gc: usize,
    d_word: Option<f64>,
    l_word: Option<f64>,
    unit: f64,
) -> Result<(), NcError> {
    let name = g_name(c);
    if st.plane == 2 && st.dialect.is_linuxcnc() {
        return Err(ierr(
            li,
            gc,
            format!("{name} in G19: LinuxCNC compensates in G17 and G18 only"),
        ));
    }
    let lathe = st.dialect.lathe() && st.plane == 1;
    let diameter: Result<f64, String> = if st.diameter && !lathe {
        Err(format!(
            "cutter compensation {name} in lathe diameter mode outside G18: not treated"
        ))
    } else if st.comp_exit.is_some() {
        Err(format!(
            "cutter compensation {name} again before a move ended the compensation before it"
        ))
    } else if matches!(c, 411 | 421) {
        match d_word {
            None => return Err(ierr(li, gc, format!("{name} needs a D word (the diameter)"))),
            Some(_) if l_word.is_some() && !lathe => Err(format!(
                "cutter compensation {name} with an L word (a lathe tool's orientation): not treated"
            )),
            Some(d) => Ok(d * unit),
        }
    } else if lathe {
        // the nose radius: the tool table's diameter of the tool loaded (LinuxCNC: T… M6, or D
        // the tool), or of a Fanuc lathe's offset (T0101: tool 01, offset 01, which holds the
        // nose radius)
        let tool = if st.dialect == Dialect::FanucLathe {
            // (T0100, T0000: offset 00, none: no nose radius)
            st.tool_next.and_then(|t| match t {
                0 => Some(0),
                100.. => Some(t % 100),
                _ => None,
            })
        } else {
            d_word.map(|d| d.max(0.0) as u32).or(st.tool_loaded)
        };
        match tool {
            Some(0) if st.dialect == Dialect::FanucLathe => Ok(0.0),
            Some(t) => table_diameter(st, t).ok_or_else(|| format!(
                "nose radius compensation {name} with offset {t}: its nose radius is not known; give it in the tool table (--tool-table: tool {t}, D the nose diameter)"
            )),
            None => Err(format!(
                "nose radius compensation {name} with no tool offset selected (a lathe's T0101, or T… M6 on LinuxCNC): the nose radius is not known"
            )),
        }
    } else {
        let tool = match d_word {
            Some(d) if d < 0.0 || d.fract() != 0.0 => {
                return Err(ierr(
                    li,
                    gc,
                    format!("{name} D{d}: D must be a tool number (a whole number >= 0)"),
                ))
            }
            Some(d) => Some(d as u32),
            None => st.tool_loaded,
        };
        match tool {
            Some(0) => Ok(0.0),
            Some(t) => match table_diameter(st, t) {
                Some(d) => Ok(d),
                None if st.tools.is_empty() => Err(format!(
                    "cutter compensation {name} with tool {t}: its diameter is not known; give the tool table (--tool-table)"
                )),
                None => Err(format!(
                    "cutter compensation {name} with tool {t}, which the tool table does not hold"
                )),
            },
            None => Err(format!(
                "cutter compensation {name} with no D word and no tool loaded (T… M6): the radius is not known"
            )),
        }
    };
    match diameter {
        Ok(d) if st.plane != 0 => {
            // in G18/G19: the contour is corrected where it is, and the field's change within
            // the radius bounded (the tool's side does not matter to the bound)
            st.nose = Some(d.abs() / 2.0);
            // (a radius of 0 compensates nothing: its moves need not stay whole)
            st.nose_edge = d != 0.0;
            st.nose_dir = None;
            // (a negative diameter puts the tool on the other side, as LinuxCNC reads it)
            st.nose_side = if matches!(c, 410 | 411) { 1.0 } else { -1.0 } * d.signum();
        }
        Ok(d) => {
            // a negative diameter puts the tool on the other side, as LinuxCNC reads it
            let side = if matches!(c, 410 | 411) { 1.0 } else { -1.0 };
            st.comp = Some(CompOn {
                after_entry_arc: false,
                last_arc: None,
                r: side * d / 2.0,
                last: None,
            });
        }
        Err(why) => comp_not_followed(out, st, li, gc, &why),
    }
    Ok(())
}

/// Under radius compensation in G18/G19, at an inside corner before the move: the factor by which
/// it may multiply the error of the offset paths where the control meets them (1/cos of half the
/// turn), and how far short of the corner the tool stops on both moves (R·tan of half the turn);
/// (1, 0) elsewhere. The direction the move ends in is kept for the next. Err for a reversal,
/// where whether the control meets the paths or goes round is its reading of a tiny turn. Which
/// side is inside is LinuxCNC's reading of G41/G42 in the plane's coordinates (G18: Z, X); in the
/// Fanuc dialects, whose lathes and mills view the plane from either side, every corner is taken
/// for an inside one.
fn nose_turn(
    st: &mut State,
    m: Motion,
    end: &[f64; NAXES],
    center: [f64; 2],
) -> Result<(f64, f64), &'static str> {
    let Some(r) = st.nose else {
        return Ok((1.0, 0.0));
    };
    let [a1, a2, _] = PLANE_AXES[st.plane as usize];
    let (s, e) = ([st.pos[a1], st.pos[a2]], [end[a1], end[a2]]);
    let unit = |x: f64, y: f64| {
        let l = x.hypot(y);
        [x / l, y / l]
    };
    let (t0, t1) = if m.is_arc() {
        let ccw = m == Motion::ArcCcw;
        let tan = |p: [f64; 2]| {
            let u = unit(p[0] - center[0], p[1] - center[1]);
            if ccw {
                [-u[1], u[0]]
            } else {
                [u[1], -u[0]]
            }
        };
        (tan(s), tan(e))
    } else if (e[0] - s[0]).hypot(e[1] - s[1]) > 1e-9 {
        let t = unit(e[0] - s[0], e[1] - s[1]);
        (t, t)
    } else {
        return Ok((1.0, 0.0)); // (no move in the plane: the tool stands)
    };
    if !(t0.iter().chain(&t1).all(|v| v.is_finite())) {
        st.nose_dir = None;
        return Ok((1.0, 0.0));
    }
    let before = st.nose_dir.replace(t1);
    let Some(ta) = before else {
        return Ok((1.0, 0.0));
    };
    // positive to the left
    let turn = (ta[0] * t0[1] - ta[1] * t0[0]).atan2(ta[0] * t0[0] + ta[1] * t0[1]);
    if turn.abs() > COMP_REVERSAL {
        return Err("a reversal (a turn of more than 175°) under radius compensation in G18/G19: where the controller meets the offset paths is not followed");
    }
    let inside = st.dialect.is_fanuc() || st.nose_side * turn > 0.0;
    if !inside || turn.abs() <= 1e-12 {
        return Ok((1.0, 0.0));
    }
    Ok((1.0 / (turn / 2.0).cos(), r * (turn.abs() / 2.0).tan()))
}

/// Turn between directions: an angle (rad) of the corner arc's pieces checked.
const COMP_CORNER_STEP: f64 = std::f64::consts::PI / 12.0;
/// Turns under this (rad) the controller neither rounds nor trims (LinuxCNC's
/// TOLERANCE_CONCAVE_CORNER).
const COMP_SMALL_TURN: f64 = 0.05;
/// Turns over this (rad, 175°) are reversals, where whether the controller meets the offset
/// paths or goes round depends on its reading of the curvature: refused.
const COMP_REVERSAL: f64 = 175.0 * std::f64::consts::PI / 180.0;

/// The tool centre's offsets for a move under cutter radius compensation, or the move that ends
/// it (None for other moves); Err names why the move cannot be followed.
fn comp_move(
    st: &mut State,
    m: Motion,
    s: &[f64; NAXES],
    e: &[f64; NAXES],
    center: [f64; 2],
    names_xy: bool,
) -> Result<Option<Comp>, &'static str> {
    let (dx, dy) = (e[0] - s[0], e[1] - s[1]);
    let moves_xy = m.is_arc() || dx.hypot(dy) > 1e-9;
    let fixed = |o: [f64; 2], radius: f64| Comp {
        radius,
        start: o,
        end: o,
        ..Default::default()
    };
    if let Some(off) = st.comp_exit {
        let radius = off[0].hypot(off[1]);
        // (the move that names X or Y goes from the offset to the programmed point, LinuxCNC's
        // current point after G40 being the tool's, even where the programmed point stays)
        if !moves_xy && !names_xy {
            return Ok(Some(fixed(off, radius)));
        }
        if m.is_arc() {
            return Err("an arc as the move after G40 that ends cutter compensation: lead out with a straight move");
        }
        st.comp_exit = None;
        return Ok(Some(Comp {
            radius,
            start: off,
            exit: true,
            ..Default::default()
        }));
    }
    let Some(on) = st.comp.as_mut() else {
        return Ok(None);
    };
    let r = on.r;
    if !moves_xy {
        // LinuxCNC's next move after G41/G42 is the entry, whatever axes it moves: one that goes
        // nowhere in the plane is not longer than the radius (rs274 refuses it; a Fanuc control
        // starts the offset at the first move in the plane)
        if on.last.is_none() && r != 0.0 && st.dialect.is_linuxcnc() {
            return Err("the move that starts cutter compensation is not longer than the tool radius (the controller refuses it)");
        }
        // the tool stands where the last move in the plane left it (before the entry: unmoved)
        return Ok(on.last.map(|(o, _)| fixed(o, r.abs())));
    }
    if !(s[0].is_finite() && s[1].is_finite() && e[0].is_finite() && e[1].is_finite()) {
        return Err(
            "a move under cutter compensation from or to a position the program does not tell",
        );
    }
    let unit = |x: f64, y: f64| {
        let l = x.hypot(y);
        [x / l, y / l]
    };
    let mut entry = None;
    let (o0, t0, o1, t1, radial) = if m.is_arc() {
        let ccw = m == Motion::ArcCcw;
        // the tool left of a counter-clockwise arc is inside it
        let k = if ccw { -r } else { r };
        let (u0, u1) = (
            unit(s[0] - center[0], s[1] - center[1]),
            unit(e[0] - center[0], e[1] - center[1]),
        );
        if k < 0.0 && -k >= (s[0] - center[0]).hypot(s[1] - center[1]) {
            return Err("an arc under cutter compensation whose radius is not larger than the tool's on the side it cuts");
        }
        let tan = |u: [f64; 2]| if ccw { [-u[1], u[0]] } else { [u[1], -u[0]] };
        if on.last.is_none() {
            // LinuxCNC's entry arc: from the programmed start (where the tool is) to the end's
            // offset point, about the point of the radial line through it equally far from both
            if dx.hypot(dy) <= r.abs() {
                return Err("the arc that starts cutter compensation does not end further than the tool radius from where it starts (the controller refuses it)");
            }
            let q = [e[0] + k * u1[0], e[1] + k * u1[1]];
            let b_len = (s[0] - q[0]).hypot(s[1] - q[1]) / 2.0;
            let ab = (center[1] - q[1]).atan2(center[0] - q[0]);
            let a = (s[1] - q[1]).atan2(s[0] - q[0]) - ab;
            if a.cos().abs() < 1e-6 {
                return Err("an arc that starts cutter compensation with a tool radius not less than its own (the controller refuses it)");
            }
            let c_len = b_len / a.cos();
            let c = [q[0] + c_len * ab.cos(), q[1] + c_len * ab.sin()];
            let rho = (s[0] - c[0]).hypot(s[1] - c[1]);
            let a0 = (s[1] - c[1]).atan2(s[0] - c[0]);
            let a1 = (q[1] - c[1]).atan2(q[0] - c[0]);
            let full = std::f64::consts::TAU;
            let mut sweep = a1 - a0;
            if ccw {
                while sweep <= 0.0 {
                    sweep += full;
                }
            } else {
                while sweep >= 0.0 {
                    sweep -= full;
                }
            }
            entry = Some((c, rho, a0, sweep));
        }
        (
            [k * u0[0], k * u0[1]],
            tan(u0),
            [k * u1[0], k * u1[1]],
            tan(u1),
            k,
        )
    } else {
        let t = unit(dx, dy);
        let o = [-r * t[1], r * t[0]];
        (o, t, o, t, 0.0)
    };
    // the turn (rad, positive to the left) from the direction the move before ended in
    let turn = on.last.map_or(0.0, |(_, ta)| {
        (ta[0] * t0[1] - ta[1] * t0[0]).atan2(ta[0] * t0[0] + ta[1] * t0[1])
    });
    if turn.abs() > COMP_REVERSAL {
        return Err("a reversal (a turn of more than 175°) under cutter compensation: where the controller meets the offset paths is not followed");
    }
    // LinuxCNC trims an inside corner after an arc from that arc's centre, which for the arc
    // that started compensation is its own, not the programmed one's
    if on.after_entry_arc && r * turn > 0.0 && turn.abs() > COMP_SMALL_TURN {
        return Err("an inside corner right after the arc that starts cutter compensation: the controller meets the offset paths from the entry arc's own centre, which is not followed");
    }
    on.after_entry_arc = entry.is_some();
    let (start, corner) = match on.last {
        None if m.is_arc() => ([0.0; 2], Vec::new()),
        None => {
            if dx.hypot(dy) <= r.abs() {
                return Err("the move that starts cutter compensation is not longer than the tool radius (the controller refuses it)");
            }
            ([0.0; 2], Vec::new())
        }
        Some((a, ta)) => (o0, comp_corner(a, ta, o0, t0, r)),
    };
    // a turn the controller neither rounds nor trims (LinuxCNC's TOLERANCE_CONCAVE_CORNER, 0.05
    // rad): the tool goes straight from where the move before ended to this move's offset end
    let kink = match on.last {
        Some((a, _)) if turn.abs() <= COMP_SMALL_TURN => (a[0] - o0[0]).hypot(a[1] - o0[1]),
        _ => 0.0,
    };
    // (a tangent joint's, rounding's: nothing)
    if kink > 1e-4 && m.is_arc() {
        return Err("a turn under 0.05 rad into an arc under cutter compensation (the controller then moves the arc's start): not followed");
    }
    // an inside corner: the point where the offset paths meet (second of the corner points)
    let trim = if corner.is_empty() || r * turn <= 0.0 {
        0.0
    } else if corner.len() == 3 {
        let (a, q) = (corner[0], corner[1]);
        (q[0] - a[0])
            .hypot(q[1] - a[1])
            .max((q[0] - o0[0]).hypot(q[1] - o0[1]))
    } else {
        f64::INFINITY // (a reversal: the offset paths meet far behind the corner, if at all)
    };
    // at an inside corner with an arc on a side the controller meets the arc's offset circle,
    // further from the corner than the tangents meet: the straight side's offset from the corner
    // to that circle (the pieces next to the corner must be longer)
    let circle = if m.is_arc() {
        Some((
            center,
            (s[0] + o0[0] - center[0]).hypot(s[1] + o0[1] - center[1]),
        ))
    } else {
        on.last_arc
    };
    let arc_corner = trim > 0.0 && circle.is_some();
    let trim = match (circle, on.last) {
        (Some((c, rho)), Some((a, ta))) if trim > 0.0 && trim.is_finite() => {
            // the straight side's offset: the move before's (backwards from its end) after an
            // arc... or this one's (from its start) before one
            let (p0, dir) = if m.is_arc() {
                ([s[0] + a[0], s[1] + a[1]], [-ta[0], -ta[1]])
            } else {
                ([s[0] + o0[0], s[1] + o0[1]], t0)
            };
            let w = [p0[0] - c[0], p0[1] - c[1]];
            let b = dir[0] * w[0] + dir[1] * w[1];
            let disc = b * b - (w[0] * w[0] + w[1] * w[1] - rho * rho);
            if disc >= 0.0 {
                let u = [-b - disc.sqrt(), -b + disc.sqrt()]
                    .into_iter()
                    .filter(|u| *u >= -1e-9)
                    .fold(f64::INFINITY, f64::min);
                trim.max(if u.is_finite() { u } else { 0.0 })
            } else {
                trim
            }
        }
        _ => trim,
    };
    on.last = Some((o1, t1));
    on.last_arc = m.is_arc().then(|| {
        (
            center,
            (e[0] + o1[0] - center[0]).hypot(e[1] + o1[1] - center[1]),
        )
    });
    Ok(Some(Comp {
        radius: r.abs(),
        start,
        end: o1,
        radial,
        entry,
        arc_corner,
        exit: false,
        corner,
        trim,
        kink,
    }))
}

/// The tool centre around a corner of a compensated contour (offsets from the corner, mm): `a`,
/// where the move before ends, with the contour's direction `ta` there; `b` and `tb` where the
/// next starts. An outside corner gets the arc of the tool radius about the corner, an inside one
/// the point where the two offset paths' tangents meet. Empty when the paths join.
fn comp_corner(a: [f64; 2], ta: [f64; 2], b: [f64; 2], tb: [f64; 2], r: f64) -> Vec<[f64; 2]> {
    if (a[0] - b[0]).hypot(a[1] - b[1]) <= 1e-9 {
        return Vec::new();
    }
    let cross = ta[0] * tb[1] - ta[1] * tb[0];
    let mut pts = vec![a];
    if r * cross > 0.0 {
        let q = 1.0 + (a[0] * b[0] + a[1] * b[1]) / (r * r);
        if q > 1e-3 {
            pts.push([(a[0] + b[0]) / q, (a[1] + b[1]) / q]);
        }
    } else {
        let phi = (a[0] * b[1] - a[1] * b[0]).atan2(a[0] * b[0] + a[1] * b[1]);
        let n = (phi.abs() / COMP_CORNER_STEP).ceil().max(1.0) as usize;
        for k in 1..n {
            let (sn, cs) = (phi * k as f64 / n as f64).sin_cos();
            pts.push([a[0] * cs - a[1] * sn, a[0] * sn + a[1] * cs]);
        }
    }
    pts.push(b);
    pts
}

/// A spline's two inner control points (mm) and whether it continues the last G5 (no I J).
type SplineCtrl = ([[f64; 2]; 2], bool);

/// A spline block's control points (LinuxCNC's `convert_spline`): a G5's are the start plus I J
/// (without both: plus the register, the last G5's -P -Q) and the end plus P Q; a G5.1's one is
/// the start plus I J, raised to the cubic's two. I J P Q are offsets in program units whatever
/// the distance mode. The errors are rs274's. None for a G5 without I and J whose register the
/// program has not set.
#[allow(clippy::too_many_arguments)]
fn spline_block(
    st: &mut State,
    li: usize,
    gcol: usize,
    m: Motion,
    end: &[f64; NAXES],
    named: u16,
    ijk: [Option<f64>; 3],
    p: Option<f64>,
    q: Option<f64>,
    unit: f64,
    wcol: &[usize; 26],
) -> Result<Option<SplineCtrl>, NcError> {
    if st.comp.is_some() || st.nose.is_some() {
        return Err(ierr(
            li,
            gcol,
            "Cannot convert spline with cutter radius compensation (as rs274)",
        ));
    }
    if st.plane != 0 {
        return Err(ierr(li, gcol, "Splines must be in the XY plane (as rs274)"));
    }
    if let Some(k) = [2usize, 3, 4, 5]
        .into_iter()
        .find(|&k| named & (1 << k) != 0)
    {
        return Err(ierr(
            li,
            wcol[(AXES[k] - b'A') as usize],
            "Splines may not have motion in Z, A, B, or C (as rs274)",
        ));
    }
    if let Some(k) = [6usize, 7, 8].into_iter().find(|&k| named & (1 << k) != 0) {
        return Err(ierr(
            li,
            wcol[(AXES[k] - b'A') as usize],
            "a U, V or W word on a spline: LinuxCNC's spline moves X and Y only",
        ));
    }
    let s = [st.pos[0], st.pos[1]];
    let e = [end[0], end[1]];
    let ij = match (ijk[0], ijk[1]) {
        (Some(i), Some(j)) => Some([i, j]),
        (None, None) if m == Motion::Spline => None,
        _ if m == Motion::QSpline => {
            return Err(ierr(
                li,
                gcol,
                "Must specify both I and J with G5.1 (as rs274)",
            ))
        }
        _ => {
            return Err(ierr(
                li,
                gcol,
                "Must specify both I and J, or neither (as rs274)",
            ))
        }
    };
    if m == Motion::QSpline {
        if p.is_some() || q.is_some() {
            return Err(ierr(
                li,
                gcol,
                "P and Q on G5.1: a quadratic spline has one control point (I J)",
            ));
        }
        let [i, j] = ij.unwrap();
        let c = [s[0] + i * unit, s[1] + j * unit];
        return Ok(Some(([c, c], false)));
    }
    let (Some(pv), Some(qv)) = (p, q) else {
        return Err(ierr(
            li,
            gcol,
            "Must specify both P and Q with G5 (as rs274)",
        ));
    };
    let continued = ij.is_none();
    let first = ij.or(st.spline_ij);
    st.spline_ij = Some([-pv, -qv]);
    Ok(first.map(|[i, j]| {
        (
            [
                [s[0] + i * unit, s[1] + j * unit],
                [e[0] + pv * unit, e[1] + qv * unit],
            ],
            continued,
        )
    }))
}

fn push_record(
    out: &mut Interp,
    st: &mut State,
    li: usize,
    motion: Motion,
    supported: bool,
    named: u16,
    center: [f64; 2],
    turns: u32,
) {
    out.line_record[li - out.line_base] = out.records.len() as u32;
    if let (Some(r), None) = (st.rot, st.rot_idx) {
        st.rot_idx = Some(out.rotations.len() as u32);
        out.rotations.push(r);
    }
    let mut end = st.pos;
    if st.dialect.lathe() {
        end[1] = 0.0;
    }
    out.records.push(Record {
        line: li as u32,
        motion,
        plane: st.plane,
        inch: st.inch,
        incremental: st.incremental,
        arc_absolute: st.arc_absolute,
        supported,
        named,
        end,
        center,
        turns,
        cycle: 0,
        frame: st.frame,
        comp: NO_COMP,
        inverse_time: st.inverse_time,
        diameter: st.diameter,
        nose: st.nose.unwrap_or(0.0),
        whole: 0,
        rot: st.rot_idx.unwrap_or(NO_ROT),
        xy_both: st.rot_first,
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lex::lex;

    fn run(s: &str) -> Interp {
        let l = lex(s.as_bytes()).unwrap();
        interpret(&l).unwrap()
    }

    #[test]
    fn incremental_and_inch() {
        let it = run("G20 G91 G0 X1 Y1 Z1\nG1 X1\n");
        let r = &it.records[1];
        assert!(r.end[0].is_nan()); // unknown start stays unknown in G91
        let it = run("G20 G90 G0 X1 Y1 Z1\nG91 G1 X1\n");
        assert!((it.records[1].end[0] - 50.8).abs() < 1e-12);
        assert!(it.records[1].supported);
    }

    #[test]
    fn r_arc_centre() {
        // quarter circle clockwise from (0,0) to (1,1), radius 1: centre (1,0); counter-clockwise: (0,1)
        let it = run("G17 G90 G0 X0 Y0 Z0\nG2 X1 Y1 R1\n");
        let c = it.records[1].center;
        assert!(
            (c[0] - 1.0).abs() < 1e-12 && (c[1] - 0.0).abs() < 1e-12,
            "{c:?}"
        );
        let it = run("G17 G90 G0 X0 Y0 Z0\nG3 X1 Y1 R1\n");
        let c = it.records[1].center;
        assert!(
            (c[0] - 0.0).abs() < 1e-12 && (c[1] - 1.0).abs() < 1e-12,
            "{c:?}"
        );
    }

    #[test]
    fn unsupported_reported() {
        let it = run("G0 X0 Y0 Z0\nG41 D1 G1 X1\nG1 X2\nG40 G1 X3\nG88 X1 Y1 Z-1 R1 P1\nX2\nG80\n");
        let names: Vec<_> = it
            .unsupported
            .iter()
            .map(|u| (u.line, u.construct.clone(), u.blocks))
            .collect();
        assert_eq!(
            names[0],
            (
                1,
                "cutter compensation G41 with tool 1: its diameter is not known; give the tool table (--tool-table)"
                    .to_string(),
                3
            )
        );
        assert_eq!(names[1].0, 4);
        assert!(names[1].1.starts_with("canned cycle G88"), "{names:?}");
        assert_eq!(names[1].2, 2);
        // the move after G40 leaves the offset compensation put the tool at: as written too
        assert!(!it.records[3].supported);
    }

    #[test]
    fn cutter_compensation_offsets_and_inside_corner() {
        // G41 with a 2 mm tool (r = 1): the first move ends 1 mm left of +X; the left turn to +Y
        // is an inside corner, where the offset paths meet at (-1, 1) from the corner, r·tan 45° = 1
        // mm short of both offset ends
        let lx =
            lex(b"G21 G0 X0 Y0 Z0\nG41 D1\nG1 X10 F100\nG1 Y10\nG2 X20 Y20 I10 J0\nG40 G1 X30\n")
                .unwrap();
        let it = Interpreter::new()
            .with_tools(std::sync::Arc::new(vec![(1, 2.0)]))
            .run_all(&lx)
            .unwrap();
        assert!(it.unsupported.is_empty(), "{:?}", it.unsupported);
        let comp = |k: usize| &it.comps[it.records[k].comp as usize];
        assert_eq!(it.records[0].comp, NO_COMP);
        assert_eq!((comp(1).start, comp(1).end), ([0.0, 0.0], [0.0, 1.0]));
        assert_eq!((comp(2).start, comp(2).end), ([-1.0, 0.0], [-1.0, 0.0]));
        assert_eq!(comp(2).corner, vec![[0.0, 1.0], [-1.0, 1.0], [-1.0, 0.0]]);
        assert!((comp(2).trim - 1.0).abs() < 1e-12);
        // the clockwise arc about (20, 10), the tool left of it: outside, 1 mm along the radius;
        // it continues the +Y move (tangent), so no corner
        assert_eq!(comp(3).radial, 1.0);
        assert!(comp(3).corner.is_empty() && comp(3).trim == 0.0);
        // the move after G40 leaves the offset at the arc's end ((20, 20): radius up, +Y) for
        // the programmed end
        assert_eq!((comp(4).start, comp(4).end), ([0.0, 1.0], [0.0, 0.0]));
    }

    #[test]
    fn return_to_reference() {
        // G91 G28 Z0: a zero rapid, then Z to the stored position; X and Y stay known
        let it = run("G90 G0 X1 Y2 Z3\nG91 G28 Z0\nG90 G1 X5 F100\n");
        assert!(it.unsupported.is_empty());
        assert_eq!(it.notes.len(), 1);
        let (via, home) = (&it.records[1], &it.records[2]);
        assert_eq!((via.line, home.line), (1, 1));
        assert_eq!(&via.end[..3], &[1.0, 2.0, 3.0]);
        assert!(home.end[2].is_nan() && home.end[0] == 1.0 && home.end[1] == 2.0);
        assert!(!it.records[3].supported); // its Z is unknown
                                           // G28.1 stores the position and moves nothing; G28 beside a motion code is an error
        assert_eq!(run("G0 X1 Y2 Z3\nG28.1\n").records.len(), 1);
        let l = lex(b"G0 X1 Y2 Z3\nG28 G1 X4 F1\n").unwrap();
        assert!(interpret(&l).is_err());
    }

    #[test]
    fn canned_cycles_traced_as_linuxcnc() {
        // G98 G81 from Z10: XY at 10, down to R, feed to the bottom, back to 10; G99 to R
        let it = run("G21 G90 G0 X0 Y0 Z10\nG98 G81 X1 Y2 Z-3 R2 F100\nG99 X5\nG80\n");
        assert!(it.unsupported.is_empty(), "{:?}", it.unsupported);
        let ends: Vec<[f64; 3]> = it.records[1..]
            .iter()
            .map(|r| [r.end[0], r.end[1], r.end[2]])
            .collect();
        assert_eq!(
            ends,
            vec![
                [1.0, 2.0, 10.0],
                [1.0, 2.0, 2.0],
                [1.0, 2.0, -3.0],
                [1.0, 2.0, 10.0],
                [5.0, 2.0, 10.0],
                [5.0, 2.0, 2.0],
                [5.0, 2.0, -3.0],
                [5.0, 2.0, 2.0],
            ]
        );
        let bottoms: Vec<bool> = it.records[1..]
            .iter()
            .map(|r| r.cycle == CYCLE_BOTTOM && r.supported)
            .collect();
        assert_eq!(
            bottoms,
            vec![false, false, true, false, false, false, true, false]
        );
        assert_eq!(it.cycles.len(), 2);
        assert!(it.cycles[0].sets_level && !it.cycles[1].sets_level);
        // G73 in inches: the last peck lands on the bottom by rounding and adds a zero-length peck,
        // as rs274 prints it
        let it = run("G20 G90 G0 X0 Y0 Z1\nG98 G73 X1 Y2 Z-0.1 R0.05 Q0.03 F10\n");
        let z: Vec<f64> = it.records[1..]
            .iter()
            .map(|r| (r.end[2] / MM_PER_INCH * 1e4).round() / 1e4)
            .collect();
        assert_eq!(
            z,
            vec![
                1.0, 0.05, 0.02, 0.03, -0.01, 0.0, -0.04, -0.03, -0.07, -0.06, -0.1, -0.09, -0.1,
                1.0
            ]
        );
        // a cycle in G18, or from an unknown position, is refused at its line
        let it = run("G21 G90 G0 X0 Y0 Z10\nG18 G81 X1 Y2 Z-3 R2 F100\n");
        assert!(it.unsupported[0].construct.contains("G18"));
        let it = run("G21 G90 G0 X0 Y0\nG81 X1 Y2 Z-3 R2 F100\n");
        assert!(it.unsupported[0].construct.contains("unknown position"));
        // words LinuxCNC requires
        for bad in [
            "G81 X1 Z-1\n",
            "G81 X1 R1\n",
            "G83 X1 Z-1 R1\n",
            "G82 X1 Z-1 R1\n",
            "G81 X1 Z1 R0\n",
            "G81 X1 Z-1 R1 L0\n",
        ] {
            let src = format!("G21 G90 G0 X0 Y0 Z10\n{bad}");
            assert!(interpret(&lex(src.as_bytes()).unwrap()).is_err(), "{bad}");
        }
    }

    /// Fanuc/Haas: a length or angle without a decimal point is refused at its word (least input
    /// increments or units: a machine parameter decides); zero, and F S T M P L N D H, are not.
    #[test]
    fn fanuc_numbers_without_a_point() {
        let fanuc = |s: &str| interpret_as(&lex(s.as_bytes()).unwrap(), Dialect::Fanuc);
        for ok in [
            "G0 X0 Y0 Z0 A0\nG1 X10.5 Y.5 Z-1. F100 S1200 T1 M3\nG4 P500\nG43 H1\nN10 G1 X1.\n",
            "G0 X0 Y0 Z10.\nG98 G81 X1. Y2. Z-3. R2. F100 L2\nG80\n",
            "G0 X0 Y0 Z10.\nG65 P9010 A1 B2\n",
            // a lathe cycle's block numbers
            "G0 X1. Z0.1\nG71 P10 Q20 U0.01 W0.005 D0.05 F0.01\n",
        ] {
            assert!(fanuc(ok).is_ok(), "{ok}");
        }
        for (bad, at) in [
            ("G0 X0 Y0 Z10\n", (1, 10)),
            ("G0 X0 Y0 Z1.\nG1 X-5 F100\n", (2, 4)),
            ("G0 X0 Y0 Z1.\nG2 X2. Y0 I1 J0\n", (2, 11)),
            ("G0 X0 Y0 Z1.\nG2 X2. Y0 R1\n", (2, 11)),
            ("G0 X0 Y0 Z10.\nG98 G83 X1. Y2. Z-3. R2. Q1 F100\n", (2, 26)),
            ("G0 X0 Y0 Z1. A90\n", (1, 14)),
            (
                "G0 X0 Y0 Z10.\nG98 G83 X1. Y2. Z-3. R2. Q1. F100\nX2 Y3.\n",
                (3, 1),
            ),
            ("G0 X0 Y0 Z1.\nG3 X2. Y0 Z-1. I1. K1\n", (2, 20)),
        ] {
            match fanuc(bad) {
                Err(NcError::Interpret { line, col, message }) => {
                    assert_eq!((line, col), at, "{bad}");
                    assert!(message.contains("no decimal point"), "{message}");
                }
                r => panic!("{bad}: {r:?}"),
            }
            // LinuxCNC reads them as units
            assert!(interpret(&lex(bad.as_bytes()).unwrap()).is_ok(), "{bad}");
        }
    }

    /// A cycle block's moves are bounded like a sampled block's pieces.
    #[test]
    fn cycle_moves_bounded() {
        for bad in [
            "G83 X1 Y1 Z-1000 R1 Q0.0001 F100\n",
            "G83 X1 Y1 Z-10 R1 Q0.1 L10000 F100\n",
        ] {
            let src = format!("G21 G90 G0 X0 Y0 Z10\n{bad}");
            match interpret(&lex(src.as_bytes()).unwrap()) {
                Err(NcError::Interpret { line, message, .. }) => {
                    assert_eq!(line, 2);
                    assert!(message.contains("more than the 1000000"), "{message}");
                }
                r => panic!("{bad}: {:?}", r.map(|i| i.records.len())),
            }
        }
        let ok = "G21 G90 G0 X0 Y0 Z10\nG81 X1 Y1 Z-1 R1 L1000 F100\n";
        assert_eq!(
            interpret(&lex(ok.as_bytes()).unwrap()).unwrap().cycles[0].repeats,
            1000
        );
    }

    /// The retract mode of a cycle the program does not state: rs274's G99 for LinuxCNC; for
    /// Fanuc the control's, so the height after the cycles is unknown.
    #[test]
    fn unstated_retract_mode() {
        let src = "G21 G90 G0 X0 Y0 Z10.\nG81 X1. Y1. Z-1. R1. F100.\nX2.\nG80\nG1 X3. F100.\n";
        let lx = lex(src.as_bytes()).unwrap();
        let it = interpret(&lx).unwrap();
        assert!(!it.cycles[0].retract_unknown && !it.cycles[0].g98);
        assert_eq!(it.records.last().unwrap().end[2], 1.0);
        let it = interpret_as(&lx, Dialect::Fanuc).unwrap();
        assert!(it.cycles.iter().all(|c| c.retract_unknown));
        assert!(it.records.last().unwrap().end[2].is_nan());
        let stated = src.replace("G81", "G98 G81");
        let it = interpret_as(&lex(stated.as_bytes()).unwrap(), Dialect::Fanuc).unwrap();
        assert!(it.cycles.iter().all(|c| !c.retract_unknown && c.g98));
        assert_eq!(it.records.last().unwrap().end[2], 10.0);
    }
}
