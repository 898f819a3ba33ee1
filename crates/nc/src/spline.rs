//! LinuxCNC's motion of a spline (G5, G5.1): not the curve itself but the arcs its canon layer
//! (`emccanon.cc`, `NURBS_FEED`) makes of it. The curve (a NURBS of its control points, clamped
//! uniform knots, `nurbs_additional_functions.cc`) is evaluated at 4 parameters per control
//! point, the tangent there by a difference of 1e-5 in the parameter, and each span between two
//! such points is joined by a biarc (two arcs meeting with one tangent, `biarc`), each arc an
//! `ARC_FEED` (a `STRAIGHT_FEED` where it is straight). The machine runs those arcs, which stray
//! from the curve by about 5e-6 of its size (5 µm on a metre): the correction follows them.

/// One piece of the motion: an arc from where the one before ends to `end`, about `centre`
/// (counter-clockwise when `ccw`), or a straight line when `centre` is None. XY, mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Piece {
    pub end: [f64; 2],
    pub centre: Option<[f64; 2]>,
    pub ccw: bool,
}

/// The knot vector of `knot_vector_creator(n, k)`: `k` zeros, then 1, 2, … up to the last
/// control point, then `n - k + 2` to the end.
fn knots(n: usize, k: usize) -> Vec<f64> {
    (0..=n + k)
        .map(|i| {
            if i < k {
                0.0
            } else if i <= n {
                (i + 1 - k) as f64
            } else {
                (n + 2 - k) as f64
            }
        })
        .collect()
}

/// The basis function `Nmix(i, k, u)` as LinuxCNC writes it (its spans closed at both ends).
fn nmix(i: usize, k: usize, u: f64, kv: &[f64]) -> f64 {
    if k == 1 {
        return if kv[i] <= u && u <= kv[i + 1] {
            1.0
        } else {
            0.0
        };
    }
    let a = kv[i + k - 1] - kv[i];
    let b = kv[i + k] - kv[i + 1];
    match (a == 0.0, b == 0.0) {
        (true, false) => (kv[i + k] - u) * nmix(i + 1, k - 1, u, kv) / b,
        (false, true) => (u - kv[i]) * nmix(i, k - 1, u, kv) / a,
        (true, true) => 0.0,
        (false, false) => {
            (u - kv[i]) * nmix(i, k - 1, u, kv) / a
                + (kv[i + k] - u) * nmix(i + 1, k - 1, u, kv) / b
        }
    }
}

/// `nurbs_point`: the curve at parameter `u` (control points X, Y, weight).
fn point(u: f64, k: usize, cp: &[[f64; 3]], kv: &[f64]) -> [f64; 2] {
    let n: Vec<f64> = (0..cp.len()).map(|i| nmix(i, k, u, kv)).collect();
    let den: f64 = (0..cp.len()).map(|i| n[i] * cp[i][2]).sum();
    let mut p = [0.0; 2];
    for i in 0..cp.len() {
        for (j, pj) in p.iter_mut().enumerate() {
            *pj += cp[i][j] * n[i] * cp[i][2] / den;
        }
    }
    p
}

fn unit(v: [f64; 2]) -> [f64; 2] {
    let h = v[0].hypot(v[1]);
    if h != 0.0 {
        [v[0] / h, v[1] / h]
    } else {
        v
    }
}

/// `nurbs_tangent`: the direction at `u`, by a difference of 1e-5 in the parameter.
fn tangent(u: f64, k: usize, cp: &[[f64; 3]], kv: &[f64]) -> [f64; 2] {
    const DU: f64 = 1e-5;
    let umax = (cp.len() + 1 - k) as f64;
    let (lo, hi) = ((u - DU).max(0.0), (u + DU).min(umax));
    let (a, b) = (point(lo, k, cp, kv), point(hi, k, cp, kv));
    unit([(b[0] - a[0]) / (hi - lo), (b[1] - a[1]) / (hi - lo)])
}

