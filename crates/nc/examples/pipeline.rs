//! Time the native correction on one program with a grid field read from a CSV (x,y,dz on a
//! uniform grid): `cargo run --release --example pipeline -- PROGRAM GRID.csv [MAXSEG]`.
//! Writes /tmp/pipeline.out; prints the wall time of each of 3 runs.
use std::time::Instant;

fn main() {
    let mut args = std::env::args().skip(1);
    let prog = args
        .next()
        .expect("usage: pipeline PROGRAM GRID.csv [MAXSEG]");
    let csv = args
        .next()
        .expect("usage: pipeline PROGRAM GRID.csv [MAXSEG]");
    let max_segment: f64 = args.next().map_or(5.0, |v| v.parse().expect("MAXSEG"));
    let text = std::fs::read_to_string(&csv).expect("read grid");
    let rows: Vec<[f64; 3]> = text
        .lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l
                .split(',')
                .map(|c| c.trim().parse().expect("number"))
                .collect();
            [v[0], v[1], v[2]]
        })
        .collect();
    let mut xs: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    let mut ys: Vec<f64> = rows.iter().map(|r| r[1]).collect();
    for a in [&mut xs, &mut ys] {
        a.sort_by(|p, q| p.partial_cmp(q).unwrap());
        a.dedup();
    }
    let mut v = vec![0.0; xs.len() * ys.len()];
    for r in &rows {
        let i = xs.partition_point(|&x| x < r[0]);
        let j = ys.partition_point(|&y| y < r[1]);
        v[j * xs.len() + i] = r[2];
    }
    let step = |g: &[f64]| (g[g.len() - 1] - g[0]) / (g.len() - 1) as f64;
    let bounds = [xs[0], xs[xs.len() - 1], ys[0], ys[ys.len() - 1]];
    let field = nc::field::Field::Grid(nc::field::Grid {
        steps: [Some(step(&xs)), Some(step(&ys))],
        xs: xs.clone(),
        ys: ys.clone(),
        v,
        outside: nc::field::Outside::Error,
        bounds,
    });
    let opts = nc::pipeline::Options {
        sample: nc::sample::SampleOpts {
            chord_tol: 0.002,
            max_segment,
            include_rapids: false,
            only_supported: true,
            grid_x: xs,
            grid_y: ys,
            grid: None,
        },
        piece_bytes: 1 << 18,
        limit: 1.0,
        keep_unsupported: false,
        clearance: None,
        shift_norm: None,
        expand_cycles: false,
        dialect: nc::interp::Dialect::LinuxCnc,
        tools: Default::default(),
    };
    let runs: usize = std::env::var("RUNS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3);
    for _ in 0..runs {
        let out = std::fs::File::create("/tmp/pipeline.out").expect("create");
        let t = Instant::now();
        let open = || -> Result<nc::stream::Reader, nc::NcError> {
            Ok(Box::new(std::io::BufReader::with_capacity(
                1 << 20,
                std::fs::File::open(&prog).map_err(|e| nc::NcError::Usage(e.to_string()))?,
            )))
        };
        let r =
            nc::pipeline::correct(&open, &field, &opts, &out, &mut |_, _| true).expect("correct");
        match r {
            nc::pipeline::Outcome::Done(rep) => println!(
                "{:.3} s: {} points, max {:.4}",
                t.elapsed().as_secs_f64(),
                rep.n_points,
                rep.max
            ),
            nc::pipeline::Outcome::Refused | nc::pipeline::Outcome::Stopped => println!("refused"),
        }
    }
}
