//! The `volcal` subcommands as library functions: argument values in, files and text out.

use anyhow::{bail, Context, Result};
use nalgebra::{Point3, Vector3};
use std::io::Write;
use std::path::{Path, PathBuf};
use volcal::predict;
use volcal::{Axis, ErrorFunction};
use volcal_bag::campaign::{load_campaign, provenance};
use volcal_formats::campaign_csv;
use volcal_formats::machine::Machine;
use volcal_formats::model_file;
use volcal_formats::plan::{load_plan, sim_config};
use volcal_formats::solving::{compare_with_truth, probe_offsets, solve_campaign, summary, Solved};
use volcal_formats::truth_file::TruthFile;
use volcal_sim::effects::{from_specs, EffectContext};
use volcal_sim::{simulate, Injection};

/// A progress spinner on stderr (hidden when stderr is not a terminal).
pub fn spinner(msg: &str) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::new_spinner();
    pb.set_style(indicatif::ProgressStyle::with_template("{spinner} {msg} [{elapsed}]").unwrap());
    pb.set_message(msg.to_string());
    pb.enable_steady_tick(std::time::Duration::from_millis(120));
    pb
}

/// A progress bar on stderr (hidden when stderr is not a terminal).
pub fn bar(len: u64, msg: &str) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::new(len);
    pb.set_style(
        indicatif::ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} [{elapsed}<{eta}]")
            .unwrap()
            .progress_chars("=> "),
    );
    pb.set_message(msg.to_string());
    pb
}

/// Options of `volcal simulate` beyond the machine, plan and seed.
#[derive(Clone, Debug, Default)]
pub struct SimulateOptions {
    /// Effects to inject (`id[:key=value,...]`, `+` joins several).
    pub inject: Vec<String>,
    /// Keep the injections out of the campaign file.
    pub conceal: bool,
    /// Air temperature drift, K/h (default: the machine file's).
    pub air_rate_k_per_h: Option<f64>,
    /// Record the air with every reading.
    pub record_air: bool,
    /// A directory of compensation files the simulated controller applies (`grid.csv`: a
    /// volumetric grid; otherwise LinuxCNC COMP_FILEs, of the given type).
    pub compensation: Option<(PathBuf, volcal_formats::compensation::CompFileType)>,
    /// Seed of the measurement noise when it should differ from the machine's (`seed` draws
    /// the machine): the same machine measured again.
    pub noise_seed: Option<u64>,
}

/// `volcal simulate`.
pub fn simulate_cmd(
    machine_path: &Path,
    plan_path: Option<&Path>,
    seed: u64,
    out: &Path,
    truth: Option<&Path>,
    opts: &SimulateOptions,
) -> Result<()> {
    let machine = Machine::load(machine_path)?;
    let plan = load_plan(plan_path)?;
    let mut cfg = sim_config(&machine, plan, seed);
    if let Some(r) = opts.air_rate_k_per_h {
        anyhow::ensure!(r.is_finite(), "--air-rate must be a number of kelvin per hour");
        cfg.environment.air_temp_rate_k_per_h = r;
    }
    cfg.environment.record_air |= opts.record_air;
    let ctx = EffectContext::new(&cfg, machine.layout.travel);
    let specs: Vec<&str> =
        opts.inject.iter().flat_map(|s| s.split('+')).map(str::trim).filter(|s| !s.is_empty()).collect();
    let mut injections = from_specs(&specs.join("+"), &ctx).map_err(|e| anyhow::anyhow!("--inject: {e}"))?;
    if let Some((dir, kind)) = &opts.compensation {
        injections.push(load_compensation(dir, *kind, machine.layout.topology.clone())?);
    }
    let refs: Vec<&dyn Injection> = injections.iter().map(|b| b.as_ref()).collect();
    let pb = spinner("simulating campaign");
    let sim = simulate(&cfg, &refs, opts.noise_seed.unwrap_or(seed)).map_err(|e| anyhow::anyhow!("{e}"))?;
    pb.finish_and_clear();
    let notes: Vec<String> =
        if opts.conceal { Vec::new() } else { specs.iter().map(|s| format!("injected: {s}")).collect() };
    campaign_csv::write_with_notes(out, &sim.campaign, &notes)?;
    eprintln!("wrote {} readings to {}", sim.campaign.readings.len(), out.display());
    for i in &sim.truth.injected {
        eprintln!("injected {}: {}", i.id, i.description);
    }
    if let Some(t) = truth {
        TruthFile::new(&sim.truth, seed, machine.gauge).write(t)?;
        eprintln!("wrote simulation truth to {}", t.display());
    }
    Ok(())
}