/// `arc`: from `p0` to `p1` leaving along `d`; `small` is LinuxCNC's 1e-6 in mm.
fn arc(p0: [f64; 2], p1: [f64; 2], d: [f64; 2], small: f64) -> Piece {
    let (x, y) = (p1[0] - p0[0], p1[1] - p0[1]);
    let den = 2.0 * (y * d[0] - x * d[1]);
    if den.abs() > small {
        let r = -(x * x + y * y) / den;
        Piece {
            end: p1,
            centre: Some([p0[0] + d[1] * r, p0[1] - d[0] * r]),
            ccw: r < 0.0,
        }
    } else {
        Piece {
            end: p1,
            centre: None,
            ccw: false,
        }
    }
}

/// Why a span's biarc is not followed, where LinuxCNC's construction is ill-conditioned: its
/// arcs would then hang on the rounding of the arithmetic (LinuxCNC computes in the program's
/// units, ncadapt in mm, and a build may fuse multiplications), and they can run metres away
/// from the curve. A biarc is followed when its two roots are well apart (the discriminant
/// above 1e-6 of b²), the one taken is positive and at most twice the chord (a proper biarc's
/// is about a quarter to a half of it), and the joint lies within a chord of the curve's span
/// (on loops and cusps LinuxCNC's joints stray up to a sixth of the chord from the curve; a
/// construction gone wrong puts them hundreds of chords away).
const ILL_CONDITIONED: &str = "LinuxCNC's arcs for a span of this spline are ill-conditioned (tangents nearly parallel or opposed: its biarc construction then depends on the rounding of its arithmetic and can run far from the curve): the machine's motion is not predictable; split the spline or write it as lines";

/// `biarc` (with r = 1): the two arcs from `p0` leaving along `ts` to `p4` arriving along `te`;
/// None where LinuxCNC makes none (it then moves nothing for the span). Also the root it takes
/// and the discriminant's share of b² (for [`ILL_CONDITIONED`]).
fn biarc(
    p0: [f64; 2],
    ts: [f64; 2],
    p4: [f64; 2],
    te: [f64; 2],
    small: f64,
) -> Option<([Piece; 2], f64, f64)> {
    let (ts, te) = (unit(ts), unit(te));
    let (vx, vy) = (p0[0] - p4[0], p0[1] - p4[1]);
    let c = vx * vx + vy * vy;
    let b = 2.0 * (vx * (ts[0] + te[0]) + vy * (ts[1] + te[1]));
    let a = 2.0 * (ts[0] * te[0] + ts[1] * te[1] - 1.0);
    let discr = b * b - 4.0 * a * c;
    if discr < 0.0 {
        return None;
    }
    let disq = discr.sqrt();
    let (beta1, beta2) = ((-b - disq) / 2.0 / a, (-b + disq) / 2.0 / a);
    if beta1 > 0.0 && beta2 > 0.0 {
        return None;
    }
    // (C's max: the first unless it is less than the second)
    let beta = if beta1 < beta2 { beta2 } else { beta1 };
    let alpha = beta;
    let ab = alpha + beta;
    let p1 = [p0[0] + alpha * ts[0], p0[1] + alpha * ts[1]];
    let p3 = [p4[0] - beta * te[0], p4[1] - beta * te[1]];
    let p2 = [
        (p1[0] * beta + p3[0] * alpha) / ab,
        (p1[1] * beta + p3[1] * alpha) / ab,
    ];
    let tm = unit([p3[0] - p2[0], p3[1] - p2[1]]);
    Some((
        [arc(p0, p2, ts, small), arc(p2, p4, tm, small)],
        beta,
        discr / (b * b),
    ))
}

