//! Campaign interchange format (CSV, DESIGN.md section 4).
//!
//! One row per acquired point, header required, `#` lines are comments. Comment lines of the
//! form `# key: value` carry campaign metadata:
//!
//! ```text
//! # volcal campaign v1
//! # wavelength_vac_m: 6.3299121258e-7
//! # readings: uncompensated          (or: compensated, the default)
//! # assumed_index: 1.0               (index used by the instrument for uncompensated readings)
//! # air_equation: ciddor             (or: edlen)
//! kind,station,beam,t_s,l_m,x_m,y_m,z_m,px_m,py_m,pz_m[,air_temp_c,air_pressure_pa,air_rh_pct,machine_temp_c,vx_mps,vy_mps,vz_mps,beam_broken]
//! ```
//!
//! Unknown columns are allowed and ignored (the reader reports which). Every problem names the
//! file, the line and the column.

use anyhow::{bail, Context, Result};
use nalgebra::{Point3, Vector3};
use std::fmt::Write as _;
use std::io::{BufRead, Write};
use std::path::Path;
use volcal::campaign::{Campaign, CampaignMeta, Compensation, ObsKind, Reading};
use volcal::environment::{Air, AirIndexEquation};

/// Required columns, in the order written.
pub const REQUIRED: [&str; 11] = ["kind", "station", "beam", "t_s", "l_m", "x_m", "y_m", "z_m", "px_m", "py_m", "pz_m"];
/// Optional columns understood by the reader.
pub const OPTIONAL: [&str; 8] =
    ["air_temp_c", "air_pressure_pa", "air_rh_pct", "machine_temp_c", "vx_mps", "vy_mps", "vz_mps", "beam_broken"];

/// A campaign read from a file, with what the reader noticed.
#[derive(Debug)]
pub struct ReadCampaign {
    pub campaign: Campaign,
    pub ignored_columns: Vec<String>,
}

/// Reads a campaign CSV file.
pub fn read(path: &Path) -> Result<ReadCampaign> {
    let f = std::fs::File::open(path).with_context(|| format!("cannot open campaign {}", path.display()))?;
    read_from(std::io::BufReader::new(f), &path.display().to_string())
}

/// Reads a campaign from any reader; `name` is used in messages.
pub fn read_from(reader: impl BufRead, name: &str) -> Result<ReadCampaign> {
    let mut meta = CampaignMeta::default();
    let mut header: Option<Vec<String>> = None;
    let mut cols = Columns::default();
    let mut readings = Vec::new();
    let mut ignored = Vec::new();
    let mut assumed_index = 1.0;
    let mut uncompensated = false;
    for (k, line) in reader.lines().enumerate() {
        let lineno = k + 1;
        let line = line.with_context(|| format!("{name} line {lineno}: cannot read (not UTF-8 text?)"))?;
        let t = line.trim();
        if t.is_empty() {
            continue;
        }
        if let Some(c) = t.strip_prefix('#') {
            if let Some((key, value)) = c.split_once(':') {
                let (key, value) = (key.trim(), value.trim());
                let num = |v: &str| -> Result<f64> {
                    v.parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| {
                        anyhow::anyhow!("{name} line {lineno}: metadata {key}: {v:?} is not a finite number")
                    })
                };
                match key {
                    "wavelength_vac_m" => meta.wavelength_vac_m = num(value)?,
                    "assumed_index" => assumed_index = num(value)?,
                    "readings" => match value {
                        "compensated" => uncompensated = false,
                        "uncompensated" => uncompensated = true,
                        _ => bail!("{name} line {lineno}: metadata readings: {value:?} (expected compensated or uncompensated)"),
                    },
                    "air_equation" => {
                        meta.air_equation = match value {
                            "ciddor" => AirIndexEquation::Ciddor,
                            "edlen" => AirIndexEquation::Edlen,
                            _ => bail!("{name} line {lineno}: metadata air_equation: {value:?} (expected ciddor or edlen)"),
                        }
                    }
                    _ => {}
                }
            }
            continue;
        }
        let fields: Vec<&str> = t.split(',').map(str::trim).collect();
        match &header {
            None => {
                let h: Vec<String> = fields.iter().map(|s| s.to_string()).collect();
                cols = Columns::from_header(&h).map_err(|e| anyhow::anyhow!("{name} line {lineno}: {e}"))?;
                ignored = h
                    .iter()
                    .filter(|c| !REQUIRED.contains(&c.as_str()) && !OPTIONAL.contains(&c.as_str()))
                    .cloned()
                    .collect();
                header = Some(h);
            }
            Some(h) => {
                if fields.len() != h.len() {
                    bail!("{name} line {lineno}: {} fields, the header has {}", fields.len(), h.len());
                }
                readings.push(cols.parse(&fields, lineno).map_err(|e| anyhow::anyhow!("{name} line {lineno}: {e}"))?);
            }
        }
    }
    if header.is_none() {
        bail!("{name}: no header line (expected {})", REQUIRED.join(","));
    }
    if readings.is_empty() {
        bail!("{name}: the campaign has a header but no readings");
    }
    if uncompensated {
        meta.compensation = Compensation::Uncompensated { assumed_index };
    }
    Ok(ReadCampaign { campaign: Campaign { meta, readings }, ignored_columns: ignored })
}

