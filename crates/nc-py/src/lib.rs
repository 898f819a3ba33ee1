//! Python bindings of the NC engine: the private module `ncadapt._nc`.
//!
//! Arrays cross as little-endian bytes that the Python side views with `numpy.frombuffer`.

use nc::emit::{EmitState, EmitStats, Emitter};
use nc::field::{Field, Grid, Outside};
use nc::interp::{Dialect, Interp, NAXES};
use nc::pipeline::{self, Options, Outcome};
use nc::sample::{SampleOpts, Samples};
use nc::stream::{scan_style, Piece, Reader, Stream};
use nc::NcError;
use pyo3::buffer::PyBuffer;
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

create_exception!(
    _nc,
    EngineError,
    PyValueError,
    "An error of the NC engine: args (kind, line, col, message)."
);

/// The one conversion of engine errors into Python exceptions.
fn to_py(e: NcError) -> PyErr {
    match e {
        NcError::Parse { line, col, message } => {
            EngineError::new_err(("parse", line, col, message))
        }
        NcError::Interpret { line, col, message } => {
            EngineError::new_err(("interpret", line, col, message))
        }
        NcError::Usage(m) => PyValueError::new_err(m),
    }
}

#[cfg(target_endian = "big")]
compile_error!("the array exchange with numpy assumes a little-endian machine");

/// The bytes of a slice of plain numbers (one copy, into the Python bytes object).
fn raw_bytes<'py, T: Copy>(py: Python<'py>, v: &[T]) -> Bound<'py, PyBytes> {
    // SAFETY: f64 and u32 have no padding and every bit pattern is a valid byte sequence.
    let b =
        unsafe { std::slice::from_raw_parts(v.as_ptr() as *const u8, std::mem::size_of_val(v)) };
    PyBytes::new(py, b)
}

fn u32_bytes<'py>(py: Python<'py>, v: impl Iterator<Item = u32>) -> Bound<'py, PyBytes> {
    let v: Vec<u32> = v.collect();
    raw_bytes(py, &v)
}

/// The values of a C-contiguous float64 buffer.
fn f64_slice(buf: &PyBuffer<f64>) -> PyResult<&[f64]> {
    if !buf.is_c_contiguous() {
        return Err(PyValueError::new_err(
            "displacements must be a C-contiguous float64 array",
        ));
    }
    // SAFETY: a contiguous buffer of item_count f64 values, held alive by `buf` while we read;
    // the caller passes an array it does not change during the call.
    Ok(unsafe { std::slice::from_raw_parts(buf.buf_ptr() as *const f64, buf.item_count()) })
}

fn stats_dict<'py>(py: Python<'py>, s: &EmitStats) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("lines_in", s.lines_in)?;
    d.set_item("lines_out", s.lines_out)?;
    d.set_item("blocks_changed", s.blocks_changed)?;
    d.set_item("lines_added", s.lines_added)?;
    d.set_item("arcs_linearised", s.arcs_linearised)?;
    d.set_item("splines_linearised", s.splines_linearised)?;
    Ok(d)
}

fn records_dict<'py>(py: Python<'py>, it: &Interp) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("line", u32_bytes(py, it.records.iter().map(|r| r.line)))?;
    let motion: Vec<u8> = it.records.iter().map(|r| r.motion as u8).collect();
    let plane: Vec<u8> = it.records.iter().map(|r| r.plane).collect();
    let flags: Vec<u8> = it
        .records
        .iter()
        .map(|r| {
            r.inch as u8
                | (r.incremental as u8) << 1
                | (r.arc_absolute as u8) << 2
                | (r.supported as u8) << 3
                | (matches!(r.cycle, 1..=3) as u8) << 4
                | ((r.comp != nc::interp::NO_COMP
                    || r.nose > 0.0
                    || r.cycle == nc::interp::CYCLE_LATHE) as u8)
                    << 5
        })
        .collect();
    let named: Vec<u16> = it.records.iter().map(|r| r.named).collect();
    d.set_item("motion", PyBytes::new(py, &motion))?;
    d.set_item("plane", PyBytes::new(py, &plane))?;
    d.set_item("flags", PyBytes::new(py, &flags))?;
    d.set_item("named", raw_bytes(py, &named))?;
    let mut end = Vec::with_capacity(it.records.len() * NAXES);
    for r in &it.records {
        end.extend_from_slice(&r.end);
    }
    d.set_item("end", raw_bytes(py, &end))?;
    d.set_item("origin", raw_bytes(py, &it.origin))?;
    Ok(d)
}

