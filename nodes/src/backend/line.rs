//! The `line` backend: an instrument bridged by a few lines of any language, over a
//! newline-delimited text protocol on TCP (`device: tcp://HOST:PORT`) or a serial port or pty
//! (`device: /dev/ttyUSB0`, set up beforehand, e.g. with `stty`). The node asks, the bridge
//! answers one line per request; numbers in SI units, `.` as the decimal point.
//!
//! ```text
//! node -> bridge                       bridge -> node
//! INFO?                                INFO wavelength_vac_m=6.329912e-7 compensated=1 instrument=XL-80
//!                                           [assumed_index=1.0] [air_equation=ciddor|edlen]
//! BEAM STATION BEAM                    OK           (interferometer: a new beam, zero the count
//!                                                    at the next reading)
//! STATION STATION                      OK           (tracer: set up at a new station)
//! READ T_NS POINT POSITION_ID          R VALUE_M SIGNAL [BROKEN]     a reading latched for the
//!                                      WAIT                          trigger at T_NS (POINT and
//!                                                                    POSITION_ID are `-` for a
//!                                                                    free-running sample); WAIT:
//!                                                                    not yet, ask again;
//!                                                                    SIGNAL 0..1; BROKEN 1 if
//!                                                                    the count was lost before it
//! ENV?                                 ENV [air_temp_c=..] [air_pressure_pa=..] [air_rh_pct=..]
//!                                          [air_co2_ppm=..] [machine_temp_c=..] [NAME_c=..]
//! (anything)                           ERR TEXT     the request failed: the node stops, naming
//!                                                   the device, the request and TEXT
//! ```

use super::{EnvironmentSample, InstrumentInfo, InterferometerBackend, LengthReading, TracerBackend};
use crate::backend::EnvironmentBackend;
use anyhow::{anyhow, bail, Context as _, Result};
use std::io::{BufRead, BufReader, Write};
use std::time::Duration;

/// One connection to a bridge: a request line out, a reply line back.
pub struct LineLink {
    device: String,
    reader: Box<dyn BufRead + Send>,
    writer: Box<dyn Write + Send>,
}

impl LineLink {
    /// Connects to `tcp://HOST:PORT` or opens a device path; `timeout` bounds each reply.
    pub fn open(device: &str, timeout: Duration) -> Result<LineLink> {
        let (reader, writer): (Box<dyn BufRead + Send>, Box<dyn Write + Send>) = if let Some(addr) =
            device.strip_prefix("tcp://")
        {
            let s = std::net::TcpStream::connect(addr).with_context(|| format!("device {device}: cannot connect"))?;
            s.set_read_timeout(Some(timeout))?;
            s.set_nodelay(true)?;
            (Box::new(BufReader::new(s.try_clone()?)), Box::new(s))
        } else {
            let f = std::fs::OpenOptions::new().read(true).write(true).open(device).with_context(|| {
                format!("device {device}: cannot open (a tcp://HOST:PORT address or a serial/pty path)")
            })?;
            (Box::new(BufReader::new(f.try_clone()?)), Box::new(f))
        };
        Ok(LineLink { device: device.to_string(), reader, writer })
    }

    /// Sends `request` and returns the reply's words; `ERR ...` becomes an error.
    pub fn request(&mut self, request: &str) -> Result<Vec<String>> {
        writeln!(self.writer, "{request}")
            .and_then(|_| self.writer.flush())
            .with_context(|| format!("device {}: cannot send {request:?}", self.device))?;
        let mut line = String::new();
        let n = self
            .reader
            .read_line(&mut line)
            .with_context(|| format!("device {}: no reply to {request:?}", self.device))?;
        if n == 0 {
            bail!("device {}: closed the connection instead of replying to {request:?}", self.device);
        }
        let words: Vec<String> = line.split_whitespace().map(str::to_string).collect();
        if words.first().is_some_and(|w| w == "ERR") {
            bail!("device {}: {request:?} failed: {}", self.device, words[1..].join(" "));
        }
        Ok(words)
    }

    fn bad_reply(&self, request: &str, words: &[String], expected: &str) -> anyhow::Error {
        anyhow!(
            "device {}: reply to {request:?} is {:?}, expected {expected} (protocol: volcal_nodes::backend::line)",
            self.device,
            words.join(" ")
        )
    }

    /// `KEY=VALUE` words after the reply's keyword `head`.
    fn fields(&self, request: &str, words: &[String], head: &str) -> Result<Vec<(String, String)>> {
        if words.first().map(String::as_str) != Some(head) {
            return Err(self.bad_reply(request, words, &format!("{head} KEY=VALUE ...")));
        }
        words[1..]
            .iter()
            .map(|w| {
                w.split_once('=')
                    .map(|(k, v)| (k.to_string(), v.to_string()))
                    .ok_or_else(|| self.bad_reply(request, words, &format!("{head} KEY=VALUE ...")))
            })
            .collect()
    }

