//! `cargo run --release -p volcal_benches --bin peak_memory -- patent|large`: solves one case
//! and prints the solve time and the process's peak resident memory (VmHWM, Linux), before and
//! after the solve, so the solve's share is visible.

fn vm_hwm_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

fn main() {
    let which = std::env::args().nth(1).unwrap_or_else(|| "patent".into());
    let case = match which.as_str() {
        "large" => volcal_benches::large(),
        _ => volcal_benches::patent(),
    };
    let before = vm_hwm_kib();
    let t0 = std::time::Instant::now();
    let sol = volcal::solve(&case.layout, &case.obs, &case.options, &[]).unwrap();
    let dt = t0.elapsed();
    let after = vm_hwm_kib();
    println!(
        "{}: solve {:.1} ms, {} iterations, chi2/dof {:.3}; peak RSS {:.1} MiB after the data were built, {:.1} MiB after the solve",
        case.name,
        dt.as_secs_f64() * 1e3,
        sol.iterations,
        sol.stats.variance_factor,
        before as f64 / 1024.0,
        after as f64 / 1024.0
    );
}
