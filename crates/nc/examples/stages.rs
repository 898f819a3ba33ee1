//! Time each stage of the engine on one program: `cargo run --release --example stages -- FILE`.
//! The displacement is a fixed small shift, so only the engine is measured (no field).
use std::io::Write;
use std::time::{Duration, Instant};

const CHUNK: usize = 32768;

fn main() {
    let path = std::env::args().nth(1).expect("usage: stages FILE");
    let t = Instant::now();
    let src = std::fs::read(&path).expect("read");
    let t_read = t.elapsed();
    let t = Instant::now();
    let lexed = nc::lex::lex(&src).expect("lex");
    let t_lex = t.elapsed();
    let t = Instant::now();
    let it = nc::interp::interpret(&lexed).expect("interp");
    let t_int = t.elapsed();
    let grid: Vec<f64> = (0..=100).map(|i| i as f64).collect();
    let opts = nc::sample::SampleOpts {
        chord_tol: 0.002,
        max_segment: std::env::var("MAXSEG")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(1.0),
        include_rapids: false,
        only_supported: true,
        grid_x: grid.clone(),
        grid_y: grid,
        grid: None,
    };
    let prog = nc::Program {
        src,
        lexed,
        interp: it,
    };
    let (mut t_samp, mut t_disp, mut t_emit, mut t_write) = (
        Duration::ZERO,
        Duration::ZERO,
        Duration::ZERO,
        Duration::ZERO,
    );
    let mut s = nc::sample::Samples::default();
    let mut disp: Vec<f64> = Vec::new();
    let mut out: Vec<u8> = Vec::new();
    let mut file =
        std::io::BufWriter::new(std::fs::File::create("/tmp/stages.out").expect("create"));
    let mut em = nc::emit::Emitter::new(&prog.src, &prog.lexed, &prog.interp);
    let (mut n_samples, mut n_bytes) = (0, 0);
    let nl = prog.lexed.lines.len();
    let mut a = 0;
    while a < nl {
        let b = (a + CHUNK).min(nl);
        let t = Instant::now();
        let recs = prog.records_of_lines(a..b);
        nc::sample::sample_range(&prog.interp, &opts, recs, &mut s).unwrap();
        t_samp += t.elapsed();
        let t = Instant::now();
        disp.clear();
        disp.extend(s.xyz.iter().map(|v| 1e-3 * (v * 0.1).sin()));
        t_disp += t.elapsed();
        let t = Instant::now();
        out.clear();
        em.lines(a..b, &s, &disp, &mut out).expect("emit");
        t_emit += t.elapsed();
        let t = Instant::now();
        file.write_all(&out).expect("write");
        t_write += t.elapsed();
        n_samples += s.rec.len();
        n_bytes += out.len();
        a = b;
    }
    println!(
        "read {:?} lex {:?} interp {:?} sample {:?} ({} samples) disp {:?} emit {:?} write {:?} ({} bytes)",
        t_read, t_lex, t_int, t_samp, n_samples, t_disp, t_emit, t_write, n_bytes
    );
}