fn unsupported_list(u: &[nc::interp::Unsupported]) -> Vec<(u32, u32, String, u32)> {
    u.iter()
        .map(|u| (u.line + 1, u.col + 1, u.construct.clone(), u.blocks))
        .collect()
}

fn notes_list(n: &[nc::interp::Note]) -> Vec<(u32, String)> {
    n.iter().map(|n| (n.line + 1, n.message.clone())).collect()
}

fn summary_dict<'py>(py: Python<'py>, s: &nc::interp::Summary) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("inch_lines", s.inch_lines)?;
    d.set_item("mm_lines", s.mm_lines)?;
    d.set_item("planes", s.planes.to_vec())?;
    d.set_item("counts", s.counts.to_vec())?;
    d.set_item("work_offsets", s.work_offsets.clone())?;
    d.set_item("tools", s.tools.clone())?;
    d.set_item("block_delete_lines", s.block_delete_lines)?;
    d.set_item("end_line", s.end_line.map(|l| l + 1))?;
    Ok(d)
}

/// A parsed program (native handle).
#[pyclass(module = "ncadapt._nc", frozen)]
struct Program {
    inner: nc::Program,
}

#[pymethods]
impl Program {
    /// `dialect`: linuxcnc, fanuc, grbl or marlin.
    #[staticmethod]
    #[pyo3(signature = (data, dialect="linuxcnc", tools=Vec::new()))]
    fn parse(py: Python<'_>, data: &[u8], dialect: &str, tools: Vec<(u32, f64)>) -> PyResult<Self> {
        let dialect = Dialect::from_name(dialect).map_err(to_py)?;
        let tools = std::sync::Arc::new(tools);
        // a borrowed slice, copied once (a Vec<u8> argument would be extracted byte by byte)
        let data = data.to_vec();
        let inner = py
            .allow_threads(|| nc::Program::parse_with(data, dialect, tools))
            .map_err(to_py)?;
        Ok(Program { inner })
    }

    /// The program's bytes.
    fn text<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, &self.inner.src)
    }

    fn n_lines(&self) -> usize {
        self.inner.lexed.lines.len()
    }

    /// Records as a dict of byte arrays: line (u32, 0-based), motion, plane, flags (u8 each:
    /// inch 1, G91 2, G90.1 4, supported 8, a move of a canned cycle 16, the field checked
    /// around it 32: cutter or nose radius compensation, a lathe's G90/G94 cycle),
    /// named (u16), end (float64, 9 per record, mm / degrees, NaN unknown), origin (9 float64).
    fn records<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        records_dict(py, &self.inner.interp)
    }

    /// The 0-based line of every record (u32 bytes).
    fn record_lines<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        u32_bytes(py, self.inner.interp.records.iter().map(|r| r.line))
    }

    /// Unsupported constructs: list of (line 1-based, col 1-based, construct, blocks).
    fn unsupported(&self) -> Vec<(u32, u32, String, u32)> {
        unsupported_list(&self.inner.interp.unsupported)
    }

    /// Notes: list of (line 1-based, message).
    fn notes(&self) -> Vec<(u32, String)> {
        notes_list(&self.inner.interp.notes)
    }

    /// Modal summary as a dict.
    fn summary<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        summary_dict(py, &self.inner.interp.summary)
    }

    /// Sample the program: (xyz, rec) as bytes of float64 (3 per sample) and uint32 (record
    /// index per sample).
    #[pyo3(signature = (chord_tol, max_segment, include_rapids, only_supported, grid_x, grid_y))]
    #[allow(clippy::too_many_arguments)]
    fn sample<'py>(
        &self,
        py: Python<'py>,
        chord_tol: f64,
        max_segment: f64,
        include_rapids: bool,
        only_supported: bool,
        grid_x: Vec<f64>,
        grid_y: Vec<f64>,
    ) -> PyResult<(Bound<'py, PyBytes>, Bound<'py, PyBytes>)> {
        let opts = SampleOpts {
            chord_tol,
            max_segment,
            include_rapids,
            only_supported,
            grid_x,
            grid_y,
            grid: None,
        };
        let s = py
            .allow_threads(|| self.inner.sample(&opts))
            .map_err(to_py)?;
        Ok((raw_bytes(py, &s.xyz), raw_bytes(py, &s.rec)))
    }
}