/// The controller that a compensation directory (`volcal export`'s output) describes, by the
/// files it holds: a volumetric grid (`grid.csv`), ISG volumetric tables (`isg_x.csv`, applied
/// through the machine's `topology`, as the kernel's configured chain does), SINUMERIK EEC and
/// CEC tables (`eec.mpf`, `cec.mpf`), else LinuxCNC per-joint tables of `kind`.
pub fn load_compensation(
    dir: &Path,
    kind: volcal_formats::compensation::CompFileType,
    topology: volcal::Topology,
) -> Result<Box<dyn Injection>> {
    let ctx = "--compensation";
    Ok(if dir.join("grid.csv").exists() {
        Box::new(volcal_formats::compensation_grid::read_grid(&dir.join("grid.csv")).context(ctx)?)
    } else if dir.join("isg_x.csv").exists() {
        Box::new(volcal_formats::isg::read_isg(dir, topology).context(ctx)?)
    } else if dir.join("eec.mpf").exists() {
        Box::new(volcal_formats::sinumerik::read_sinumerik(dir).context(ctx)?)
    } else {
        Box::new(volcal_formats::compensation::read_linuxcnc(dir, kind).context(ctx)?)
    })
}

/// Outcome of `volcal solve`, for the exit code.
pub enum SolveStatus {
    Complete,
    /// Written, but some error functions are not identifiable from the data.
    Partial,
    /// Written, but the estimator did not converge: the result may be wrong.
    NotConverged,
}

/// `volcal solve`.
pub fn solve_cmd(campaign_path: &Path, machine_path: &Path, out: &Path) -> Result<(Solved, SolveStatus)> {
    let machine = Machine::load(machine_path)?;
    let campaign = load_campaign(campaign_path)?;
    let pb = spinner(&format!("solving {} readings", campaign.readings.len()));
    let prov = provenance(campaign_path, machine_path)?;
    let t0 = std::time::Instant::now();
    let solved = solve_campaign(&campaign, machine, &campaign_path.display().to_string(), prov)?;
    let dt = t0.elapsed();
    pb.finish_and_clear();
    eprintln!(
        "solved {} readings, {} parameters in {:.1} ms ({} iterations)",
        solved.prepared.obs.len(),
        solved.solution.model.layout.n_params,
        dt.as_secs_f64() * 1e3,
        solved.solution.iterations
    );
    solved.file.write(out)?;
    print!(
        "{}",
        summary(&solved.solution.model, &solved.solution.uncertainty(), &solved.file, &probe_offsets(&campaign))
    );
    println!("\nwrote model to {}", out.display());
    let status = if !solved.solution.converged {
        SolveStatus::NotConverged
    } else if solved.solution.identifiability.extra_null_dim > 0 {
        SolveStatus::Partial
    } else {
        SolveStatus::Complete
    };
    Ok((solved, status))
}