/// Column positions.
#[derive(Default)]
struct Columns {
    req: [usize; 11],
    opt: [Option<usize>; 8],
}

impl Columns {
    fn from_header(h: &[String]) -> Result<Columns, String> {
        let find = |name: &str| h.iter().position(|c| c == name);
        let mut req = [0; 11];
        let missing: Vec<&str> = REQUIRED.iter().filter(|n| find(n).is_none()).cloned().collect();
        if !missing.is_empty() {
            return Err(format!("header lacks column(s) {} (required: {})", missing.join(", "), REQUIRED.join(",")));
        }
        for (i, n) in REQUIRED.iter().enumerate() {
            req[i] = find(n).unwrap();
        }
        let opt = OPTIONAL.map(find);
        let air = [opt[0], opt[1], opt[2]];
        if air.iter().any(|c| c.is_some()) && !air.iter().all(|c| c.is_some()) {
            return Err("air_temp_c, air_pressure_pa and air_rh_pct must be given together".into());
        }
        let vel = [opt[4], opt[5], opt[6]];
        if vel.iter().any(|c| c.is_some()) && !vel.iter().all(|c| c.is_some()) {
            return Err("vx_mps, vy_mps and vz_mps must be given together".into());
        }
        Ok(Columns { req, opt })
    }

    fn parse(&self, f: &[&str], lineno: usize) -> Result<Reading, String> {
        let num = |i: usize, name: &str| -> Result<f64, String> {
            let s = f[i];
            let v: f64 = s.parse().map_err(|_| format!("column {name}: {s:?} is not a number"))?;
            if !v.is_finite() {
                return Err(format!("column {name}: {s:?} is not a finite number"));
            }
            Ok(v)
        };
        let int = |i: usize, name: &str| -> Result<u32, String> {
            f[i].parse::<u32>().map_err(|_| format!("column {name}: {:?} is not a non-negative integer", f[i]))
        };
        let kind = ObsKind::parse(f[self.req[0]])
            .ok_or_else(|| format!("column kind: {:?} (expected beam or range)", f[self.req[0]]))?;
        let optnum = |k: usize| -> Result<Option<f64>, String> {
            match self.opt[k] {
                Some(i) if !f[i].is_empty() => num(i, OPTIONAL[k]).map(Some),
                _ => Ok(None),
            }
        };
        let air = match (optnum(0)?, optnum(1)?, optnum(2)?) {
            (Some(t), Some(p), Some(h)) => Some(Air { temp_c: t, pressure_pa: p, humidity_pct: h, co2_ppm: 450.0 }),
            (None, None, None) => None,
            _ => return Err("air_temp_c, air_pressure_pa and air_rh_pct must all be given or all be empty".into()),
        };
        let velocity = match (optnum(4)?, optnum(5)?, optnum(6)?) {
            (Some(x), Some(y), Some(z)) => Some(Vector3::new(x, y, z)),
            (None, None, None) => None,
            _ => return Err("vx_mps, vy_mps and vz_mps must all be given or all be empty".into()),
        };
        let beam_broken = match self.opt[7] {
            Some(i) => match f[i] {
                "" | "0" | "false" => false,
                "1" | "true" => true,
                s => return Err(format!("column beam_broken: {s:?} (expected 0 or 1)")),
            },
            None => false,
        };
        Ok(Reading {
            kind,
            station: int(self.req[1], "station")?,
            line: int(self.req[2], "beam")?,
            t_s: num(self.req[3], "t_s")?,
            l_m: num(self.req[4], "l_m")?,
            x: Point3::new(num(self.req[5], "x_m")?, num(self.req[6], "y_m")?, num(self.req[7], "z_m")?),
            p: Vector3::new(num(self.req[8], "px_m")?, num(self.req[9], "py_m")?, num(self.req[10], "pz_m")?),
            air,
            machine_temp_c: optnum(3)?,
            velocity,
            beam_broken,
            source_line: lineno,
        })
    }
}