/// A piece sampled for Python: first line, end line, the bytes of the points the field is
/// evaluated at, record bytes, the piece's records, the bytes of the cutter compensation's
/// corner points.
type ChunkArrays<'py> = (
    usize,
    usize,
    Bound<'py, PyBytes>,
    Bound<'py, PyBytes>,
    Bound<'py, PyDict>,
    Bound<'py, PyBytes>,
);

/// One piece handed to the emitting thread: its lines, samples and displacements.
struct Job {
    piece: Piece,
    samples: Samples,
    disp: Vec<f64>,
    /// U V W displacements, 3 per sample, or empty.
    uvw: Vec<f64>,
}

/// What the emitting thread gives back: the output bytes and the buffers to reuse.
type Done = Result<(Vec<u8>, Samples, Vec<f64>), NcError>;

/// Bytes shared between the two passes over an in-memory program.
struct Shared(std::sync::Arc<Vec<u8>>);

impl AsRef<[u8]> for Shared {
    fn as_ref(&self) -> &[u8] {
        &self.0
    }
}

/// The program's bytes, or a file, as a reader.
enum Source {
    Bytes(std::sync::Arc<Vec<u8>>),
    File(std::path::PathBuf),
}

impl Source {
    fn open(&self) -> Result<Reader, NcError> {
        Ok(match self {
            Source::Bytes(b) => Box::new(std::io::Cursor::new(Shared(b.clone()))),
            Source::File(p) => Box::new(std::io::BufReader::with_capacity(
                1 << 20,
                std::fs::File::open(p)
                    .map_err(|e| NcError::Usage(format!("cannot read the program: {e}")))?,
            )),
        })
    }
}

/// A correction (or an inspection) run over a program read piece by piece: `next` reads,
/// interprets and samples the next piece, the caller evaluates its field there, `emit` hands the
/// piece with its displacements to an emitting thread and returns the output of the piece before
/// (so emitting one overlaps reading and sampling the next), `discard` drops a piece whose output
/// is not wanted; `finish` returns the last output. At most two pieces are held at a time, so
/// memory does not grow with the program.
#[pyclass(module = "ncadapt._nc")]
struct Corrector {
    stream: Stream,
    opts: SampleOpts,
    /// The piece sampled by `next` and not yet emitted.
    current: Option<(Piece, Samples)>,
    /// Buffers back from the emitting thread.
    spare: Vec<(Samples, Vec<f64>)>,
    jobs: Option<std::sync::mpsc::Sender<Job>>,
    done: std::sync::Mutex<std::sync::mpsc::Receiver<Done>>,
    in_flight: bool,
    worker: Option<std::thread::JoinHandle<Option<EmitState>>>,
    stats: Option<EmitStats>,
}

