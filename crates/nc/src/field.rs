//! Correction fields evaluated natively: a constant shift and a bilinear grid.
//!
//! These are the arithmetic of `ncadapt.fields.Shift` and `ncadapt.fields.GridField` (linear)
//! operation for operation, so the displacements are the same numbers to the last bit
//! (`tests/test_correct.py` compares them with the numpy evaluation). A correction with any other
//! field evaluates it in Python.

/// What a grid does with points outside its domain.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outside {
    /// Refuse (the caller falls back to the Python evaluation for the located refusal).
    Error,
    /// Hold the border value.
    Clamp,
    /// Extend the edge cells linearly.
    Extrapolate,
}

/// How far outside its domain a point may lie and still count as inside (`fields._EPS`).
pub const EPS: f64 = 1e-9;

/// A Z displacement `dz(x, y)` on a rectangular grid, interpolated bilinearly.
#[derive(Clone, Debug)]
pub struct Grid {
    pub xs: Vec<f64>,
    pub ys: Vec<f64>,
    /// Spacing of a uniform grid (`fields._step`), None for an irregular one.
    pub steps: [Option<f64>; 2],
    /// Values in row order: `v[j * nx + i]` at `(xs[i], ys[j])`.
    pub v: Vec<f64>,
    pub outside: Outside,
    /// (xmin, xmax, ymin, ymax) as the field holds them (`GridField.bounds`).
    pub bounds: [f64; 4],
}

/// A field the engine evaluates itself.
#[derive(Clone, Debug)]
pub enum Field {
    /// The same displacement everywhere.
    Shift([f64; 3]),
    Grid(Grid),
}

/// `u.floor()` without the library call: the same value for every finite u (-0.0 gives 0.0,
/// which makes the same cell and fraction).
#[inline]
fn floor(u: f64) -> f64 {
    if u.abs() < 4.0e15 {
        // SAFETY: |u| < 4e15 fits an i64
        let t = unsafe { u.to_int_unchecked::<i64>() } as f64;
        if t > u {
            t - 1.0
        } else {
            t
        }
    } else {
        u.floor()
    }
}

/// Cell index and fraction of `x` along a grid (`fields._cell`): the edge cells continue outside.
#[inline(always)]
fn cell(grid: &[f64], step: Option<f64>, x: f64) -> (usize, f64) {
    let n = grid.len();
    let top = (n - 2) as f64;
    match step {
        Some(step) => {
            let u = (x - grid[0]) / step;
            // np.clip(np.floor(u), 0, n - 2).astype(np.intp), then u - i in float64
            let f = floor(u);
            let f = if f < 0.0 {
                0.0
            } else if f > top {
                top
            } else {
                f
            };
            // SAFETY: 0 <= f <= n - 2 (a NaN, from a NaN point, takes cell 0: its value is NaN)
            let i = if f >= 0.0 {
                unsafe { f.to_int_unchecked::<i64>() as usize }
            } else {
                0
            };
            // f is the whole number i (u - f is NaN for a NaN f, as u is then NaN too)
            (i, u - f)
        }
        None => {
            // np.searchsorted(grid, x, side="right") - 1, clipped to 0..n-2
            let k = grid.partition_point(|&g| g <= x) as isize - 1;
            let i = k.clamp(0, n as isize - 2) as usize;
            (i, (x - grid[i]) / (grid[i + 1] - grid[i]))
        }
    }
}

impl Grid {
    /// The displacement's Z at (x, y), or None for a point outside the domain when outside
    /// points are refused.
    #[inline(always)]
    pub fn dz(&self, x: f64, y: f64) -> Option<f64> {
        let [x0, x1, y0, y1] = self.bounds;
        let (mut x, mut y) = (x, y);
        match self.outside {
            Outside::Error => {
                if x < x0 - EPS || x > x1 + EPS || y < y0 - EPS || y > y1 + EPS {
                    return None;
                }
            }
            Outside::Clamp => {
                // np.clip: max then min
                x = x.max(x0).min(x1);
                y = y.max(y0).min(y1);
            }
            Outside::Extrapolate => {}
        }
        let (i, a) = cell(&self.xs, self.steps[0], x);
        let (j, b) = cell(&self.ys, self.steps[1], y);
        let nx = self.xs.len();
        let k = j * nx + i;
        let (v00, v01) = (self.v[k], self.v[k + 1]);
        let (v10, v11) = (self.v[k + nx], self.v[k + nx + 1]);
        let lo = v00 + a * (v01 - v00);
        let hi = v10 + a * (v11 - v10);
        Some(lo + b * (hi - lo))
    }
}

