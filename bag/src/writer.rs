//! Writing a bag: MCAP (profile `ros2`, `ros2msg` schemas, `cdr` messages, zstd chunks) plus
//! rosbag2's `metadata.yaml`.

use super::metadata::{
    qos_yaml, BagInfo, FileInfo, MetadataFile, Nanoseconds, StartingTime, TopicMetadata, TopicWithCount,
    WRITTEN_VERSION,
};
use anyhow::{bail, Context, Result};
use ros2_client::qos::QosProfile;
use serde::Serialize;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use volcal_msgs::cdr;
use volcal_msgs::RosMessage;

/// A topic of the bag, returned by [`BagWriter::add_topic`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TopicHandle(usize);

struct TopicState {
    name: String,
    type_name: String,
    qos: String,
    channel: u16,
    count: u64,
}

/// Counts of a finished bag.
#[derive(Clone, Debug, PartialEq)]
pub struct BagStats {
    pub dir: PathBuf,
    pub messages: u64,
    pub per_topic: BTreeMap<String, u64>,
    pub bytes: u64,
}

/// An open bag being recorded.
pub struct BagWriter {
    dir: PathBuf,
    file_name: String,
    mcap: Option<mcap::Writer<BufWriter<File>>>,
    topics: Vec<TopicState>,
    first_ns: Option<i64>,
    last_ns: i64,
    messages: u64,
    sequence: u32,
    flush_period: Duration,
    last_flush: Instant,
    buf: Vec<u8>,
}

impl BagWriter {
    /// Creates the bag directory `dir` (it must not exist, or be empty: nothing recorded is
    /// ever overwritten) with `<dir name>_0.mcap` inside.
    pub fn create(dir: &Path, flush_period: Duration) -> Result<BagWriter> {
        if dir.exists() {
            let non_empty = std::fs::read_dir(dir).map(|mut d| d.next().is_some()).unwrap_or(true);
            if non_empty {
                bail!(
                    "{}: the bag directory exists and is not empty; choose a new name (nothing is overwritten)",
                    dir.display()
                );
            }
        }
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create bag directory {}", dir.display()))?;
        let stem = dir.file_name().and_then(|s| s.to_str()).filter(|s| !s.is_empty()).unwrap_or("bag").to_string();
        let file_name = format!("{stem}_0.mcap");
        let path = dir.join(&file_name);
        let f = File::create(&path).with_context(|| format!("cannot create {}", path.display()))?;
        let opts = mcap::WriteOptions::new()
            .profile("ros2")
            .library(volcal_formats::software_version())
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(4 << 20))
            .compression_threads(0);
        let mcap = opts
            .create(BufWriter::with_capacity(1 << 20, f))
            .with_context(|| format!("cannot start {}", path.display()))?;
        let w = BagWriter {
            dir: dir.to_path_buf(),
            file_name,
            mcap: Some(mcap),
            topics: Vec::new(),
            first_ns: None,
            last_ns: 0,
            messages: 0,
            sequence: 0,
            flush_period,
            last_flush: Instant::now(),
            buf: Vec::with_capacity(512),
        };
        w.metadata().write(&w.dir)?;
        Ok(w)
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn mcap(&mut self) -> &mut mcap::Writer<BufWriter<File>> {
        self.mcap.as_mut().expect("bag already finished")
    }

    /// Declares a topic of type `M` with the QoS its publishers offer.
    pub fn add_topic<M: RosMessage>(&mut self, topic: &str, qos: &QosProfile) -> Result<TopicHandle> {
        if let Some(i) = self.topics.iter().position(|t| t.name == topic) {
            if self.topics[i].type_name != M::type_name() {
                bail!("topic {topic}: already recorded as {}, not {}", self.topics[i].type_name, M::type_name());
            }
            return Ok(TopicHandle(i));
        }
        let qos = qos_yaml(qos);
        let mcap = self.mcap();
        let schema = mcap.add_schema(&M::type_name(), "ros2msg", M::SCHEMA.as_bytes())?;
        let mut meta = BTreeMap::new();
        meta.insert("offered_qos_profiles".to_string(), qos.clone());
        let channel = mcap.add_channel(schema, topic, "cdr", &meta)?;
        self.topics.push(TopicState { name: topic.to_string(), type_name: M::type_name(), qos, channel, count: 0 });
        Ok(TopicHandle(self.topics.len() - 1))
    }

