//! # volcal_bag: rosbag2 bags, and the pairing of readings with coordinates
//!
//! Bags are MCAP files in rosbag2's layout, written by the recorder and read back by `volcal`.
//!
//! A bag is a directory `NAME/` holding `metadata.yaml` (rosbag2's, version 5) and
//! `NAME_0.mcap`: chunked, zstd-compressed MCAP with profile `ros2`, one `ros2msg` schema per
//! message type (the `.msg` text with its dependencies appended) and `cdr` message encoding,
//! so that `ros2 bag info`, `rosbags`, `mcap-ros2-support` and Foxglove open it.
//!
//! The writer closes a chunk at least every flush period (0.5 s by default) and rewrites
//! `metadata.yaml` then, so a recorder killed with SIGKILL leaves a bag readable up to its last
//! complete chunk; the reader says how much it recovered.
//!
//! Also here: [`pairing`] (the recorder's core: readings and coordinates into synchronised
//! pairs), [`convert`] (messages <-> core types and pairing events) and [`campaign`] (a bag's
//! pairs as a campaign; any campaign file with its provenance).

pub mod campaign;
pub mod convert;
pub mod metadata;
pub mod pairing;
pub mod reader;
pub mod writer;

pub use reader::{Bag, MessageRef, ReadSummary};
pub use writer::{BagWriter, TopicHandle};
