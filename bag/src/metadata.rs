//! rosbag2's `metadata.yaml`. volcal writes version 5 (read by every rosbag2 since Humble and by
//! `rosbags`) and reads every version rosbag2 has written since it stored QoS: 4 to 9.
//!
//! What changed between them, as rosbag2's `metadata_io` writes it: 4 added
//! `relative_file_paths` and `offered_qos_profiles` (a YAML document in a string); 5 the
//! per-file `files` list; 6 `custom_data`; 7 each topic's `type_description_hash`; 8
//! `ros_distro`; 9 writes `offered_qos_profiles` as a YAML list (Jazzy and later). Fields volcal
//! does not use are ignored, and the QoS is kept as the YAML text it was offered in.

use anyhow::{anyhow, bail, Context, Result};
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
    /// The offered QoS as YAML text (version 9's list is turned back into text).
    #[serde(default, deserialize_with = "qos_text")]
    pub offered_qos_profiles: String,
}

/// `offered_qos_profiles`: a string up to version 8, a YAML list from version 9 on.
fn qos_text<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<String, D::Error> {
    match serde_yaml::Value::deserialize(d)? {
        serde_yaml::Value::Null => Ok(String::new()),
        serde_yaml::Value::String(s) => Ok(s),
        v @ serde_yaml::Value::Sequence(_) => {
            serde_yaml::to_string(&v).map(|s| s.trim_end().to_string()).map_err(serde::de::Error::custom)
        }
        other => {
            Err(serde::de::Error::custom(format!("offered_qos_profiles: expected text or a list, found {other:?}")))
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct FileInfo {
    pub path: String,
    pub starting_time: StartingTime,
    pub duration: Nanoseconds,
    pub message_count: u64,
}

/// The metadata versions this reader knows (it writes [`WRITTEN_VERSION`]).
pub const READ_VERSIONS: std::ops::RangeInclusive<u32> = 4..=9;

/// The version volcal's recorder writes.
pub const WRITTEN_VERSION: u32 = 5;

impl MetadataFile {
    /// Reads `metadata.yaml` of a bag directory; an error names the file, line and column, and
    /// says so when the bag's storage or version is not one volcal reads.
    pub fn read(dir: &Path) -> Result<MetadataFile> {
        let p = dir.join(FILE_NAME);
        let text = std::fs::read_to_string(&p).with_context(|| format!("cannot read {}", p.display()))?;
        Self::parse(&text).map_err(|e| anyhow!("{}: {e}", p.display()))
    }

    /// Parses the text of a `metadata.yaml`.
    pub fn parse(text: &str) -> Result<MetadataFile> {
        let m: MetadataFile = serde_yaml::from_str(text).map_err(|e| {
            let at = e.location().map(|l| format!("line {}, column {}: ", l.line(), l.column())).unwrap_or_default();
            anyhow!("{at}{e}")
        })?;
        let info = &m.rosbag2_bagfile_information;
        if !READ_VERSIONS.contains(&info.version) {
            bail!(
                "rosbag2 metadata version {} (volcal reads versions {} to {})",
                info.version,
                READ_VERSIONS.start(),
                READ_VERSIONS.end()
            );
        }
        if !info.storage_identifier.eq_ignore_ascii_case("mcap") {
            bail!(
                "storage {:?}: volcal reads MCAP bags; convert this one first (`ros2 bag convert`, or `rosbags-convert --dst-storage mcap`)",
                info.storage_identifier
            );
        }
        if info.compression_mode.eq_ignore_ascii_case("file") {
            bail!(
                "compression mode FILE ({} compressed whole files): decompress them first (`ros2 bag convert` without compression)",
                info.compression_format
            );
        }
        Ok(m)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// `metadata.yaml` of one topic as rosbag2 writes version `v` (fields added by each version
    /// included from it on; the QoS as text up to 8, as a list from 9).
    fn sample(v: u32) -> String {
        let qos_text = "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  deadline:\n    sec: 9223372036\n    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n    nsec: 854775807\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 9223372036\n    nsec: 854775807\n  avoid_ros_namespace_conventions: false";
        let qos = if v >= 9 {
            "\n          - history: keep_last\n            depth: 10\n            reliability: reliable\n            durability: volatile\n            deadline:\n              sec: 0\n              nsec: 0\n            lifespan:\n              sec: 0\n              nsec: 0\n            liveliness: automatic\n            liveliness_lease_duration:\n              sec: 0\n              nsec: 0\n            avoid_ros_namespace_conventions: false".to_string()
        } else {
            format!("\"{qos_text}\"")
        };
        let hash = if v >= 7 { "\n        type_description_hash: RIHS01_0123abcd" } else { "" };
        let files = if v >= 5 {
            "\n  files:\n    - path: b_0.mcap\n      starting_time:\n        nanoseconds_since_epoch: 1700000000000000000\n      duration:\n        nanoseconds: 5000000000\n      message_count: 42"
        } else {
            ""
        };
        let custom = if v >= 6 { "\n  custom_data: ~" } else { "" };
        let distro = if v >= 8 { "\n  ros_distro: jazzy" } else { "" };
        format!(
            "rosbag2_bagfile_information:\n  version: {v}\n  storage_identifier: mcap\n  duration:\n    nanoseconds: 5000000000\n  starting_time:\n    nanoseconds_since_epoch: 1700000000000000000\n  message_count: 42\n  topics_with_message_count:\n    - topic_metadata:\n        name: /campaign/pairs\n        type: volcal_msgs/msg/SyncedPair\n        serialization_format: cdr\n        offered_qos_profiles: {qos}{hash}\n      message_count: 42\n  compression_format: \"\"\n  compression_mode: \"\"\n  relative_file_paths:\n    - b_0.mcap{files}{custom}{distro}\n"
        )
    }

    #[test]
    fn every_version_from_4_to_9_is_read() {
        for v in 4..=9 {
            let m = MetadataFile::parse(&sample(v)).unwrap_or_else(|e| panic!("version {v}: {e:#}"));
            let info = &m.rosbag2_bagfile_information;
            assert_eq!(info.version, v);
            assert_eq!(info.relative_file_paths, ["b_0.mcap"]);
            assert_eq!(info.files.len(), usize::from(v >= 5), "version {v}");
            let t = &info.topics_with_message_count[0].topic_metadata;
            assert_eq!(
                (t.name.as_str(), t.type_name.as_str(), info.message_count),
                ("/campaign/pairs", "volcal_msgs/msg/SyncedPair", 42)
            );
            assert!(t.offered_qos_profiles.contains("depth:"), "version {v}: {:?}", t.offered_qos_profiles);
        }
    }

    #[test]
    fn what_is_not_read_is_said() {
        let e = MetadataFile::parse(&sample(9).replace("version: 9", "version: 3")).unwrap_err().to_string();
        assert!(e.contains("version 3") && e.contains("4 to 9"), "{e}");
        let e = MetadataFile::parse(&sample(8).replace("storage_identifier: mcap", "storage_identifier: sqlite3"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("sqlite3") && e.contains("convert"), "{e}");
        let e = MetadataFile::parse("rosbag2_bagfile_information:\n  version: [\n").unwrap_err().to_string();
        assert!(e.contains("line"), "{e}");
    }

    #[test]
    fn written_metadata_reads_back() {
        let m = MetadataFile::parse(&sample(WRITTEN_VERSION)).unwrap();
        let again = MetadataFile::parse(&serde_yaml::to_string(&m).unwrap()).unwrap();
        assert_eq!(m, again);
    }
}