    /// Writes one message. `log_ns`: when it was received; `publish_ns`: its header stamp.
    pub fn write<M: Serialize>(&mut self, topic: TopicHandle, msg: &M, log_ns: i64, publish_ns: i64) -> Result<()> {
        let mut buf = std::mem::take(&mut self.buf);
        cdr::encode_into(msg, &mut buf);
        let r = self.write_cdr(topic, &buf, log_ns, publish_ns);
        self.buf = buf;
        r
    }

    /// Writes a CDR payload (with its encapsulation header).
    pub fn write_cdr(&mut self, topic: TopicHandle, data: &[u8], log_ns: i64, publish_ns: i64) -> Result<()> {
        let t = &mut self.topics[topic.0];
        t.count += 1;
        let channel = t.channel;
        self.sequence = self.sequence.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: self.sequence,
            log_time: log_ns.max(0) as u64,
            publish_time: publish_ns.max(0) as u64,
        };
        self.first_ns = Some(self.first_ns.map_or(log_ns, |f| f.min(log_ns)));
        self.last_ns = self.last_ns.max(log_ns);
        self.messages += 1;
        self.mcap().write_to_known_channel(&header, data).context("cannot write to the bag")?;
        Ok(())
    }

    /// Closes the current chunk and updates `metadata.yaml` when the flush period has passed.
    pub fn flush_if_due(&mut self) -> Result<bool> {
        if self.last_flush.elapsed() < self.flush_period {
            return Ok(false);
        }
        self.flush()?;
        Ok(true)
    }

    /// Closes the current chunk, pushes it to the file, and updates `metadata.yaml`.
    pub fn flush(&mut self) -> Result<()> {
        self.last_flush = Instant::now();
        self.mcap().flush().context("cannot flush the bag")?;
        self.metadata().write(&self.dir)
    }

    /// Writes the summary and the final `metadata.yaml`.
    pub fn finish(mut self) -> Result<BagStats> {
        let mut mcap = self.mcap.take().expect("bag already finished");
        mcap.finish().context("cannot finish the bag")?;
        drop(mcap);
        self.metadata().write(&self.dir)?;
        let bytes = std::fs::metadata(self.dir.join(&self.file_name)).map(|m| m.len()).unwrap_or(0);
        Ok(BagStats {
            dir: self.dir.clone(),
            messages: self.messages,
            per_topic: self.topics.iter().map(|t| (t.name.clone(), t.count)).collect(),
            bytes,
        })
    }

    fn metadata(&self) -> MetadataFile {
        let start = self.first_ns.unwrap_or(0);
        let duration = if self.first_ns.is_some() { self.last_ns - start } else { 0 };
        MetadataFile {
            rosbag2_bagfile_information: BagInfo {
                version: WRITTEN_VERSION,
                storage_identifier: "mcap".into(),
                duration: Nanoseconds { nanoseconds: duration },
                starting_time: StartingTime { nanoseconds_since_epoch: start },
                message_count: self.messages,
                topics_with_message_count: self
                    .topics
                    .iter()
                    .map(|t| TopicWithCount {
                        topic_metadata: TopicMetadata {
                            name: t.name.clone(),
                            type_name: t.type_name.clone(),
                            serialization_format: "cdr".into(),
                            offered_qos_profiles: t.qos.clone(),
                        },
                        message_count: t.count,
                    })
                    .collect(),
                compression_format: String::new(),
                compression_mode: String::new(),
                relative_file_paths: vec![self.file_name.clone()],
                files: vec![FileInfo {
                    path: self.file_name.clone(),
                    starting_time: StartingTime { nanoseconds_since_epoch: start },
                    duration: Nanoseconds { nanoseconds: duration },
                    message_count: self.messages,
                }],
            },
        }
    }
}
