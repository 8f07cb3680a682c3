//! Reading a bag, including one whose recorder was killed: messages are read in file order up
//! to the last complete chunk, and the summary says what was recovered.

use super::metadata::{MetadataFile, FILE_NAME};
use anyhow::{anyhow, bail, Context, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use volcal_msgs::cdr;
use volcal_msgs::RosMessage;

/// Largest record (and chunk, uncompressed) the reader accepts beyond the file's own size:
/// 1 GiB. The recorder's chunks are a few megabytes. The MCAP reader trusts a record's stated
/// length: without a limit a damaged one overflowed its arithmetic (a panic) or had it reserve
/// an exabyte (an abort) before any check.
const RECORD_LIMIT: u64 = 1 << 30;

/// The records of one MCAP file in order, chunks unpacked: `mcap`'s linear reader with each
/// record's stated length bounded ([`RECORD_LIMIT`], or the file's size if larger) and each
/// chunk's CRC checked before its records are parsed, so that damaged bytes are an error, not a
/// crash. The end magic is not required (a killed recorder leaves none).
struct Records<'a> {
    buf: &'a [u8],
    reader: mcap::sans_io::LinearReader,
}

impl<'a> Records<'a> {
    fn new(buf: &'a [u8]) -> Records<'a> {
        let limit = usize::try_from((buf.len() as u64).max(RECORD_LIMIT)).unwrap_or(usize::MAX);
        let options = mcap::sans_io::LinearReaderOptions::default()
            .with_skip_end_magic(true)
            .with_prevalidate_chunk_crcs(true)
            .with_record_length_limit(limit);
        Records { buf, reader: mcap::sans_io::LinearReader::new_with_options(options) }
    }
}

impl Iterator for Records<'_> {
    type Item = mcap::McapResult<mcap::records::Record<'static>>;

    fn next(&mut self) -> Option<Self::Item> {
        while let Some(event) = self.reader.next_event() {
            match event {
                Ok(mcap::sans_io::LinearReadEvent::ReadRequest(need)) => {
                    let n = need.min(self.buf.len());
                    self.reader.insert(n).copy_from_slice(&self.buf[..n]);
                    self.reader.notify_read(n);
                    self.buf = &self.buf[n..];
                }
                Ok(mcap::sans_io::LinearReadEvent::Record { data, opcode }) => {
                    return Some(mcap::parse_record(opcode, data).map(|r| r.into_owned()))
                }
                Err(e) => return Some(Err(e)),
            }
        }
        None
    }
}

/// One message as stored.
pub struct MessageRef<'a> {
    pub topic: &'a str,
    /// `package/msg/Type` (the schema name).
    pub type_name: &'a str,
    /// Receive time (MCAP log time), nanoseconds since the epoch.
    pub log_ns: i64,
    /// Header stamp (MCAP publish time).
    pub publish_ns: i64,
    /// CDR payload with its encapsulation header.
    pub data: &'a [u8],
    /// Position of the message in the bag (0-based), for messages about it.
    pub index: u64,
}

impl MessageRef<'_> {
    /// Decodes the payload as `M`, checking the type name.
    pub fn decode<M: RosMessage>(&self) -> Result<M> {
        if self.type_name != M::TYPE_NAME {
            bail!("message #{} on {}: type {} is not {}", self.index, self.topic, self.type_name, M::type_name());
        }
        cdr::decode(self.data).map_err(|e| anyhow!("message #{} on {}: {e}", self.index, self.topic))
    }
}

/// Per-topic message count.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TopicCount {
    pub type_name: String,
    pub count: u64,
}

/// What a read found.
#[derive(Clone, Debug, PartialEq)]
pub struct ReadSummary {
    pub messages: u64,
    pub per_topic: BTreeMap<String, TopicCount>,
    /// Log times of the first and last message read.
    pub first_ns: Option<i64>,
    pub last_ns: Option<i64>,
    /// `None` for a properly closed file; otherwise why reading stopped early.
    pub truncated: Option<String>,
    /// `metadata.yaml`'s message count, when it differs from what was read.
    pub metadata_count: Option<u64>,
}