#[pymethods]
impl Corrector {
    /// `source`: the program's bytes, or the path of its file (str); `dialect`: linuxcnc,
    /// fanuc, grbl or marlin; `grid`: the native spec of a bilinear grid field the samples are for
    /// (an arc it leaves flat is sampled at its end, as `correct_native` samples it).
    #[new]
    #[pyo3(signature = (source, chord_tol, max_segment, include_rapids, only_supported, grid_x, grid_y, piece_bytes, expand_cycles=false, dialect="linuxcnc", grid=None, tools=Vec::new()))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        source: &Bound<'_, PyAny>,
        chord_tol: f64,
        max_segment: f64,
        include_rapids: bool,
        only_supported: bool,
        grid_x: Vec<f64>,
        grid_y: Vec<f64>,
        piece_bytes: usize,
        expand_cycles: bool,
        dialect: &str,
        grid: Option<&Bound<'_, PyAny>>,
        tools: Vec<(u32, f64)>,
    ) -> PyResult<Self> {
        let dialect = Dialect::from_name(dialect).map_err(to_py)?;
        let tools = std::sync::Arc::new(tools);
        let grid = match grid.map(native_field).transpose()? {
            Some(Field::Grid(g)) => Some(std::sync::Arc::new(g)),
            _ => None,
        };
        let src = if let Ok(b) = source.downcast::<PyBytes>() {
            Source::Bytes(std::sync::Arc::new(b.as_bytes().to_vec()))
        } else {
            Source::File(std::path::PathBuf::from(source.extract::<String>()?))
        };
        let piece_bytes = piece_bytes.max(1);
        // the first pass reads the program's number style, which every piece is written in
        let stream = py
            .allow_threads(|| -> Result<Stream, NcError> {
                let (style, crlf) = scan_style(src.open()?, piece_bytes)?;
                Ok(Stream::new(src.open()?, piece_bytes, style, crlf)
                    .with_dialect(dialect)
                    .with_tools(tools))
            })
            .map_err(to_py)?;
        let opts = SampleOpts {
            chord_tol,
            max_segment,
            include_rapids,
            only_supported,
            grid_x,
            grid_y,
            grid,
        };
        let (jobs, job_rx) = std::sync::mpsc::channel::<Job>();
        let (done_tx, done) = std::sync::mpsc::channel::<Done>();
        let worker = std::thread::spawn(move || {
            let mut state: Option<EmitState> = None;
            for job in job_rx {
                let p = &job.piece;
                let mut out = Vec::with_capacity(p.src.len() + p.src.len() / 4);
                let st = state.take().unwrap_or_else(|| {
                    let mut s = EmitState::new(&p.interp);
                    s.expand_cycles = expand_cycles;
                    s.arc_tol = chord_tol;
                    s
                });
                let mut em = Emitter::resume(&p.src, &p.lexed, &p.interp, st);
                let r = em.lines_uvw(
                    0..p.lexed.lines.len(),
                    &job.samples,
                    &job.disp,
                    &job.uvw,
                    &mut out,
                );
                state = Some(em.into_state());
                let failed = r.is_err();
                if done_tx
                    .send(r.map(|_| (out, job.samples, job.disp)))
                    .is_err()
                    || failed
                {
                    break;
                }
            }
            state
        });
        Ok(Corrector {
            stream,
            opts,
            current: None,
            spare: Vec::new(),
            jobs: Some(jobs),
            done: std::sync::Mutex::new(done),
            in_flight: false,
            worker: Some(worker),
            stats: None,
        })
    }

    /// Read and sample the next piece: (first line, end line, the bytes of the points to evaluate
    /// the field at (3 per sample: the sample, or the tool centre under cutter compensation),
    /// record bytes, the piece's records as `Program.records` gives them, with `origin`, the
    /// position before them, the bytes of the tool-centre points around compensated corners for
    /// [`Corrector::comp_check`]), or None at the end of the program.
    fn next<'py>(&mut self, py: Python<'py>) -> PyResult<Option<ChunkArrays<'py>>> {
        if self.current.is_some() {
            return Err(PyValueError::new_err(
                "emit or discard the current piece before reading the next",
            ));
        }
        let mut samples = self.spare.pop().map(|(s, _)| s).unwrap_or_default();
        let (stream, opts) = (&mut self.stream, &self.opts);
        let r = py.allow_threads(|| -> Result<Option<Piece>, NcError> {
            let Some(p) = stream.next_piece()? else {
                return Ok(None);
            };
            nc::sample::sample_range(&p.interp, opts, 0..p.interp.records.len(), &mut samples)?;
            Ok(Some(p))
        });
        let piece = match r {
            Ok(Some(p)) => p,
            Ok(None) => {
                self.spare.push((samples, Vec::new()));
                return Ok(None);
            }
            Err(e) => {
                self.spare.push((samples, Vec::new()));
                return Err(to_py(e));
            }
        };
        let (a, b) = (piece.line_base, piece.line_base + piece.lexed.lines.len());
        let recs = records_dict(py, &piece.interp)?;
        let r = (
            a,
            b,
            raw_bytes(py, samples.eval_points()),
            raw_bytes(py, &samples.rec),
            recs,
            raw_bytes(py, &samples.checks),
        );
        self.current = Some((piece, samples));
        Ok(Some(r))
    }

    /// The current piece's refusal under cutter compensation given the displacements at its
    /// samples and at its corner points: (1-based line, message), or None.
    fn comp_check(
        &self,
        disp: PyBuffer<f64>,
        cdisp: PyBuffer<f64>,
    ) -> PyResult<Option<(u32, String)>> {
        let (piece, samples) = self
            .current
            .as_ref()
            .ok_or_else(|| PyValueError::new_err("no piece read"))?;
        let (d, c) = (f64_slice(&disp)?, f64_slice(&cdisp)?);
        if d.len() != samples.xyz.len() || c.len() != samples.checks.len() {
            return Err(PyValueError::new_err(
                "displacements do not match the piece's samples and corner points",
            ));
        }
        Ok(nc::sample::comp_check(
            &piece.interp,
            samples,
            d,
            c,
            self.opts.chord_tol,
        ))
    }

    /// Hand the current piece with its displacements (C-contiguous float64, 3 per sample) to the
    /// emitting thread, with those of U, V and W (3 per sample) when the field moves them;
    /// returns the output of the piece handed before (empty for the first).
    #[pyo3(signature = (disp, uvw=None))]
    fn emit<'py>(
        &mut self,
        py: Python<'py>,
        disp: PyBuffer<f64>,
        uvw: Option<PyBuffer<f64>>,
    ) -> PyResult<Bound<'py, PyBytes>> {
        let (piece, samples) = self
            .current
            .take()
            .ok_or_else(|| PyValueError::new_err("no piece read"))?;
        let d = f64_slice(&disp)?;
        if d.len() != samples.xyz.len() {
            return Err(PyValueError::new_err(format!(
                "displacements have {} values, expected {}",
                d.len(),
                samples.xyz.len()
            )));
        }
        let uvw = match &uvw {
            Some(b) => {
                let u = f64_slice(b)?;
                if u.len() != samples.xyz.len() {
                    return Err(PyValueError::new_err(format!(
                        "U V W displacements have {} values, expected {}",
                        u.len(),
                        samples.xyz.len()
                    )));
                }
                u.to_vec()
            }
            None => Vec::new(),
        };
        let mut buf = self.spare.pop().map(|(_, v)| v).unwrap_or_default();
        buf.clear();
        buf.extend_from_slice(d);
        let prev = self.collect(py)?;
        let jobs = self
            .jobs
            .as_ref()
            .ok_or_else(|| PyValueError::new_err("the correction has finished"))?;
        jobs.send(Job {
            piece,
            samples,
            disp: buf,
            uvw,
        })
        .map_err(|_| PyValueError::new_err("the emitting thread has stopped"))?;
        self.in_flight = true;
        Ok(PyBytes::new(py, &prev))
    }

    /// Drop the current piece without emitting it: the run's output is not wanted (a check
    /// refused it, or this is an inspection), but reading goes on so the checks see the whole
    /// program.
    fn discard(&mut self) -> PyResult<()> {
        let (_, samples) = self
            .current
            .take()
            .ok_or_else(|| PyValueError::new_err("no piece read"))?;
        self.spare.push((samples, Vec::new()));
        Ok(())
    }

    /// The output of the last piece; ends the run (its counts are then in `stats`).
    fn finish<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let last = self.collect(py)?;
        self.jobs = None;
        if let Some(w) = self.worker.take() {
            let st = py
                .allow_threads(|| w.join())
                .map_err(|_| PyValueError::new_err("the emitting thread failed"))?;
            self.stats = Some(st.map(|s| s.stats).unwrap_or_default());
        }
        Ok(PyBytes::new(py, &last))
    }

    /// The counts of the finished run.
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let st = self
            .stats
            .as_ref()
            .ok_or_else(|| PyValueError::new_err("call finish first"))?;
        stats_dict(py, st)
    }

    /// Lines read so far.
    fn lines_read(&self) -> usize {
        self.stream.lines_read()
    }

    /// Unsupported constructs of the pieces read: list of (line 1-based, col 1-based, construct, blocks).
    fn unsupported(&self) -> Vec<(u32, u32, String, u32)> {
        unsupported_list(&self.stream.interp.unsupported)
    }

    /// Number of unsupported constructs in the pieces read.
    fn n_unsupported(&self) -> usize {
        self.stream.interp.unsupported.len()
    }

    /// Notes of the pieces read: list of (line 1-based, message).
    fn notes(&self) -> Vec<(u32, String)> {
        notes_list(&self.stream.interp.notes)
    }

    /// Modal summary of the pieces read.
    fn summary<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        summary_dict(py, &self.stream.interp.summary)
    }
}