/// Reads points for `volcal predict`: columns `x_m,y_m,z_m` and optional `px_m,py_m,pz_m`.
pub fn read_points(path: &Path) -> Result<(Vec<Point3<f64>>, Option<Vec<Vector3<f64>>>)> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read points {}", path.display()))?;
    let mut header: Option<Vec<String>> = None;
    let mut pts = Vec::new();
    let mut offs = Vec::new();
    let mut idx = [0usize; 3];
    let mut pidx: Option<[usize; 3]> = None;
    for (k, line) in text.lines().enumerate() {
        let lineno = k + 1;
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let f: Vec<&str> = t.split(',').map(str::trim).collect();
        match &header {
            None => {
                let h: Vec<String> = f.iter().map(|s| s.to_string()).collect();
                let find = |n: &str| h.iter().position(|c| c == n);
                for (i, n) in ["x_m", "y_m", "z_m"].iter().enumerate() {
                    idx[i] = find(n).ok_or_else(|| anyhow::anyhow!("{} line {lineno}: header lacks column {n} (required: x_m,y_m,z_m; optional: px_m,py_m,pz_m)", path.display()))?;
                }
                let p: Vec<Option<usize>> = ["px_m", "py_m", "pz_m"].iter().map(|n| find(n)).collect();
                if p.iter().all(|c| c.is_some()) {
                    pidx = Some([p[0].unwrap(), p[1].unwrap(), p[2].unwrap()]);
                } else if p.iter().any(|c| c.is_some()) {
                    bail!("{} line {lineno}: px_m, py_m and pz_m must be given together", path.display());
                }
                header = Some(h);
            }
            Some(h) => {
                if f.len() != h.len() {
                    bail!("{} line {lineno}: {} fields, the header has {}", path.display(), f.len(), h.len());
                }
                let num = |i: usize| -> Result<f64> {
                    let v: f64 = f[i].parse().map_err(|_| {
                        anyhow::anyhow!("{} line {lineno}, column {}: {:?} is not a number", path.display(), h[i], f[i])
                    })?;
                    if !v.is_finite() {
                        bail!("{} line {lineno}, column {}: {:?} is not a finite number", path.display(), h[i], f[i]);
                    }
                    Ok(v)
                };
                pts.push(Point3::new(num(idx[0])?, num(idx[1])?, num(idx[2])?));
                if let Some(p) = pidx {
                    offs.push(Vector3::new(num(p[0])?, num(p[1])?, num(p[2])?));
                }
            }
        }
    }
    if header.is_none() {
        bail!("{}: no header line (expected x_m,y_m,z_m)", path.display());
    }
    Ok((pts, pidx.map(|_| offs)))
}