impl ReadSummary {
    /// A sentence on what was recovered from a truncated bag (or `None` if it was complete).
    pub fn recovery_note(&self, bag: &Path) -> Option<String> {
        let why = self.truncated.as_ref()?;
        let span = match (self.first_ns, self.last_ns) {
            (Some(a), Some(b)) => format!(", {:.3} s of recording", (b - a) as f64 * 1e-9),
            _ => String::new(),
        };
        Some(format!(
            "{}: the bag was not closed (recorder killed?): recovered {} messages up to the last complete chunk{span}; {why}",
            bag.display(),
            self.messages
        ))
    }
}

/// An opened bag: the MCAP file(s) in memory and the rosbag2 metadata if present.
pub struct Bag {
    /// What the user named (directory or file).
    pub path: PathBuf,
    pub files: Vec<PathBuf>,
    pub metadata: Option<MetadataFile>,
}

impl Bag {
    /// Opens a bag directory (with `metadata.yaml`, or just `*.mcap` files) or an MCAP file.
    pub fn open(path: &Path) -> Result<Bag> {
        if path.is_dir() {
            let metadata = if path.join(FILE_NAME).exists() { Some(MetadataFile::read(path)?) } else { None };
            let files: Vec<PathBuf> = match &metadata {
                Some(m) => m.rosbag2_bagfile_information.relative_file_paths.iter().map(|f| path.join(f)).collect(),
                None => {
                    let mut v: Vec<PathBuf> = std::fs::read_dir(path)
                        .with_context(|| format!("cannot read {}", path.display()))?
                        .filter_map(|e| e.ok().map(|e| e.path()))
                        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
                        .collect();
                    v.sort();
                    v
                }
            };
            if files.is_empty() {
                bail!("{}: no MCAP file in the bag directory", path.display());
            }
            for f in &files {
                if !f.exists() {
                    bail!("{}: {} is listed in {FILE_NAME} but missing", path.display(), f.display());
                }
            }
            Ok(Bag { path: path.to_path_buf(), files, metadata })
        } else if path.exists() {
            Ok(Bag { path: path.to_path_buf(), files: vec![path.to_path_buf()], metadata: None })
        } else {
            bail!("{}: no such bag (a directory with metadata.yaml, or an .mcap file)", path.display())
        }
    }

