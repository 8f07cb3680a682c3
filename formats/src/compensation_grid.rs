//! Reads a `volcal export --format grid` table (`grid.csv`) back as the correction a grid
//! compensating controller applies: `-error` at each node (the file holds the error,
//! `actual - (commanded + probe offset)`, in micrometres, at positions in millimetres).
//!
//! Used by the closed loop (`volcal simulate --compensation DIR`), so it reads the file as a
//! controller would, from the text alone: a complete grid, `x` varying fastest, then `y`, then
//! `z`, nodes ascending on each axis.

use anyhow::{bail, Context, Result};
use std::path::Path;
use volcal_sim::controller::GridCompensation;

/// The header that `volcal export --format grid` writes.
pub const GRID_HEADER: &str = "x_mm,y_mm,z_mm,ex_um,ey_um,ez_um,u95_um";

/// Reads `path` (a `grid.csv`) as the controller's correction.
pub fn read_grid(path: &Path) -> Result<GridCompensation> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let at = |line: usize| format!("{} line {}", path.display(), line);
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim())).filter(|(_, l)| !l.is_empty());
    match lines.next() {
        Some((_, h)) if h == GRID_HEADER => {}
        Some((n, h)) => bail!("{}: header {h:?}, expected {GRID_HEADER:?}", at(n)),
        None => bail!("{}: empty file", path.display()),
    }
    let mut rows: Vec<(usize, [f64; 6])> = Vec::new();
    for (n, l) in lines {
        let v: Vec<&str> = l.split(',').collect();
        if v.len() != 7 {
            bail!("{}: {} fields, expected 7 ({GRID_HEADER})", at(n), v.len());
        }
        let mut r = [0.0; 6];
        for (k, f) in v[..6].iter().enumerate() {
            r[k] = f.trim().parse::<f64>().ok().filter(|x| x.is_finite()).with_context(|| {
                format!(
                    "{}: field {} ({}) is not a number: {f:?}",
                    at(n),
                    k + 1,
                    &GRID_HEADER.split(',').nth(k).unwrap_or("")
                )
            })?;
        }
        rows.push((n, r));
    }
    // The axes: the distinct node positions in the order of the file.
    let axis = |k: usize| -> Vec<f64> {
        let mut v: Vec<f64> = rows.iter().map(|(_, r)| r[k]).collect();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v
    };
    let axes_mm = [axis(0), axis(1), axis(2)];
    let [nx, ny, nz] = [0, 1, 2].map(|a| axes_mm[a].len());
    if rows.len() != nx * ny * nz || rows.is_empty() {
        bail!("{}: {} rows do not form a complete grid of {nx} x {ny} x {nz} nodes", path.display(), rows.len());
    }
    let mut correction_m = Vec::with_capacity(rows.len());
    for (idx, (n, r)) in rows.iter().enumerate() {
        let (i, j, k) = (idx % nx, (idx / nx) % ny, idx / (nx * ny));
        if r[0] != axes_mm[0][i] || r[1] != axes_mm[1][j] || r[2] != axes_mm[2][k] {
            bail!(
                "{}: node ({}, {}, {}) mm out of order (x varies fastest, then y, then z, each ascending)",
                at(*n),
                r[0],
                r[1],
                r[2]
            );
        }
        correction_m.push([-r[3] * 1e-6, -r[4] * 1e-6, -r[5] * 1e-6]);
    }
    Ok(GridCompensation { axes_m: axes_mm.map(|v| v.into_iter().map(|x| x * 1e-3).collect()), correction_m })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(text: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("volcal-grid-{}-{}", std::process::id(), text.len()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("grid.csv");
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn reads_the_correction_as_minus_the_error() {
        let mut t = format!("{GRID_HEADER}\n");
        for z in [0, 100] {
            for y in [0, 100] {
                for x in [0, 50, 100] {
                    t.push_str(&format!("{x},{y},{z},{},2,-3,0.5\n", x as f64 / 100.0));
                }
            }
        }
        let g = read_grid(&write(&t)).unwrap();
        assert_eq!(g.axes_m[0], vec![0.0, 0.05, 0.1]);
        assert_eq!(g.correction_m.len(), 12);
        assert_eq!(g.correction_m[2], [-1e-6, -2e-6, 3e-6]);
    }

    #[test]
    fn says_which_line_is_wrong() {
        let e = read_grid(&write(&format!("{GRID_HEADER}\n0,0,0,1,2,x,0\n"))).unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("ez_um"), "{e}");
        let e = read_grid(&write(&format!("{GRID_HEADER}\n0,0,0,1,2,3,0\n1,0,0,1,2,3,0\n0,1,0,1,2,3,0\n")))
            .unwrap_err()
            .to_string();
        assert!(e.contains("complete grid"), "{e}");
        let e = read_grid(&write("x,y\n")).unwrap_err().to_string();
        assert!(e.contains("line 1") && e.contains("header"), "{e}");
    }
}
