//! Python bindings of the NC engine: the private module `ncadapt._nc`.
//!
//! Arrays cross as little-endian bytes that the Python side views with `numpy.frombuffer`.

use nc::interp::{Interp, NAXES};
use nc::sample::{SampleOpts, Samples};
use nc::NcError;
use pyo3::buffer::PyBuffer;
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

create_exception!(_nc, EngineError, PyValueError, "An error of the NC engine: args (kind, line, col, message).");

/// The one conversion of engine errors into Python exceptions.
fn to_py(e: NcError) -> PyErr {
    match e {
        NcError::Parse { line, col, message } => EngineError::new_err(("parse", line, col, message)),
        NcError::Interpret { line, col, message } => EngineError::new_err(("interpret", line, col, message)),
        NcError::Usage(m) => PyValueError::new_err(m),
    }
}

#[cfg(target_endian = "big")]
compile_error!("the array exchange with numpy assumes a little-endian machine");

/// The bytes of a slice of plain numbers (one copy, into the Python bytes object).
fn raw_bytes<'py, T: Copy>(py: Python<'py>, v: &[T]) -> Bound<'py, PyBytes> {
    // SAFETY: f64 and u32 have no padding and every bit pattern is a valid byte sequence.
    let b = unsafe { std::slice::from_raw_parts(v.as_ptr() as *const u8, std::mem::size_of_val(v)) };
    PyBytes::new(py, b)
}

fn u32_bytes<'py>(py: Python<'py>, v: impl Iterator<Item = u32>) -> Bound<'py, PyBytes> {
    let v: Vec<u32> = v.collect();
    raw_bytes(py, &v)
}

/// A parsed program (native handle).
#[pyclass(module = "ncadapt._nc", frozen)]
struct Program {
    inner: nc::Program,
}

/// Samples of a program (native handle), kept to be passed back to `emit`.
#[pyclass(module = "ncadapt._nc", frozen)]
struct Sampled {
    inner: Samples,
}

#[pymethods]
impl Sampled {
    /// (xyz, rec) as bytes of float64 (3 per sample) and uint32 (record index per sample).
    fn arrays<'py>(&self, py: Python<'py>) -> (Bound<'py, PyBytes>, Bound<'py, PyBytes>) {
        let s = &self.inner;
        (raw_bytes(py, &s.xyz), raw_bytes(py, &s.rec))
    }

    fn __len__(&self) -> usize {
        self.inner.t.len()
    }
}

#[pymethods]
impl Program {
    #[staticmethod]
    fn parse(py: Python<'_>, data: Vec<u8>) -> PyResult<Self> {
        let inner = py.allow_threads(|| nc::Program::parse(data)).map_err(to_py)?;
        Ok(Program { inner })
    }

    /// The program's bytes.
    fn text<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, &self.inner.src)
    }

    fn n_lines(&self) -> usize {
        self.inner.lexed.lines.len()
    }

    /// Records as a dict of byte arrays: line (u32, 0-based), motion, plane, flags (u8 each),
    /// end (float64, 9 per record, mm / degrees, NaN unknown).
    fn records<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let it: &Interp = &self.inner.interp;
        let d = PyDict::new(py);
        d.set_item("line", u32_bytes(py, it.records.iter().map(|r| r.line)))?;
        let motion: Vec<u8> = it.records.iter().map(|r| r.motion as u8).collect();
        let plane: Vec<u8> = it.records.iter().map(|r| r.plane).collect();
        let flags: Vec<u8> = it
            .records
            .iter()
            .map(|r| r.inch as u8 | (r.incremental as u8) << 1 | (r.arc_absolute as u8) << 2 | (r.supported as u8) << 3)
            .collect();
        d.set_item("motion", PyBytes::new(py, &motion))?;
        d.set_item("plane", PyBytes::new(py, &plane))?;
        d.set_item("flags", PyBytes::new(py, &flags))?;
        let mut end = Vec::with_capacity(it.records.len() * NAXES);
        for r in &it.records {
            end.extend_from_slice(&r.end);
        }
        d.set_item("end", raw_bytes(py, &end))?;
        Ok(d)
    }

    /// Unsupported constructs: list of (line 1-based, col 1-based, construct, blocks).
    fn unsupported(&self) -> Vec<(u32, u32, String, u32)> {
        self.inner.interp.unsupported.iter().map(|u| (u.line + 1, u.col + 1, u.construct.clone(), u.blocks)).collect()
    }

    /// Notes: list of (line 1-based, message).
    fn notes(&self) -> Vec<(u32, String)> {
        self.inner.interp.notes.iter().map(|n| (n.line + 1, n.message.clone())).collect()
    }

    /// Modal summary as a dict.
    fn summary<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = &self.inner.interp.summary;
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

    #[pyo3(signature = (chord_tol, max_segment, include_rapids, only_supported, grid_x, grid_y))]
    fn sample(
        &self,
        py: Python<'_>,
        chord_tol: f64,
        max_segment: f64,
        include_rapids: bool,
        only_supported: bool,
        grid_x: Vec<f64>,
        grid_y: Vec<f64>,
    ) -> Sampled {
        let opts = SampleOpts { chord_tol, max_segment, include_rapids, only_supported, grid_x, grid_y };
        let inner = py.allow_threads(|| self.inner.sample(&opts));
        Sampled { inner }
    }

    /// Write the program with displacements: a C-contiguous float64 buffer, 3 per sample.
    fn emit<'py>(&self, py: Python<'py>, samples: &Sampled, disp: PyBuffer<f64>) -> PyResult<(Bound<'py, PyBytes>, Bound<'py, PyDict>)> {
        if !disp.is_c_contiguous() {
            return Err(PyValueError::new_err("displacements must be a C-contiguous float64 array"));
        }
        // SAFETY: a contiguous buffer of item_count f64 values, held alive by `disp` while we read;
        // the caller passes an array it does not change during the call.
        let d: &[f64] = unsafe { std::slice::from_raw_parts(disp.buf_ptr() as *const f64, disp.item_count()) };
        let (out, stats) = py.allow_threads(|| self.inner.emit(&samples.inner, d)).map_err(to_py)?;
        let st = PyDict::new(py);
        st.set_item("lines_in", stats.lines_in)?;
        st.set_item("lines_out", stats.lines_out)?;
        st.set_item("blocks_changed", stats.blocks_changed)?;
        st.set_item("lines_added", stats.lines_added)?;
        st.set_item("arcs_linearised", stats.arcs_linearised)?;
        Ok((PyBytes::new(py, &out), st))
    }
}

#[pymodule]
fn _nc(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Program>()?;
    m.add_class::<Sampled>()?;
    m.add("EngineError", m.py().get_type::<EngineError>())?;
    Ok(())
}