/// `volcal predict`.
pub fn predict_cmd(model_path: &Path, points: &Path, out: &Path) -> Result<usize> {
    let loaded = model_file::load(model_path)?;
    let (model, unc) = (&loaded.model, loaded.uncertainty());
    let (pts, offs) = read_points(points)?;
    let travel = model.layout.travel;
    let big = Axis::ALL.iter().map(|&a| travel.length(a)).fold(0.0, f64::max);
    // Outside the travel the functions hold their end values, which no reading determines: such
    // a point gets no value, as one the readings leave open does (a tolerance of a thousandth
    // of the longest axis keeps points at the ends, rounded, inside).
    let inside = |x: &Point3<f64>| travel.contains(x, 1e-3 * big);
    let outside = pts.iter().filter(|x| !inside(x)).count();
    if outside * 2 > pts.len() && pts.iter().any(|x| x.coords.amax() > 50.0 * big) {
        bail!(
            "{}: the points are far outside the travel: they look like millimetres; coordinates are in metres",
            points.display()
        );
    }
    let f = std::fs::File::create(out).with_context(|| format!("cannot create {}", out.display()))?;
    let mut w = std::io::BufWriter::new(f);
    let with_p = offs.is_some();
    writeln!(
        w,
        "x_m,y_m,z_m{},ex_m,ey_m,ez_m,u95_m,determined,interpolated",
        if with_p { ",px_m,py_m,pz_m" } else { "" }
    )?;
    let pb = bar(pts.len() as u64, "predicting");
    let mut undetermined = 0;
    for (i, x) in pts.iter().enumerate() {
        let p = offs.as_ref().map(|o| o[i]).unwrap_or_else(Vector3::zeros);
        let values = if inside(x) {
            let pe = predict::predict(model, &unc, x, &p);
            undetermined += !pe.is_determined() as usize;
            error_fields(model, &pe)
        } else {
            ",,,,0,0".to_string()
        };
        if with_p {
            writeln!(w, "{},{},{},{},{},{},{values}", x.x, x.y, x.z, p.x, p.y, p.z)?;
        } else {
            writeln!(w, "{},{},{},{values}", x.x, x.y, x.z)?;
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    w.flush()?;
    if outside > 0 {
        let ranges = Axis::ALL
            .map(|a| {
                let [lo, hi] = travel.range(a);
                format!("{} {lo} to {hi} m", a.letter().to_ascii_lowercase())
            })
            .join(", ");
        eprintln!(
            "warning: {}: {outside} of {} point(s) lie outside the calibrated travel ({ranges}): no reading says what the error is there (determined = 0, no value); calibrate over the travel these points need",
            points.display(),
            pts.len()
        );
    }
    if undetermined > 0 {
        eprintln!(
            "warning: the data do not determine the error at {undetermined} of {} point(s) (determined = 0, no value): {}",
            pts.len(),
            volcal_formats::report::what_to_measure(model, &unc, &Vector3::zeros())
        );
    }
    Ok(pts.len())
}

/// Most grid points `volcal map` writes (about 2 GB of CSV).
const MAP_MAX_POINTS: usize = 20_000_000;

/// `volcal map`: the volumetric error on a grid.
pub fn map_cmd(model_path: &Path, step: f64, probe: Vector3<f64>, out: &Path) -> Result<usize> {
    if !(step > 0.0 && step.is_finite()) {
        bail!("--step must be a positive number of metres, got {step}");
    }
    let loaded = model_file::load(model_path)?;
    let (model, unc) = (&loaded.model, loaded.uncertainty());
    // Counted before the grid is built: a step in millimetres taken as metres would ask for
    // more points than memory holds.
    let count = predict::grid_len(&model.layout.travel, step);
    if count > MAP_MAX_POINTS as f64 {
        bail!(
            "--step {step} m gives {count:.3e} grid points (at most {MAP_MAX_POINTS}); use a coarser step (is it in millimetres?)"
        );
    }
    let pts = predict::grid(&model.layout.travel, step);
    let f = std::fs::File::create(out).with_context(|| format!("cannot create {}", out.display()))?;
    let mut w = std::io::BufWriter::new(f);
    writeln!(w, "x_m,y_m,z_m,px_m,py_m,pz_m,ex_m,ey_m,ez_m,e_norm_m,u95_m,determined,interpolated")?;
    let pb = bar(pts.len() as u64, "mapping");
    let mut undetermined = 0;
    for x in &pts {
        let pe = predict::predict(model, &unc, x, &probe);
        let values = if pe.is_determined() {
            let e = model.error(x, &probe);
            format!("{},{},{},{},{},1,{}", e.x, e.y, e.z, e.norm(), pe.u95(), pe.interpolated as u8)
        } else {
            undetermined += 1;
            format!(",,,,,0,{}", pe.interpolated as u8)
        };
        writeln!(w, "{},{},{},{},{},{},{values}", x.x, x.y, x.z, probe.x, probe.y, probe.z)?;
        pb.inc(1);
    }
    pb.finish_and_clear();
    w.flush()?;
    if undetermined > 0 {
        eprintln!(
            "warning: the data do not determine the error at {undetermined} of {} grid point(s) (determined = 0, no value): {}",
            pts.len(),
            volcal_formats::report::what_to_measure(model, &unc, &probe)
        );
    }
    Ok(pts.len())
}

/// `ex_m,ey_m,ez_m,u95_m,determined,interpolated` of a prediction: no numbers where the data do not
/// determine the error (the minimum-norm value there means nothing).
fn error_fields(model: &volcal::ErrorModel, pe: &predict::PointError) -> String {
    if !pe.is_determined() {
        return format!(",,,,0,{}", pe.interpolated as u8);
    }
    let e = model.error(&pe.x, &pe.p);
    format!("{},{},{},{},1,{}", e.x, e.y, e.z, pe.u95(), pe.interpolated as u8)
}

/// `volcal report`: the summary, and optionally per-axis compensation tables.
pub fn report_cmd(model_path: &Path, compensation_dir: Option<&Path>, points: usize) -> Result<String> {
    let loaded = model_file::load(model_path)?;
    let (model, unc, file) = (&loaded.model, loaded.uncertainty(), &loaded.file);
    let mut text = summary(model, &unc, file, &[]);
    if let Some(dir) = compensation_dir {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        for a in Axis::ALL {
            let path = dir.join(format!("compensation_{}.csv", a.letter().to_ascii_lowercase()));
            let mut w = std::io::BufWriter::new(
                std::fs::File::create(&path).with_context(|| format!("cannot create {}", path.display()))?,
            );
            let names: Vec<String> = (0..6).map(|m| ErrorFunction::from_index(a.index() * 6 + m).name()).collect();
            let units: Vec<&str> = (0..6).map(|m| if m < 3 { "m" } else { "rad" }).collect();
            let head: Vec<String> =
                names.iter().zip(&units).map(|(n, u)| format!("{}_{u}", n.to_ascii_lowercase())).collect();
            let sig: Vec<String> =
                names.iter().zip(&units).map(|(n, u)| format!("u_{}_{u}", n.to_ascii_lowercase())).collect();
            writeln!(
                w,
                "# compensation table of axis {} ({} gauge); u_ = standard uncertainty; both empty where the data do not determine the function",
                a.letter(),
                file.gauge.name()
            )?;
            writeln!(w, "{}_m,{},{}", a.letter().to_ascii_lowercase(), head.join(","), sig.join(","))?;
            for row in predict::compensation_table(model, &unc, a, points) {
                // Where the data do not determine a function its uncertainty is infinite and its
                // value the minimum-norm one, which no controller should apply: both cells are
                // empty, as in `volcal map` and `volcal predict`.
                let determined: Vec<bool> = row.sigmas.iter().map(|s| s.is_finite()).collect();
                let cell = |v: f64, d: bool| if d { v.to_string() } else { String::new() };
                let v: Vec<String> = row.values.iter().zip(&determined).map(|(&v, &d)| cell(v, d)).collect();
                let s: Vec<String> = row.sigmas.iter().zip(&determined).map(|(&v, &d)| cell(v, d)).collect();
                writeln!(w, "{},{},{}", row.q_m, v.join(","), s.join(","))?;
            }
            w.flush()?;
        }
        let sq: Vec<String> = file.squareness.iter().map(|(n, v)| format!("{n} = {v} rad")).collect();
        std::fs::write(dir.join("squareness.txt"), sq.join("\n") + "\n")?;
        text.push_str(&format!("\nwrote compensation tables to {}\n", dir.display()));
    }
    Ok(text)
}

/// `volcal demo`: simulate the patent's example campaign on the built-in machine, solve it,
/// print the report and the comparison with the simulation truth; then run the same campaign
/// through the ROS 2 node set ([`crate::demo_chain`]).
pub fn demo_cmd(workdir: Option<&Path>, seed: u64) -> Result<()> {
    let dir = match workdir {
        Some(d) => d.to_path_buf(),
        None => std::env::temp_dir().join(format!("volcal-demo-{}", std::process::id())),
    };
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let machine_path = dir.join("machine.yaml");
    std::fs::write(&machine_path, volcal_formats::machine::DEMO_MACHINE)?;
    let campaign = dir.join("campaign.csv");
    let truth = dir.join("truth.json");
    let model = dir.join("model.json");
    println!("volcal demo: fixed-beam campaign (patent EP 1 990 605 example: 3 positions x 25 beams x 100 points) on a simulated 1.0 x 0.8 x 0.6 m CMM\nworking directory: {}\n", dir.display());
    simulate_cmd(&machine_path, None, seed, &campaign, Some(&truth), &SimulateOptions::default())?;
    let (solved, _) = solve_cmd(&campaign, &machine_path, &model)?;
    let t = TruthFile::load(&truth)?;
    let (tm, _) = t.model.to_model()?;
    let offs = probe_offsets(&load_campaign(&campaign)?);
    let c = compare_with_truth(
        &solved.solution.model,
        &solved.solution.uncertainty(),
        &tm,
        solved.machine.gauge,
        &offs,
        0.1,
    );
    println!(
        "\nAgainst the simulation truth (gauge-aligned, 0.1 m grid, {} probe offsets): volumetric error RMS {:.4} um, max {:.4} um; predicted standard uncertainty RMS {:.4} um",
        offs.len(),
        c.rms_m * 1e6,
        c.max_m * 1e6,
        c.predicted_rms_m * 1e6
    );
    // The same campaign through the ROS 2 node set (launch, record, replay, solve).
    crate::demo_chain::run(&dir, seed, &machine_path, &solved, &tm, &offs)?;
    Ok(())
}

/// Parses three comma-separated numbers in metres (a point `x,y,z` or a probe offset
/// `px,py,pz`); the caller names the option in the error's context.
pub fn parse_vec3(s: &str) -> Result<Vector3<f64>> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| anyhow::anyhow!("{s:?} is not three comma-separated numbers in metres (e.g. 0.5,0.4,-0.3)"))?;
    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
        bail!("{s:?} is not three finite comma-separated numbers in metres (e.g. 0.5,0.4,-0.3)");
    }
    Ok(Vector3::new(v[0], v[1], v[2]))
}

/// [`parse_vec3`] of the value of `option` (e.g. `--probe`), which the error names.
pub fn parse_option_vec3(option: &str, s: &str) -> Result<Vector3<f64>> {
    parse_vec3(s).with_context(|| option.to_string())
}

/// Default working directory path helper for tests.
pub fn temp_path(name: &str) -> PathBuf {
    std::env::temp_dir().join(name)
}
