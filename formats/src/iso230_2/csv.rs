//! The runs file of `volcal iso230-2`: one row per approach, header required, `#` lines are
//! comments, blank lines skipped.
//!
//! ```text
//! target_mm,run,direction,deviation_um
//! 0,1,+,0.8
//! 0,1,-,-1.9
//! ```
//!
//! `direction` is `+` (approached moving in the positive direction, ISO ↑) or `-` (↓);
//! `deviation_um` is measured minus commanded position in micrometres. The header must be exactly
//! these four columns in this order, so that a file in another unit or sign convention is not
//! read silently. Every problem names the file, the line and the column.

use super::{Approach, Direction, Runs};
use anyhow::{bail, Context, Result};
use std::io::BufRead;
use std::path::Path;

/// The header, column by column.
pub const HEADER: [&str; 4] = ["target_mm", "run", "direction", "deviation_um"];

/// Reads a runs file.
pub fn read(path: &Path) -> Result<Runs> {
    let f = std::fs::File::open(path).with_context(|| format!("cannot open runs file {}", path.display()))?;
    read_from(std::io::BufReader::new(f), &path.display().to_string())
}

/// Reads runs from any reader; `name` is used in messages.
pub fn read_from(reader: impl BufRead, name: &str) -> Result<Runs> {
    let mut header_seen = false;
    let mut approaches = Vec::new();
    for (k, line) in reader.lines().enumerate() {
        let lineno = k + 1;
        let line = line.with_context(|| format!("{name} line {lineno}: cannot read (not UTF-8 text?)"))?;
        // A byte-order mark (spreadsheets write one) is not part of the first column's name.
        let t = line.trim().trim_start_matches('\u{feff}');
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = t.split(',').map(str::trim).collect();
        if !header_seen {
            if fields != HEADER {
                bail!("{name} line {lineno}: header {t:?}, expected {}", HEADER.join(","));
            }
            header_seen = true;
            continue;
        }
        if fields.len() != HEADER.len() {
            bail!("{name} line {lineno}: {} fields, expected {} ({})", fields.len(), HEADER.len(), HEADER.join(","));
        }
        approaches.push(parse_row(&fields, lineno).map_err(|e| anyhow::anyhow!("{name} line {lineno}: {e}"))?);
    }
    if !header_seen {
        bail!("{name}: no header line (expected {})", HEADER.join(","));
    }
    if approaches.is_empty() {
        bail!("{name}: a header but no approaches");
    }
    Ok(Runs { name: name.to_string(), approaches })
}

fn parse_row(f: &[&str], line: usize) -> Result<Approach, String> {
    let num = |i: usize| -> Result<f64, String> {
        let v: f64 = f[i].parse().map_err(|_| format!("column {}: {:?} is not a number", HEADER[i], f[i]))?;
        if !v.is_finite() {
            return Err(format!("column {}: {:?} is not a finite number", HEADER[i], f[i]));
        }
        Ok(v)
    };
    let run = f[1].parse::<u32>().map_err(|_| format!("column run: {:?} is not a non-negative integer", f[1]))?;
    let direction = match f[2] {
        "+" => Direction::Up,
        "-" => Direction::Down,
        s => return Err(format!("column direction: {s:?} (expected + or -)")),
    };
    // Beyond these no positioning test lies (10 km of travel, a deviation of a metre); squared
    // and summed, larger values overflowed into infinite and null figures.
    let (target_mm, deviation_um) = (num(0)?, num(3)?);
    if target_mm.abs() > 1e7 {
        return Err(format!("column {}: {target_mm:e} mm is beyond 10 km", HEADER[0]));
    }
    if deviation_um.abs() > 1e6 {
        return Err(format!("column {}: {deviation_um:e} um is beyond a metre", HEADER[3]));
    }
    Ok(Approach { target_mm, run, direction, deviation_um, line })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str) -> String {
        format!("{:#}", read_from(text.as_bytes(), "runs.csv").unwrap_err())
    }

    #[test]
    fn names_file_line_and_column() {
        assert!(err("target_mm,run,dir,deviation_um\n").contains("runs.csv line 1: header"));
        let e = err("# c\ntarget_mm,run,direction,deviation_um\n0,1,+,abc\n");
        assert!(e.contains("runs.csv line 3: column deviation_um: \"abc\" is not a number"), "{e}");
        assert!(err("target_mm,run,direction,deviation_um\n0,1,up,1\n").contains("line 2: column direction"));
        assert!(err("target_mm,run,direction,deviation_um\n0,1,+\n").contains("line 2: 3 fields"));
        assert!(err("target_mm,run,direction,deviation_um\n0,1,+,inf\n").contains("not a finite number"));
        // Finite but beyond any positioning test: squared and summed they overflowed.
        assert!(err("target_mm,run,direction,deviation_um\n0,1,+,1e200\n").contains("line 2: column deviation_um"));
        assert!(err("target_mm,run,direction,deviation_um\n1e300,1,+,1\n").contains("line 2: column target_mm"));
        assert!(err("").contains("no header"));
    }
}