impl Corrector {
    /// Wait for the piece in flight, keep its buffers, return its output.
    fn collect(&mut self, py: Python<'_>) -> PyResult<Vec<u8>> {
        if !self.in_flight {
            return Ok(Vec::new());
        }
        self.in_flight = false;
        let done = &self.done;
        let r = py
            .allow_threads(|| {
                done.lock()
                    .map_err(|_| ())
                    .and_then(|rx| rx.recv().map_err(|_| ()))
            })
            .map_err(|_| PyValueError::new_err("the emitting thread has stopped"))?;
        let (out, samples, disp) = r.map_err(to_py)?;
        self.spare.push((samples, disp));
        Ok(out)
    }
}

/// A field the engine evaluates itself, from Python: `("shift", (dx, dy, dz))` or
/// `("grid", xs, ys, step_x, step_y, values, outside, bounds)` (values in row order, steps None for an
/// irregular grid, outside "error", "clamp" or "extrapolate").
fn native_field(spec: &Bound<'_, PyAny>) -> PyResult<Field> {
    let kind: String = spec.get_item(0)?.extract()?;
    match kind.as_str() {
        "shift" => Ok(Field::Shift(spec.get_item(1)?.extract()?)),
        "grid" => {
            let outside = match spec.get_item(6)?.extract::<String>()?.as_str() {
                "error" => Outside::Error,
                "clamp" => Outside::Clamp,
                "extrapolate" => Outside::Extrapolate,
                o => return Err(PyValueError::new_err(format!("unknown outside mode {o:?}"))),
            };
            let f = Field::Grid(Grid {
                xs: spec.get_item(1)?.extract()?,
                ys: spec.get_item(2)?.extract()?,
                steps: [spec.get_item(3)?.extract()?, spec.get_item(4)?.extract()?],
                v: spec.get_item(5)?.extract()?,
                outside,
                bounds: spec.get_item(7)?.extract()?,
            });
            f.check().map_err(PyValueError::new_err)?;
            Ok(f)
        }
        k => Err(PyValueError::new_err(format!("unknown native field {k:?}"))),
    }
}