/// Writes a campaign as CSV (full precision; optional columns only when some reading has them).
pub fn write(path: &Path, c: &Campaign) -> Result<()> {
    write_with_notes(path, c, &[])
}

/// [`write`] with `notes` as comment lines of the header (e.g. `injected: latency:...`; readers
/// ignore them).
pub fn write_with_notes(path: &Path, c: &Campaign, notes: &[String]) -> Result<()> {
    let f = std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut w = std::io::BufWriter::new(f);
    write_to(&mut w, c, notes).with_context(|| format!("writing {}", path.display()))?;
    w.flush()?;
    Ok(())
}

/// Writes a campaign to any writer.
pub fn write_to(w: &mut impl Write, c: &Campaign, notes: &[String]) -> Result<()> {
    writeln!(w, "# volcal campaign v1")?;
    for n in notes {
        writeln!(w, "# {n}")?;
    }
    writeln!(w, "# wavelength_vac_m: {}", c.meta.wavelength_vac_m)?;
    match c.meta.compensation {
        Compensation::Compensated => writeln!(w, "# readings: compensated")?,
        Compensation::Uncompensated { assumed_index } => {
            writeln!(w, "# readings: uncompensated")?;
            writeln!(w, "# assumed_index: {assumed_index}")?;
        }
    }
    writeln!(
        w,
        "# air_equation: {}",
        match c.meta.air_equation {
            AirIndexEquation::Ciddor => "ciddor",
            AirIndexEquation::Edlen => "edlen",
        }
    )?;
    let air = c.readings.iter().any(|r| r.air.is_some());
    let temp = c.readings.iter().any(|r| r.machine_temp_c.is_some());
    let vel = c.readings.iter().any(|r| r.velocity.is_some());
    let brk = c.readings.iter().any(|r| r.beam_broken);
    let mut head = REQUIRED.join(",");
    if air {
        head.push_str(",air_temp_c,air_pressure_pa,air_rh_pct");
    }
    if temp {
        head.push_str(",machine_temp_c");
    }
    if vel {
        head.push_str(",vx_mps,vy_mps,vz_mps");
    }
    if brk {
        head.push_str(",beam_broken");
    }
    writeln!(w, "{head}")?;
    let mut line = String::with_capacity(256);
    for r in &c.readings {
        line.clear();
        write!(
            line,
            "{},{},{},{},{},{},{},{},{},{},{}",
            r.kind.name(),
            r.station,
            r.line,
            r.t_s,
            r.l_m,
            r.x.x,
            r.x.y,
            r.x.z,
            r.p.x,
            r.p.y,
            r.p.z
        )?;
        if air {
            match r.air {
                Some(a) => write!(line, ",{},{},{}", a.temp_c, a.pressure_pa, a.humidity_pct)?,
                None => line.push_str(",,,"),
            }
        }
        if temp {
            match r.machine_temp_c {
                Some(t) => write!(line, ",{t}")?,
                None => line.push(','),
            }
        }
        if vel {
            match r.velocity {
                Some(v) => write!(line, ",{},{},{}", v.x, v.y, v.z)?,
                None => line.push_str(",,,"),
            }
        }
        if brk {
            line.push_str(if r.beam_broken { ",1" } else { ",0" });
        }
        writeln!(w, "{line}")?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Campaign {
        let r = |i: usize| Reading {
            kind: ObsKind::Beam,
            station: 0,
            line: 3,
            t_s: i as f64 * 0.5,
            l_m: 0.1 * i as f64 + 1e-7,
            x: Point3::new(0.1 * i as f64, 0.2, -0.3),
            p: Vector3::new(0.0, 0.0, -0.1),
            air: Some(Air { temp_c: 20.1, pressure_pa: 101_300.0, humidity_pct: 45.0, co2_ppm: 450.0 }),
            machine_temp_c: None,
            velocity: None,
            beam_broken: i == 2,
            source_line: 0,
        };
        Campaign {
            meta: CampaignMeta {
                compensation: Compensation::Uncompensated { assumed_index: 1.0 },
                ..Default::default()
            },
            readings: (0..4).map(r).collect(),
        }
    }

    #[test]
    fn round_trip_is_exact() {
        let c = sample();
        let mut buf = Vec::new();
        write_to(&mut buf, &c, &[]).unwrap();
        let back = read_from(&buf[..], "mem").unwrap().campaign;
        assert_eq!(back.meta, c.meta);
        for (a, b) in back.readings.iter().zip(&c.readings) {
            assert_eq!(Reading { source_line: 0, ..a.clone() }, *b);
        }
    }

    #[test]
    fn errors_name_line_and_column() {
        let text = "kind,station,beam,t_s,l_m,x_m,y_m,z_m,px_m,py_m,pz_m,extra\nbeam,0,1,0,0,0,0,0,0,0,0,x\nbeam,0,1,0,abc,0,0,0,0,0,0,x\n";
        let e = read_from(text.as_bytes(), "c.csv").unwrap_err().to_string();
        assert!(e.contains("c.csv line 3") && e.contains("l_m"), "{e}");
        let e = read_from(
            "kind,station,beam,t_s,l_m,x_m,y_m,z_m,px_m,py_m,pz_m\nbeam,0,1,0,NaN,0,0,0,0,0,0\n".as_bytes(),
            "c.csv",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("line 2") && e.contains("finite"), "{e}");
        let e =
            read_from("kind,station,beam,t_s,l_m,x_m,y_m,z_m,px_m,py_m\n".as_bytes(), "c.csv").unwrap_err().to_string();
        assert!(e.contains("pz_m"), "{e}");
        let e = read_from(
            "kind,station,beam,t_s,l_m,x_m,y_m,z_m,px_m,py_m,pz_m\nlaser,0,1,0,0,0,0,0,0,0,0\n".as_bytes(),
            "c.csv",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("kind"), "{e}");
        let e = read_from("kind,station,beam,t_s,l_m,x_m,y_m,z_m,px_m,py_m,pz_m\nbeam,0,1,0,0,0\n".as_bytes(), "c.csv")
            .unwrap_err()
            .to_string();
        assert!(e.contains("6 fields"), "{e}");
        let e = read_from("# only a comment\n".as_bytes(), "c.csv").unwrap_err().to_string();
        assert!(e.contains("no header"), "{e}");
        let ok = read_from(
            "kind,station,beam,t_s,l_m,x_m,y_m,z_m,px_m,py_m,pz_m,extra\nbeam,0,1,0,0,0,0,0,0,0,0,x\n".as_bytes(),
            "c.csv",
        )
        .unwrap();
        assert_eq!(ok.ignored_columns, vec!["extra".to_string()]);
    }
}