    fn number(&self, request: &str, words: &[String], what: &str, text: &str) -> Result<f64> {
        text.parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| self.bad_reply(request, words, &format!("a number for {what} (got {text:?})")))
    }

    /// `INFO?`: what the instrument's readings are.
    fn info(&mut self) -> Result<InstrumentInfo> {
        let req = "INFO?";
        let words = self.request(req)?;
        let mut info = InstrumentInfo {
            instrument: self.device.clone(),
            wavelength_vac_m: f64::NAN,
            compensated: true,
            assumed_index: 1.0,
            air_equation: "ciddor".into(),
        };
        for (k, v) in self.fields(req, &words, "INFO")? {
            match k.as_str() {
                "instrument" => info.instrument = v,
                "wavelength_vac_m" => info.wavelength_vac_m = self.number(req, &words, &k, &v)?,
                "compensated" => info.compensated = v == "1" || v == "true",
                "assumed_index" => info.assumed_index = self.number(req, &words, &k, &v)?,
                "air_equation" => info.air_equation = v,
                _ => log::warn!("device {}: INFO field {k} is not known, ignored", self.device),
            }
        }
        if !(info.wavelength_vac_m > 0.0) {
            return Err(self.bad_reply(req, &words, "INFO with wavelength_vac_m=..."));
        }
        Ok(info)
    }

    /// `READ`: a length, or `None` on `WAIT`.
    fn read(&mut self, at_ns: i64, point: Option<u32>, position_id: Option<u64>) -> Result<Option<LengthReading>> {
        let dash = |x: Option<String>| x.unwrap_or_else(|| "-".into());
        let req =
            format!("READ {at_ns} {} {}", dash(point.map(|p| p.to_string())), dash(position_id.map(|p| p.to_string())));
        let words = self.request(&req)?;
        match words.first().map(String::as_str) {
            Some("WAIT") => Ok(None),
            Some("R") if words.len() == 3 || words.len() == 4 => Ok(Some(LengthReading {
                value_m: self.number(&req, &words, "VALUE_M", &words[1])?,
                signal_strength: self.number(&req, &words, "SIGNAL", &words[2])?,
                beam_broken: words.get(3).is_some_and(|b| b == "1"),
            })),
            _ => Err(self.bad_reply(&req, &words, "R VALUE_M SIGNAL [BROKEN] or WAIT")),
        }
    }

    /// A request whose reply is `OK`.
    fn command(&mut self, req: &str) -> Result<()> {
        let words = self.request(req)?;
        if words.first().map(String::as_str) != Some("OK") {
            return Err(self.bad_reply(req, &words, "OK"));
        }
        Ok(())
    }
}

/// Opens the link named by the node's `device` parameter (`reply_timeout_s`, default 2 s).
pub fn open_from_args(args: &crate::ros::NodeArgs) -> Result<LineLink> {
    let device: String = args.require("device")?;
    let timeout: f64 = args.get_or("reply_timeout_s", 2.0)?;
    if !(timeout > 0.0) {
        bail!("parameter reply_timeout_s: must be positive, got {timeout}");
    }
    LineLink::open(&device, Duration::from_secs_f64(timeout))
}

/// What the node learnt (a beam, a station) and tells the bridge with its next reading: the
/// backend traits' `new_beam`/`new_station` cannot fail, a request can.
struct Announced<T> {
    latest: Option<T>,
    told: Option<T>,
}

impl<T: Copy + PartialEq> Announced<T> {
    fn new() -> Self {
        Announced { latest: None, told: None }
    }

    /// Sends `request(latest)` unless the bridge already has it.
    fn tell(&mut self, link: &mut LineLink, request: impl Fn(T) -> String) -> Result<()> {
        if let Some(x) = self.latest.filter(|x| Some(*x) != self.told) {
            link.command(&request(x))?;
            self.told = Some(x);
        }
        Ok(())
    }
}

/// An interferometer behind a bridge.
pub struct LineInterferometer {
    link: LineLink,
    info: InstrumentInfo,
    /// The beam (station, beam) the deflector announced.
    beam: Announced<(u32, u32)>,
}

impl LineInterferometer {
    pub fn new(mut link: LineLink) -> Result<LineInterferometer> {
        let info = link.info()?;
        Ok(LineInterferometer { link, info, beam: Announced::new() })
    }
}

impl InterferometerBackend for LineInterferometer {
    fn info(&self) -> InstrumentInfo {
        self.info.clone()
    }
    fn new_beam(&mut self, station: u32, beam: u32) {
        self.beam.latest = Some((station, beam));
    }
    fn read(&mut self, at_ns: i64, point: Option<u32>, position_id: Option<u64>) -> Result<Option<LengthReading>> {
        self.beam.tell(&mut self.link, |(s, b)| format!("BEAM {s} {b}"))?;
        self.link.read(at_ns, point, position_id)
    }
}

/// A laser tracer behind a bridge.
pub struct LineTracer {
    link: LineLink,
    info: InstrumentInfo,
    station: Announced<u32>,
}