/// Evaluate a native field at points (bytes of float64, 3 per point): the displacements as
/// bytes, or None when a point is outside a refusing domain or a value is not finite.
#[pyfunction]
fn eval_field<'py>(
    py: Python<'py>,
    spec: &Bound<'py, PyAny>,
    xyz: &[u8],
) -> PyResult<Option<Bound<'py, PyBytes>>> {
    let f = native_field(spec)?;
    let pts: Vec<f64> = xyz
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
        .collect();
    let mut out = Vec::new();
    Ok(if f.eval(&pts, &mut out) {
        Some(raw_bytes(py, &out))
    } else {
        None
    })
}

/// The caller's open file `fd`, duplicated (it is not taken over: the caller closes its own).
#[cfg(unix)]
fn output_file(fd: i32) -> PyResult<Option<std::fs::File>> {
    use std::os::fd::BorrowedFd;
    // SAFETY: the caller's open file outlives the call
    Ok(Some(std::fs::File::from(
        unsafe { BorrowedFd::borrow_raw(fd) }.try_clone_to_owned()?,
    )))
}

/// Elsewhere the engine does not write the caller's file: the Python evaluation does the run.
#[cfg(not(unix))]
fn output_file(_fd: i32) -> PyResult<Option<std::fs::File>> {
    Ok(None)
}

