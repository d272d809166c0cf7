//! Times the area resample (equirect → cube) alone, on one thread, for profiling its
//! kernels: `cargo run --release -p ibl-core --example resample -- SRC.hdr N [RUNS]` prints
//! the fastest run's wall time and the work per output texel.

use ibl_core::equirect::{equirect_to_cube, Filter};
use ibl_core::progress::NoProgress;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let [_, src, n, rest @ ..] = args.as_slice() else {
        eprintln!("usage: resample SRC N [RUNS]");
        std::process::exit(2);
    };
    let n: usize = n.parse().expect("face size");
    let runs: usize = rest.first().map_or(5, |r| r.parse().expect("runs"));
    let env = ibl_core::envmap::load_environment(std::path::Path::new(src), false)
        .expect("readable environment");
    let ibl_core::envmap::Environment::Equirect(img) = &env.env else {
        panic!("{src} is not an equirect image");
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("thread pool");
    let mut best = f64::INFINITY;
    let mut sum = 0.0f64;
    for _ in 0..runs {
        let t = Instant::now();
        let cube = pool.install(|| equirect_to_cube(img, n, Filter::Area, 0.0, &NoProgress));
        best = best.min(t.elapsed().as_secs_f64());
        sum += cube
            .faces
            .iter()
            .map(|f| f.data.iter().map(|&v| v as f64).sum::<f64>())
            .sum::<f64>();
    }
    let texels = 6 * n * n;
    println!(
        "{}x{} -> {n}^2: best of {runs} {:.4} s on one thread, {:.0} ns per texel (checksum {:.6e})",
        img.width,
        img.height,
        best,
        best * 1e9 / texels as f64,
        sum / runs as f64
    );
}