    /// Calls `f` for every message in file order. A file that ends early (no footer) is read up
    /// to its last complete chunk and reported in [`ReadSummary::truncated`]; a damaged record
    /// inside a properly closed file is an error.
    pub fn read(&self, mut f: impl FnMut(&MessageRef) -> Result<()>) -> Result<ReadSummary> {
        let mut s = ReadSummary {
            messages: 0,
            per_topic: BTreeMap::new(),
            first_ns: None,
            last_ns: None,
            truncated: None,
            metadata_count: None,
        };
        for file in &self.files {
            let buf = std::fs::read(file).with_context(|| format!("cannot read {}", file.display()))?;
            if buf.len() < mcap::MAGIC.len() || &buf[..mcap::MAGIC.len()] != mcap::MAGIC {
                bail!("{}: not an MCAP file", file.display());
            }
            let closed = buf.ends_with(mcap::MAGIC) && mcap::read::footer(&buf).is_ok();
            // Schema names by id; per channel id: topic, type, messages read (no string lookups
            // per message).
            let mut schemas: BTreeMap<u16, String> = BTreeMap::new();
            let mut channels: Vec<Option<(String, String, u64)>> = Vec::new();
            for item in Records::new(&buf) {
                let record = match item {
                    Ok(r) => r,
                    Err(e) if !closed => {
                        s.truncated = Some(format!("{} ends in an incomplete record ({e})", file.display()));
                        break;
                    }
                    Err(e) => bail!("{}: damaged after {} messages: {e}", file.display(), s.messages),
                };
                let (header, data) = match record {
                    mcap::records::Record::Schema { header, .. } => {
                        schemas.insert(header.id, header.name);
                        continue;
                    }
                    mcap::records::Record::Channel(c) => {
                        let id = c.id as usize;
                        if channels.len() <= id {
                            channels.resize(id + 1, None);
                        }
                        if channels[id].is_none() {
                            let ty = schemas.get(&c.schema_id).cloned().unwrap_or_default();
                            channels[id] = Some((c.topic, ty, 0));
                        }
                        continue;
                    }
                    mcap::records::Record::Message { header, data } => (header, data),
                    // The messages end with the data section.
                    mcap::records::Record::DataEnd(_) => break,
                    _ => continue,
                };
                let id = header.channel_id as usize;
                if channels.get(id).is_none_or(Option::is_none) {
                    bail!("{}: message on unknown channel {id}", file.display());
                }
                let (topic, ty, count) = channels[id].as_mut().unwrap();
                let log_ns = header.log_time as i64;
                let msg = MessageRef {
                    topic,
                    type_name: ty,
                    log_ns,
                    publish_ns: header.publish_time as i64,
                    data: &data,
                    index: s.messages,
                };
                f(&msg)?;
                *count += 1;
                s.messages += 1;
                s.first_ns = Some(s.first_ns.map_or(log_ns, |v| v.min(log_ns)));
                s.last_ns = Some(s.last_ns.map_or(log_ns, |v| v.max(log_ns)));
            }
            for (topic, ty, count) in channels.into_iter().flatten() {
                match s.per_topic.get_mut(&topic) {
                    Some(c) => c.count += count,
                    None => {
                        s.per_topic.insert(topic, TopicCount { type_name: ty, count });
                    }
                }
            }
            if !closed && s.truncated.is_none() {
                s.truncated = Some(format!("{} has no summary or footer", file.display()));
            }
            if s.truncated.is_some() {
                break;
            }
        }
        if let Some(m) = &self.metadata {
            let n = m.rosbag2_bagfile_information.message_count;
            if n != s.messages {
                s.metadata_count = Some(n);
            }
        }
        Ok(s)
    }