/// A program being read, lexed and interpreted ahead of its correction ([`read_ahead`]).
#[pyclass(module = "ncadapt._nc")]
struct ReadAhead {
    inner: std::sync::Mutex<Option<pipeline::ReadAhead>>,
    path: String,
}

#[pymethods]
impl ReadAhead {
    /// A correction has taken the pieces read ahead (or they were dropped).
    #[getter]
    fn taken(&self) -> bool {
        self.inner.lock().map_or(true, |g| g.is_none())
    }

    /// Drop the pieces read ahead (the correction reads the program itself): the reading
    /// thread stops and its memory is freed.
    fn cancel(&self) {
        if let Ok(mut g) = self.inner.lock() {
            g.take();
        }
    }
}

/// Start reading the program file `path` (in pieces of `piece_bytes`, as `dialect`) in a thread
/// of its own, up to `ahead` pieces, for a `correct_native` of the same file to continue: the
/// caller's start-up (imports, reading the field) then runs beside it. Unused, it stops.
#[pyfunction]
#[pyo3(signature = (path, piece_bytes, dialect="linuxcnc", ahead=32))]
fn read_ahead(
    path: String,
    piece_bytes: usize,
    dialect: &str,
    ahead: usize,
) -> PyResult<ReadAhead> {
    let dialect = Dialect::from_name(dialect).map_err(to_py)?;
    let src = Source::File(std::path::PathBuf::from(&path));
    let reader = src.open().map_err(to_py)?;
    Ok(ReadAhead {
        inner: std::sync::Mutex::new(Some(pipeline::ReadAhead::start(
            reader,
            piece_bytes.max(1),
            dialect,
            ahead,
        ))),
        path,
    })
}