impl Grid {
    /// The least and largest displacement over the rectangle [x0, x1] × [y0, y1], when it lies
    /// inside the measured area and crosses at most four grid lines each way: the bilinear field
    /// is monotone along x and along y within a cell, so its extremes over the rectangle are at
    /// the corners of the rectangle cut by the grid lines, which are evaluated. None otherwise.
    pub fn range_over(&self, x0: f64, x1: f64, y0: f64, y1: f64) -> Option<(f64, f64)> {
        let [bx0, bx1, by0, by1] = self.bounds;
        if !(x0 >= bx0 && x1 <= bx1 && y0 >= by0 && y1 <= by1) {
            return None;
        }
        let inside = |g: &[f64], a: f64, b: f64| -> Option<([f64; 6], usize)> {
            let (i, j) = (
                g.partition_point(|&v| v <= a),
                g.partition_point(|&v| v < b),
            );
            if j.saturating_sub(i) > 4 {
                return None;
            }
            let mut at = [a; 6];
            let mut n = 1;
            for &v in &g[i..j.max(i)] {
                at[n] = v;
                n += 1;
            }
            at[n] = b;
            Some((at, n + 1))
        };
        let (xs, nx) = inside(&self.xs, x0, x1)?;
        let (ys, ny) = inside(&self.ys, y0, y1)?;
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &y in &ys[..ny] {
            for &x in &xs[..nx] {
                let v = self.dz(x, y)?;
                if !v.is_finite() {
                    return None;
                }
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        Some((lo, hi))
    }
}

impl Field {
    /// Check a grid's shape (the Python side has validated its values).
    pub fn check(&self) -> Result<(), String> {
        if let Field::Grid(g) = self {
            if g.xs.len() < 2 || g.ys.len() < 2 || g.v.len() != g.xs.len() * g.ys.len() {
                return Err(format!(
                    "a grid of {} x {} needs {} values, got {}",
                    g.xs.len(),
                    g.ys.len(),
                    g.xs.len() * g.ys.len(),
                    g.v.len()
                ));
            }
        }
        Ok(())
    }

    /// The rectangle the field was measured on (None: everywhere).
    pub fn bounds(&self) -> Option<[f64; 4]> {
        match self {
            Field::Shift(_) => None,
            Field::Grid(g) => Some(g.bounds),
        }
    }

    /// Displacements (3 per point) at the points `xyz` (3 per point), appended to `out`
    /// (cleared first). False when a point is outside a domain that refuses outside points, or a
    /// point or displacement is not finite: the caller then leaves the run to the Python
    /// evaluation, which reports it.
    pub fn eval(&self, xyz: &[f64], out: &mut Vec<f64>) -> bool {
        out.clear();
        out.reserve(xyz.len());
        match self {
            Field::Shift(d) => {
                if !d.iter().all(|v| v.is_finite()) {
                    return false;
                }
                for p in xyz.chunks_exact(3) {
                    if !(p[0].is_finite() && p[1].is_finite() && p[2].is_finite()) {
                        return false;
                    }
                    out.extend_from_slice(d);
                }
                true
            }
            Field::Grid(g) => {
                let mut ok = true;
                // written straight into the reserved room: (0, 0, dz) per point
                let room = &mut out.spare_capacity_mut()[..xyz.len() - xyz.len() % 3];
                for (p, d) in xyz.chunks_exact(3).zip(room.chunks_exact_mut(3)) {
                    ok &= p[0].is_finite() && p[1].is_finite() && p[2].is_finite();
                    match g.dz(p[0], p[1]) {
                        Some(dz) => {
                            ok &= dz.is_finite();
                            d[0].write(0.0);
                            d[1].write(0.0);
                            d[2].write(dz);
                        }
                        None => return false,
                    }
                }
                // SAFETY: every element up to this length was written above
                unsafe { out.set_len(xyz.len() - xyz.len() % 3) };
                ok
            }
        }
    }
}

/// numpy's sum of a float64 array (`ndarray.sum`): pairwise, in blocks of 128 with eight
/// accumulators, so a total over pieces is the same number the numpy evaluation gives.
pub fn numpy_sum(a: &[f64]) -> f64 {
    let n = a.len();
    if n < 8 {
        let mut res = -0.0;
        for &v in a {
            res += v;
        }
        // numpy starts from 0. for an empty or short array; -0.0 + x == x for any x != -0.0
        if n == 0 {
            return 0.0;
        }
        res
    } else if n <= 128 {
        let mut r = [0.0f64; 8];
        r.copy_from_slice(&a[..8]);
        let mut i = 8;
        while i < n - n % 8 {
            for k in 0..8 {
                r[k] += a[i + k];
            }
            i += 8;
        }
        let mut res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        while i < n {
            res += a[i];
            i += 1;
        }
        res
    } else {
        let mut n2 = n / 2;
        n2 -= n2 % 8;
        numpy_sum(&a[..n2]) + numpy_sum(&a[n2..])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_at_nodes_centres_and_outside() {
        let g = Grid {
            xs: vec![0.0, 10.0],
            ys: vec![0.0, 10.0],
            steps: [Some(10.0), Some(10.0)],
            v: vec![0.0, 0.1, 0.2, 0.3],
            outside: Outside::Extrapolate,
            bounds: [0.0, 10.0, 0.0, 10.0],
        };
        assert_eq!(g.dz(5.0, 5.0), Some(0.15000000000000002));
        assert_eq!(g.dz(0.0, 0.0), Some(0.0));
        assert_eq!(g.dz(10.0, 10.0), Some(0.3));
        assert!((g.dz(20.0, 0.0).unwrap() - 0.2).abs() < 1e-15);
        let c = Grid {
            outside: Outside::Clamp,
            ..g.clone()
        };
        assert_eq!(c.dz(20.0, 0.0), Some(0.1));
        let e = Grid {
            outside: Outside::Error,
            ..g
        };
        assert_eq!(e.dz(10.0 + 1e-10, 0.0).is_some(), true);
        assert_eq!(e.dz(10.0 + 1e-8, 0.0), None);
    }

    #[test]
    fn pairwise_sum_shapes() {
        for n in [0usize, 1, 7, 8, 9, 127, 128, 129, 1000] {
            let a: Vec<f64> = (0..n).map(|k| 0.1 * k as f64).collect();
            let s = numpy_sum(&a);
            assert!(
                (s - a.iter().sum::<f64>()).abs() <= 1e-9 * s.abs().max(1.0),
                "{n}"
            );
        }
    }
}
