//! The plot of `volcal iso230-2 --plot`: deviation against target, in the layout of the
//! standard's figures (ISO 230-2:2014 figure 2 style): every run's point, the mean line of each
//! direction, the band x̄ ± 2s of each direction, and the axis figures in the title. The exact
//! numbers are in the printed report; the plot is for seeing the shape (slope, periodic error,
//! reversal, a run that went astray).

use crate::raster::{text_width, Raster, Rgb, GLYPH_HEIGHT};
use anyhow::Result;
use std::path::Path;
use volcal_formats::iso230_2::{Direction, Evaluation, Runs};

const WIDTH: u32 = 1000;
const HEIGHT: u32 = 620;
const LEFT: i32 = 110;
const RIGHT: i32 = 30;
const TOP: i32 = 80;
const BOTTOM: i32 = 80;
const SCALE: i32 = 2;

const WHITE: Rgb = [255, 255, 255];
const BLACK: Rgb = [20, 20, 20];
const GRID: Rgb = [205, 205, 205];
const UP: Rgb = [25, 80, 200];
const DOWN: Rgb = [200, 45, 30];

/// Draws the plot of an evaluation and the runs it came from.
pub fn plot(e: &Evaluation, runs: &Runs, path: &Path) -> Result<()> {
    let mut r = Raster::new(WIDTH, HEIGHT, WHITE);
    let (x_lo, x_hi) = padded(e.targets.iter().map(|t| t.target_mm), 0.03, 1.0);
    let ys = runs.approaches.iter().map(|a| a.deviation_um).chain(e.targets.iter().flat_map(|t| {
        [t.up.mean_um + 2.0 * t.up.s_um, t.up.mean_um - 2.0 * t.up.s_um]
            .into_iter()
            .chain([t.down.mean_um + 2.0 * t.down.s_um, t.down.mean_um - 2.0 * t.down.s_um])
    }));
    let (y_lo, y_hi) = padded(ys.chain([0.0]), 0.08, 1e-3);
    let (px0, px1, py0, py1) = (LEFT, WIDTH as i32 - RIGHT, HEIGHT as i32 - BOTTOM, TOP);
    let sx = |x: f64| px0 + ((x - x_lo) / (x_hi - x_lo) * (px1 - px0) as f64).round() as i32;
    let sy = |y: f64| py0 + ((y - y_lo) / (y_hi - y_lo) * (py1 - py0) as f64).round() as i32;

    // Grid and tick labels.
    for (v, label) in ticks(y_lo, y_hi) {
        let y = sy(v);
        r.dashed_hline(px0, px1, y, GRID);
        r.line((px0 - 6, y), (px0, y), 1, BLACK);
        r.text(px0 - 10 - text_width(&label, SCALE), y - GLYPH_HEIGHT * SCALE / 2, &label, SCALE, BLACK);
    }
    for (v, label) in ticks(x_lo, x_hi) {
        let x = sx(v);
        r.line((x, py0), (x, py0 + 6), 1, BLACK);
        r.text(x - text_width(&label, SCALE) / 2, py0 + 12, &label, SCALE, BLACK);
    }

    // Bands x̄ ± 2s, linearly between targets, blended so both stay visible where they overlap.
    for (dir, colour) in [(Direction::Up, UP), (Direction::Down, DOWN)] {
        let band: Vec<(f64, f64, f64)> = e
            .targets
            .iter()
            .map(|t| {
                let w = if dir == Direction::Up { t.up } else { t.down };
                (t.target_mm, w.mean_um - 2.0 * w.s_um, w.mean_um + 2.0 * w.s_um)
            })
            .collect();
        for (k, pair) in band.windows(2).enumerate() {
            let ((xa, la, ua), (xb, lb, ub)) = (pair[0], pair[1]);
            // Each column once: a segment's last column is the next one's first.
            let end = if k + 2 == band.len() { sx(xb) } else { sx(xb) - 1 };
            for x in sx(xa)..=end {
                let f = if sx(xb) == sx(xa) { 0.0 } else { (x - sx(xa)) as f64 / (sx(xb) - sx(xa)) as f64 };
                let (lo, hi) = (sy(la + f * (lb - la)), sy(ua + f * (ub - ua)));
                for y in hi.min(lo)..=hi.max(lo) {
                    r.blend(x, y, colour, 0.18);
                }
            }
        }
        // A lone target has no band between targets: an error bar instead.
        if let [(x, lo, hi)] = band[..] {
            r.line((sx(x), sy(lo)), (sx(x), sy(hi)), 3, colour);
        }
    }

    // Zero line and frame.
    r.line((px0, sy(0.0)), (px1, sy(0.0)), 1, [120, 120, 120]);
    r.line((px0, py0), (px1, py0), 1, BLACK);
    r.line((px0, py1), (px1, py1), 1, BLACK);
    r.line((px0, py0), (px0, py1), 1, BLACK);
    r.line((px1, py0), (px1, py1), 1, BLACK);

    // Mean lines, then every run's point (up a little left of the target, down a little right).
    for (dir, colour) in [(Direction::Up, UP), (Direction::Down, DOWN)] {
        let means: Vec<(i32, i32)> = e
            .targets
            .iter()
            .map(|t| (sx(t.target_mm), sy(if dir == Direction::Up { t.up.mean_um } else { t.down.mean_um })))
            .collect();
        for pair in means.windows(2) {
            r.line(pair[0], pair[1], 3, colour);
        }
    }
    for a in &runs.approaches {
        let (colour, dx) = if a.direction == Direction::Up { (UP, -4) } else { (DOWN, 4) };
        let (x, y) = (sx(a.target_mm) + dx, sy(a.deviation_um));
        r.fill_rect(x - 3, y - 3, x + 3, y + 3, WHITE);
        r.fill_rect(x - 2, y - 2, x + 2, y + 2, colour);
    }

    // Title, axis names, legend.
    let f = &e.figures;
    let d = volcal_formats::iso230_2::report::decimals(f);
    let title = format!("ISO 230-2 (UM):  A {:.d$}  R {:.d$}  B {:.d$}  E {:.d$}  M {:.d$}", f.A, f.R, f.B, f.E, f.M);
    r.text(16, 16, &title, SCALE, BLACK);
    r.text(LEFT, 46, "DEVIATION (UM)", SCALE, BLACK);
    let xl = "TARGET (MM)";
    r.text((px0 + px1 - text_width(xl, SCALE)) / 2, HEIGHT as i32 - 36, xl, SCALE, BLACK);
    let mut lx = px1 - 560;
    for (label, colour) in [("UP (+): RUNS, MEAN, +-2S", UP), ("DOWN (-)", DOWN)] {
        r.fill_rect(lx, 48, lx + 18, 60, colour);
        lx += 26 + r.text(lx + 26, 48, label, SCALE, BLACK) + 24;
    }
    r.write_png(path)
}

/// Range of the values widened by `pad` of its span on each side (or by `min_half` when all
/// values are equal), so nothing sits on the frame.
fn padded(values: impl Iterator<Item = f64>, pad: f64, min_half: f64) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let span = hi - lo;
    if !(span > 0.0) {
        return (lo - min_half, hi + min_half);
    }
    (lo - pad * span, hi + pad * span)
}

/// Ticks at 1, 2 or 5 times a power of ten, about six over the range, with labels that have just
/// the decimals the step needs.
fn ticks(lo: f64, hi: f64) -> Vec<(f64, String)> {
    let raw = (hi - lo) / 6.0;
    let p = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0].into_iter().map(|m| m * p).find(|s| *s >= raw).unwrap_or(10.0 * p);
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last)
        .map(|k| {
            let v = k as f64 * step;
            let s = format!("{v:.decimals$}");
            (v, if s.trim_start_matches('-').chars().all(|c| c == '0' || c == '.') { "0".into() } else { s })
        })
        .collect()
}