/// Correct a program (bytes, or the path of its file) with a native field, writing the output
/// to the open file descriptor `fd` (from its current offset) in threads that run without the
/// GIL. Returns the figures as a dict, or None when a check refuses the program (the caller runs
/// the Python evaluation to report it). `progress(first, end)` is called for each piece. `ahead`:
/// a [`read_ahead`] of the same file (path), whose pieces the first pass takes.
#[pyfunction]
#[pyo3(signature = (source, fd, field, chord_tol, max_segment, include_rapids, grid_x, grid_y, piece_bytes, limit, keep_unsupported, clearance, shift_norm, progress, expand_cycles=false, dialect="linuxcnc", ahead=None, tools=Vec::new()))]
#[allow(clippy::too_many_arguments)]
fn correct_native<'py>(
    py: Python<'py>,
    source: &Bound<'py, PyAny>,
    fd: i32,
    field: &Bound<'py, PyAny>,
    chord_tol: f64,
    max_segment: f64,
    include_rapids: bool,
    grid_x: Vec<f64>,
    grid_y: Vec<f64>,
    piece_bytes: usize,
    limit: f64,
    keep_unsupported: bool,
    clearance: Option<f64>,
    shift_norm: Option<f64>,
    progress: Option<PyObject>,
    expand_cycles: bool,
    dialect: &str,
    ahead: Option<&Bound<'py, ReadAhead>>,
    tools: Vec<(u32, f64)>,
) -> PyResult<Option<Bound<'py, PyDict>>> {
    let dialect = Dialect::from_name(dialect).map_err(to_py)?;
    let src = if let Ok(b) = source.downcast::<PyBytes>() {
        Source::Bytes(std::sync::Arc::new(b.as_bytes().to_vec()))
    } else {
        Source::File(std::path::PathBuf::from(source.extract::<String>()?))
    };
    // the pieces read ahead, when they are of this file
    let ahead = match (ahead, &src) {
        (Some(a), Source::File(p)) => {
            let a = a.borrow();
            if p.to_str() == Some(a.path.as_str()) {
                a.inner.lock().ok().and_then(|mut g| g.take())
            } else {
                None
            }
        }
        _ => None,
    };
    let field = native_field(field)?;
    if fd < 0 {
        return Err(PyValueError::new_err("a file descriptor is >= 0"));
    }
    let Some(out) = output_file(fd)? else {
        return Ok(None);
    };
    let opts = Options {
        sample: SampleOpts {
            chord_tol,
            max_segment,
            include_rapids,
            only_supported: true,
            grid_x,
            grid_y,
            grid: None,
        },
        piece_bytes: piece_bytes.max(1),
        limit,
        keep_unsupported,
        clearance,
        shift_norm,
        expand_cycles,
        dialect,
        tools: std::sync::Arc::new(tools),
    };
    // between pieces: the progress display, and Python's signal handlers (SIGTERM, Ctrl-C), which
    // run only when the main thread asks for them; an exception they raise stops the run
    let mut raised: Option<PyErr> = None;
    let mut say = |a: usize, b: usize| -> bool {
        Python::with_gil(|py| {
            if let Some(p) = &progress {
                if let Err(e) = p.call1(py, (a, b)) {
                    raised = Some(e);
                    return false;
                }
            }
            match py.check_signals() {
                Ok(()) => true,
                Err(e) => {
                    raised = Some(e);
                    false
                }
            }
        })
    };
    let r = py
        .allow_threads(|| {
            pipeline::correct_ahead(&|| src.open(), &field, &opts, &out, &mut say, ahead)
        })
        .map_err(to_py)?;
    let rep = match r {
        Outcome::Done(rep) => rep,
        Outcome::Refused => return Ok(None),
        Outcome::Stopped => {
            return Err(
                raised.unwrap_or_else(|| PyValueError::new_err("the correction was stopped"))
            )
        }
    };
    let d = PyDict::new(py);
    d.set_item("stats", stats_dict(py, &rep.stats)?)?;
    d.set_item("n_points", rep.n_points)?;
    d.set_item("total", rep.total)?;
    d.set_item("max", rep.max)?;
    d.set_item("unknown", rep.unknown)?;
    d.set_item("first_unknown", rep.first_unknown)?;
    d.set_item("low", rep.low)?;
    d.set_item("unsupported", unsupported_list(&rep.unsupported))?;
    d.set_item("notes", notes_list(&rep.notes))?;
    d.set_item("lines_read", rep.lines_read)?;
    Ok(Some(d))
}

#[pymodule]
fn _nc(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Program>()?;
    m.add_class::<Corrector>()?;
    m.add_function(wrap_pyfunction!(correct_native, m)?)?;
    m.add_function(wrap_pyfunction!(read_ahead, m)?)?;
    m.add_class::<ReadAhead>()?;
    m.add_function(wrap_pyfunction!(eval_field, m)?)?;
    m.add("EngineError", m.py().get_type::<EngineError>())?;
    // the package's one version (the crates'), without importlib.metadata at start-up
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