/// The pieces LinuxCNC moves along for the NURBS of control points `cp` (X, Y, weight; mm) and
/// order `k`: G5's four points with order 4, G5.1's three with order 3. `small` is LinuxCNC's
/// straightness threshold (1e-6 program units) in mm. An error where LinuxCNC's construction
/// fails or gives no number (a span it skips, tangents it cannot join): the machine's motion is
/// then not what the program says.
pub fn linuxcnc_pieces(cp: &[[f64; 3]], k: usize, small: f64) -> Result<Vec<Piece>, &'static str> {
    let n = cp.len() - 1;
    let kv = knots(n, k);
    let umax = (n + 2 - k) as f64;
    let div = cp.len() * 4;
    let mut p0 = point(0.0, k, cp, &kv);
    let mut t0 = tangent(0.0, k, cp, &kv);
    let mut out = Vec::with_capacity(2 * div);
    for i in 1..=div {
        let u = umax * i as f64 / div as f64;
        let p1 = point(u, k, cp, &kv);
        let t1 = tangent(u, k, cp, &kv);
        let Some((two, beta, separation)) = biarc(p0, t0, p1, t1, small) else {
            return Err("LinuxCNC makes no arcs for a span of this spline (its biarc construction fails there): the machine's motion is not the program's");
        };
        let chord = (p1[0] - p0[0]).hypot(p1[1] - p0[1]);
        if !(separation > 1e-6 && beta > 0.0 && beta <= 2.0 * chord) {
            return Err(ILL_CONDITIONED);
        }
        // the joint near the curve's span (its distance to the polyline of 16 pieces of it)
        let joint = two[0].end;
        let at = |j: usize| {
            point(
                umax * (i as f64 - 1.0 + j as f64 / 16.0) / div as f64,
                k,
                cp,
                &kv,
            )
        };
        let mut near = f64::INFINITY;
        let mut a = at(0);
        for j in 1..=16 {
            let b = at(j);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let l2 = dx * dx + dy * dy;
            let t = if l2 > 0.0 {
                (((joint[0] - a[0]) * dx + (joint[1] - a[1]) * dy) / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            near = near.min((a[0] + t * dx - joint[0]).hypot(a[1] + t * dy - joint[1]));
            a = b;
        }
        if !(near <= chord) {
            return Err(ILL_CONDITIONED);
        }
        for pc in two {
            let finite = pc.end.iter().all(|v| v.is_finite())
                && pc.centre.is_none_or(|c| c.iter().all(|v| v.is_finite()));
            if !finite {
                return Err("LinuxCNC's arcs for this spline are not defined (tangents it cannot join, such as those of a straight or degenerate spline)");
            }
            out.push(pc);
        }
        (p0, t0) = (p1, t1);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cubic_s_arcs_stay_near_the_curve_and_end_at_its_end() {
        let cp = [
            [0.0, 0.0, 1.0],
            [3.0, 4.0, 1.0],
            [7.0, 4.0, 1.0],
            [10.0, 0.0, 1.0],
        ];
        let pieces = linuxcnc_pieces(&cp, 4, 1e-6).unwrap();
        assert_eq!(pieces.len(), 32);
        let last = pieces.last().unwrap().end;
        assert!((last[0] - 10.0).abs() < 1e-9 && last[1].abs() < 1e-9);
        // the arcs' ends are on the curve at u = i/16 or between (biarc joints)
        let mid = pieces[15].end; // the span's second arc ends at u = 8/16
        assert!((mid[0] - 5.0).abs() < 1e-9 && (mid[1] - 3.0).abs() < 1e-9);
    }

    #[test]
    fn an_ill_conditioned_biarc_is_refused() {
        // G5 X1 Y20 I0 J2 P-2 Q2 from X0 Y0: LinuxCNC's fourth arc ends 17 m away
        let cp = [
            [0.0, 0.0, 1.0],
            [0.0, 2.0, 1.0],
            [-1.0, 22.0, 1.0],
            [1.0, 20.0, 1.0],
        ];
        assert_eq!(linuxcnc_pieces(&cp, 4, 1e-6), Err(ILL_CONDITIONED));
    }

    #[test]
    fn a_straight_spline_is_refused() {
        let cp = [
            [0.0, 0.0, 1.0],
            [0.0, 0.0, 1.0],
            [400.0, 0.0, 1.0],
            [400.0, 0.0, 1.0],
        ];
        assert!(linuxcnc_pieces(&cp, 4, 1e-6).is_err());
    }
}