impl LineTracer {
    pub fn new(mut link: LineLink) -> Result<LineTracer> {
        let info = link.info()?;
        Ok(LineTracer { link, info, station: Announced::new() })
    }
}

impl TracerBackend for LineTracer {
    fn info(&self) -> InstrumentInfo {
        self.info.clone()
    }
    fn new_station(&mut self, station: u32) {
        self.station.latest = Some(station);
    }
    fn read(&mut self, at_ns: i64, point: Option<u32>, position_id: Option<u64>) -> Result<Option<LengthReading>> {
        self.station.tell(&mut self.link, |s| format!("STATION {s}"))?;
        self.link.read(at_ns, point, position_id)
    }
}

/// Environment sensors behind a bridge.
pub struct LineEnvironment {
    pub link: LineLink,
}

impl EnvironmentBackend for LineEnvironment {
    fn read(&mut self, _now_ns: i64) -> Result<EnvironmentSample> {
        let req = "ENV?";
        let words = self.link.request(req)?;
        let mut s = EnvironmentSample::default();
        let mut air = volcal::environment::Air::standard();
        let mut has_air = false;
        for (k, v) in self.link.fields(req, &words, "ENV")? {
            let x = self.link.number(req, &words, &k, &v)?;
            match k.as_str() {
                "air_temp_c" => (air.temp_c, has_air) = (x, true),
                "air_pressure_pa" => (air.pressure_pa, has_air) = (x, true),
                "air_rh_pct" => (air.humidity_pct, has_air) = (x, true),
                "air_co2_ppm" => (air.co2_ppm, has_air) = (x, true),
                "machine_temp_c" => s.machine_temp_c = Some(x),
                other => match other.strip_suffix("_c") {
                    Some(name) => s.materials.push((name.to_string(), x)),
                    None => return Err(self.link.bad_reply(req, &words, "known ENV fields (air_temp_c, ..., NAME_c)")),
                },
            }
        }
        s.air = has_air.then_some(air);
        Ok(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{BufRead, BufReader, Write};

    /// A bridge in a thread answering from a script of (expected request, reply).
    fn bridge(script: Vec<(&'static str, &'static str)>) -> String {
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = l.local_addr().unwrap();
        std::thread::spawn(move || {
            let (s, _) = l.accept().unwrap();
            let mut r = BufReader::new(s.try_clone().unwrap());
            let mut w = s;
            for (want, reply) in script {
                let mut line = String::new();
                r.read_line(&mut line).unwrap();
                assert_eq!(line.trim_end(), want);
                writeln!(w, "{reply}").unwrap();
            }
        });
        format!("tcp://{addr}")
    }

    #[test]
    fn an_interferometer_over_tcp() {
        let dev = bridge(vec![
            ("INFO?", "INFO wavelength_vac_m=6.329912e-7 compensated=1 instrument=XL-80"),
            ("BEAM 0 3", "OK"),
            ("READ 100 4 77", "R 0.12345 0.9"),
            ("READ 200 - -", "WAIT"),
            ("READ 300 - -", "R 0.2 0.01 1"),
            ("READ 400 5 78", "ERR laser not warmed up"),
        ]);
        let mut i = LineInterferometer::new(LineLink::open(&dev, Duration::from_secs(2)).unwrap()).unwrap();
        assert_eq!(i.info().instrument, "XL-80");
        i.new_beam(0, 3);
        i.new_beam(0, 3);
        let r = i.read(100, Some(4), Some(77)).unwrap().unwrap();
        assert_eq!((r.value_m, r.signal_strength, r.beam_broken), (0.12345, 0.9, false));
        assert!(i.read(200, None, None).unwrap().is_none());
        assert!(i.read(300, None, None).unwrap().unwrap().beam_broken);
        let e = i.read(400, Some(5), Some(78)).unwrap_err().to_string();
        assert!(e.contains(&dev) && e.contains("READ 400 5 78") && e.contains("laser not warmed up"), "{e}");
    }

    #[test]
    fn bad_replies_are_named() {
        let dev = bridge(vec![("INFO?", "INFO wavelength_vac_m=6.33e-7"), ("READ 1 - -", "R abc 0.5")]);
        let mut i = LineInterferometer::new(LineLink::open(&dev, Duration::from_secs(2)).unwrap()).unwrap();
        let e = i.read(1, None, None).unwrap_err().to_string();
        assert!(e.contains("\"R abc 0.5\"") && e.contains("VALUE_M"), "{e}");
        let dev = bridge(vec![("ENV?", "ENV air_temp_c=20.5 machine_temp_c=20.1 table_c=19.9")]);
        let mut env = LineEnvironment { link: LineLink::open(&dev, Duration::from_secs(2)).unwrap() };
        let s = env.read(0).unwrap();
        assert_eq!(s.air.unwrap().temp_c, 20.5);
        assert_eq!(s.machine_temp_c, Some(20.1));
        assert_eq!(s.materials, vec![("table".to_string(), 19.9)]);
        assert!(LineLink::open("tcp://127.0.0.1:1", Duration::from_secs(1)).is_err());
    }
}
