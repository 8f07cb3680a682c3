//! rosbag2's `metadata.yaml` (version 5, read by every rosbag2 since Humble and by `rosbags`).

use anyhow::{anyhow, Context, Result};
use ros2_client::qos::{Durability, History, QosProfile, Reliability};
use serde::{Deserialize, Serialize};
use std::path::Path;

pub const FILE_NAME: &str = "metadata.yaml";

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct MetadataFile {
    pub rosbag2_bagfile_information: BagInfo,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct BagInfo {
    pub version: u32,
    pub storage_identifier: String,
    pub duration: Nanoseconds,
    pub starting_time: StartingTime,
    pub message_count: u64,
    pub topics_with_message_count: Vec<TopicWithCount>,
    #[serde(default)]
    pub compression_format: String,
    #[serde(default)]
    pub compression_mode: String,
    pub relative_file_paths: Vec<String>,
    #[serde(default)]
    pub files: Vec<FileInfo>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Nanoseconds {
    pub nanoseconds: i64,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct StartingTime {
    pub nanoseconds_since_epoch: i64,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct TopicWithCount {
    pub topic_metadata: TopicMetadata,
    pub message_count: u64,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct TopicMetadata {
    pub name: String,
    #[serde(rename = "type")]
    pub type_name: String,
    pub serialization_format: String,
    #[serde(default)]
    pub offered_qos_profiles: String,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct FileInfo {
    pub path: String,
    pub starting_time: StartingTime,
    pub duration: Nanoseconds,
    pub message_count: u64,
}

impl MetadataFile {
    pub fn read(dir: &Path) -> Result<MetadataFile> {
        let p = dir.join(FILE_NAME);
        let text = std::fs::read_to_string(&p).with_context(|| format!("cannot read {}", p.display()))?;
        serde_yaml::from_str(&text).map_err(|e| anyhow!("{}: {e}", p.display()))
    }

    /// Writes atomically (temporary file, then rename), so a crash never leaves half a file.
    pub fn write(&self, dir: &Path) -> Result<()> {
        let p = dir.join(FILE_NAME);
        let tmp = dir.join(format!(".{FILE_NAME}.tmp"));
        std::fs::write(&tmp, serde_yaml::to_string(self)?)
            .with_context(|| format!("cannot write {}", tmp.display()))?;
        std::fs::rename(&tmp, &p).with_context(|| format!("cannot write {}", p.display()))
    }
}

/// rosbag2's YAML for the QoS a publisher offered (`offered_qos_profiles`, also stored in the
/// MCAP channel metadata).
pub fn qos_yaml(q: &QosProfile) -> String {
    let (history, depth) = match q.history {
        History::KeepLast { depth } => (1, depth),
        History::KeepAll => (2, 0),
    };
    let reliability = match q.reliability {
        Reliability::Reliable { .. } => 1,
        Reliability::BestEffort => 2,
    };
    let durability = match q.durability {
        Durability::TransientLocal => 1,
        Durability::Volatile => 2,
    };
    let infinite = "\n    sec: 2147483647\n    nsec: 4294967295";
    format!(
        "- history: {history}\n  depth: {depth}\n  reliability: {reliability}\n  durability: {durability}\n  deadline:{infinite}\n  lifespan:{infinite}\n  liveliness: 1\n  liveliness_lease_duration:{infinite}\n  avoid_ros_namespace_conventions: false"
    )
}