    /// Counts messages per topic (reads everything).
    pub fn count(&self) -> Result<ReadSummary> {
        self.read(|_| Ok(()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::writer::BagWriter;
    use ros2_client::qos::QosProfile;
    use std::time::Duration;
    use volcal_msgs::msg::{Abscissa, MachinePosition};
    use volcal_msgs::std_msgs::msg::Header;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("volcal-bag-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    fn write_bag(dir: &Path, n: u64, flush_every: u64) -> BagWriter {
        let mut w = BagWriter::create(dir, Duration::from_secs(3600)).unwrap();
        // Any offered QoS will do: the reader does not interpret it.
        let qos = QosProfile::publisher_default();
        let a = w.add_topic::<Abscissa>("/interferometer/abscissa", &qos).unwrap();
        let p = w.add_topic::<MachinePosition>("/machine/position", &qos).unwrap();
        for i in 0..n {
            let t = 1_700_000_000_000_000_000 + i as i64 * 1_000_000;
            let m = Abscissa { header: Header::at(t, "d"), abscissa_m: i as f64, trigger_id: i, ..Default::default() };
            w.write(a, &m, t, t).unwrap();
            let q = MachinePosition { header: Header::at(t, "m"), x_m: i as f64, ..Default::default() };
            w.write(p, &q, t, t).unwrap();
            if (i + 1) % flush_every == 0 {
                w.flush().unwrap();
            }
        }
        w
    }

    #[test]
    fn round_trip_with_metadata() {
        let dir = scratch("rt");
        let stats = write_bag(&dir, 1000, 300).finish().unwrap();
        assert_eq!(stats.messages, 2000);
        let bag = Bag::open(&dir).unwrap();
        let info = &bag.metadata.as_ref().unwrap().rosbag2_bagfile_information;
        assert_eq!(info.message_count, 2000);
        assert_eq!(info.topics_with_message_count.len(), 2);
        let mut xs = Vec::new();
        let s = bag
            .read(|m| {
                if m.topic == "/machine/position" {
                    xs.push(m.decode::<MachinePosition>()?.x_m);
                } else {
                    assert!(m.decode::<MachinePosition>().is_err(), "type checked");
                }
                Ok(())
            })
            .unwrap();
        assert_eq!(s.messages, 2000);
        assert!(s.truncated.is_none() && s.metadata_count.is_none());
        assert_eq!(xs, (0..1000).map(|i| i as f64).collect::<Vec<_>>());
        assert!(Bag::open(&dir.join("nope")).is_err());
        assert!(BagWriter::create(&dir, Duration::from_secs(1)).is_err(), "an existing bag is never overwritten");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Damaged bytes give an error or a recovery note, never a panic or an abort: a record
    /// length of 2^64 - 1 (which overflowed the MCAP reader's arithmetic), a chunk stating an
    /// exabyte uncompressed (which it tried to allocate), and a flipped byte inside a chunk's
    /// compressed records (caught by the chunk's CRC).
    #[test]
    fn damaged_bytes_are_an_error_not_a_crash() {
        let dir = scratch("damaged");
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("bad.mcap");
        let mut bytes = mcap::MAGIC.to_vec();
        bytes.extend([0xff; 9]);
        std::fs::write(&file, &bytes).unwrap();
        let s = Bag::open(&file).unwrap().count().unwrap();
        assert_eq!(s.messages, 0);
        assert!(s.truncated.as_deref().is_some_and(|t| t.contains("bad.mcap ends in an incomplete record")), "{s:?}");

        let bag = scratch("damaged-chunk");
        write_bag(&bag, 1000, 250).finish().unwrap();
        let mcap = std::fs::read_dir(&bag)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.extension().is_some_and(|e| e == "mcap"))
            .unwrap();
        let good = std::fs::read(&mcap).unwrap();
        // The first chunk record.
        let mut at = mcap::MAGIC.len();
        while good[at] != 0x06 {
            at += 9 + u64::from_le_bytes(good[at + 1..at + 9].try_into().unwrap()) as usize;
        }
        let mut huge = good.clone();
        huge[at + 9 + 16..at + 9 + 24].copy_from_slice(&(1u64 << 60).to_le_bytes());
        std::fs::write(&mcap, &huge).unwrap();
        let e = Bag::open(&bag).unwrap().count().unwrap_err().to_string();
        assert!(e.contains("damaged after 0 messages"), "{e}");

        let mut flipped = good.clone();
        let len = u64::from_le_bytes(good[at + 1..at + 9].try_into().unwrap()) as usize;
        flipped[at + 9 + len - 20] ^= 0x02;
        std::fs::write(&mcap, &flipped).unwrap();
        let e = Bag::open(&bag).unwrap().count().unwrap_err().to_string();
        assert!(e.contains("damaged after 0 messages"), "a flipped byte inside a closed file's first chunk: {e}");
        let _ = std::fs::remove_dir_all(&dir);
        let _ = std::fs::remove_dir_all(&bag);
    }

    #[test]
    fn truncated_bag_is_read_to_the_last_complete_chunk() {
        let dir = scratch("trunc");
        let w = write_bag(&dir, 1000, 250);
        // Simulate SIGKILL: the writer never finishes; whatever sits in the open chunk is lost.
        std::mem::forget(w);
        let file = dir.join(format!("{}_0.mcap", dir.file_name().unwrap().to_str().unwrap()));
        let full = std::fs::read(&file).unwrap();
        // Also cut the file inside the last flushed chunk, as a crash mid-write would.
        for cut in [full.len(), full.len() / 2] {
            std::fs::write(&file, &full[..cut]).unwrap();
            let bag = Bag::open(&dir).unwrap();
            let s = bag.count().unwrap();
            // Whole chunks only: 4 chunks of 250 points (500 messages) each.
            assert_eq!(s.messages % 500, 0, "cut at {cut}");
            if cut == full.len() {
                assert_eq!(s.messages, 2000);
            } else {
                assert!(s.messages < 2000, "{}", s.messages);
            }
            assert!(s.truncated.is_some());
            let note = s.recovery_note(&dir).unwrap();
            assert!(note.contains(&format!("recovered {} messages", s.messages)), "{note}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
