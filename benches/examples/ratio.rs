//! `cargo run --release -p volcal_benches --example ratio -- [N]`: the best of N wall times of
//! the patent example's solve, with the benchmark's representation and with `representation:
//! auto`, run alternately in one process so that a machine whose speed drifts from one minute to
//! the next slows both alike; and a hash of the `auto` model and its covariance, to tell whether
//! a change left them the same to the bit.
use std::time::Instant;

fn main() {
    let n: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(30);
    let case = volcal_benches::patent();
    let t = &case.layout;
    let auto = volcal::flexibility::Auto::default();
    let (mut bg, mut ba) = (f64::MAX, f64::MAX);
    let mut hash = 0u64;
    for _ in 0..n {
        let s = Instant::now();
        let g = volcal::solve(&case.layout, &case.obs, &case.options, &[]).unwrap();
        bg = bg.min(s.elapsed().as_secs_f64());
        std::hint::black_box(g);
        let s = Instant::now();
        let a = volcal::flexibility::solve_auto(&t.topology, t.travel, &case.obs, &case.options, &auto, &[None; 18])
            .unwrap();
        // What `volcal solve` does after it when the machine file does not state the beams'
        // alignment (the patent example's beams follow the motion: nothing to cover).
        let (solution, _) = volcal::alignment::cover(&case.obs, &case.options, a.solution).unwrap();
        ba = ba.min(s.elapsed().as_secs_f64());
        let cov = &solution.covariance;
        let cov = (0..cov.nrows()).flat_map(|i| (0..cov.ncols()).map(move |j| cov[(i, j)]));
        hash = fnv1a(solution.model.u.iter().copied().chain(cov));
    }
    println!("given {:.2} ms  auto {:.2} ms  ratio {:.3}  hash {:016x}", bg * 1e3, ba * 1e3, ba / bg, hash);
}

/// FNV-1a over the bits of the values: equal hashes, equal values to the bit.
fn fnv1a(values: impl Iterator<Item = f64>) -> u64 {
    values.fold(0xcbf29ce484222325, |h, v| (h ^ v.to_bits()).wrapping_mul(0x100000001b3))
}
