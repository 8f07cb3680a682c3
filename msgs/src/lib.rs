//! # volcal_msgs: the ROS 2 messages of volcal
//!
//! The `.msg` files in `msgs/msg/` are the source of truth. At build time `build.rs` turns
//! them (and the upstream definitions they use, in `msgs/deps/`) into:
//!
//! - plain Rust structs with serde derives ([`msg`], [`std_msgs`], [`builtin_interfaces`]),
//!   whose field order and types are those of the `.msg` files, so that serde's CDR
//!   serialisation (as used by `ros2-client`) produces the same bytes as ROS 2;
//! - the MCAP `ros2msg` schema text of each type ([`RosMessage::SCHEMA`]): the definition
//!   followed by its dependencies, each after rosbag2's `====...` separator and a
//!   `MSG: package/Type` line, as rosbag2 writes them.
//!
//! ROS 2 naming: the type `volcal_msgs/msg/Abscissa` travels over DDS as
//! `volcal_msgs::msg::dds_::Abscissa_` ([`RosMessage::dds_type_name`]); the topic
//! `/interferometer/abscissa` as `rt/interferometer/abscissa` ([`dds_topic_name`]).
//!
//! [`cdr`] encodes and decodes the payloads (CDR with the 4-byte encapsulation header) that
//! DDS carries and rosbag2 stores in MCAP.
//!
//! ## Topics
//!
//! The topic names are constants in [`topics`]; ARCHITECTURE.md has the table of who
//! publishes and who subscribes.

include!(concat!(env!("OUT_DIR"), "/generated.rs"));

pub mod cdr;

use builtin_interfaces::msg::Time;
use std_msgs::msg::Header;

/// A ROS 2 message type generated from a `.msg` file.
pub trait RosMessage:
    serde::Serialize + serde::de::DeserializeOwned + Clone + Default + std::fmt::Debug + Send + Sync + 'static
{
    /// ROS package, e.g. `volcal_msgs`.
    const PACKAGE: &'static str;
    /// Type name within the package, e.g. `Abscissa`.
    const NAME: &'static str;
    /// `package/msg/Type`, the name ROS 2 tools and MCAP schemas use.
    const TYPE_NAME: &'static str;
    /// The `.msg` file, verbatim.
    const DEFINITION: &'static str;
    /// The MCAP `ros2msg` schema: [`Self::DEFINITION`] with its dependencies appended.
    const SCHEMA: &'static str;

    /// [`Self::TYPE_NAME`] as a `String`.
    fn type_name() -> String {
        Self::TYPE_NAME.to_string()
    }

    /// The DDS type name, `package::msg::dds_::Type_`.
    fn dds_type_name() -> String {
        format!("{}::msg::dds_::{}_", Self::PACKAGE, Self::NAME)
    }
}

/// The DDS topic name of a ROS 2 topic: `/a/b` travels as `rt/a/b`.
pub fn dds_topic_name(ros_topic: &str) -> String {
    format!("rt{}", if ros_topic.starts_with('/') { ros_topic.to_string() } else { format!("/{ros_topic}") })
}

/// The schema of a type by its `package/msg/Type` name.
pub fn schema_of(type_name: &str) -> Option<&'static str> {
    ALL_SCHEMAS.iter().find(|(n, _)| *n == type_name).map(|(_, s)| *s)
}

/// Topic names of the node set. Remaps in a launch file can change them per node.
pub mod topics {
    /// `Abscissa`: interferometer -> recorder, sequencer (signal strength), viz.
    pub const ABSCISSA: &str = "/interferometer/abscissa";
    /// `AbscissaBatch`: free-running interferometer samples above about 1 kHz.
    pub const ABSCISSA_BATCH: &str = "/interferometer/abscissa_batch";
    /// `InterferometerInfo` (transient-local): wavelength and air compensation.
    pub const INTERFEROMETER_INFO: &str = "/interferometer/info";
    /// `TracerRange`: tracer -> recorder, sequencer, viz.
    pub const TRACER_RANGE: &str = "/tracer/range";
    /// `MachinePosition`: machine -> recorder, sequencer, viz.
    pub const MACHINE_POSITION: &str = "/machine/position";
    /// `MachinePositionBatch`: machine coordinates sampled above about 1 kHz.
    pub const MACHINE_POSITION_BATCH: &str = "/machine/position_batch";
    /// `MachineCommand`: sequencer -> machine.
    pub const MACHINE_COMMAND: &str = "/machine/command";
    /// `BeamCommand`: sequencer -> deflector.
    pub const DEFLECTOR_COMMAND: &str = "/deflector/command";
    /// `BeamState` (transient-local): deflector -> all.
    pub const DEFLECTOR_STATE: &str = "/deflector/state";
    /// `Environment`: environment sensors -> recorder.
    pub const ENVIRONMENT: &str = "/environment";
    /// `Trigger`: sequencer -> interferometer, tracer, machine, recorder.
    pub const TRIGGER: &str = "/sequencer/trigger";
    /// `SequencerStatus` (transient-local): campaign progress.
    pub const SEQUENCER_STATUS: &str = "/sequencer/status";
    /// `SyncedPair`: recorder -> solver (through the bag), viz.
    pub const PAIRS: &str = "/campaign/pairs";
    /// `ErrorModel` (transient-local): solver -> anyone.
    pub const ERROR_MODEL: &str = "/error_model";
    /// `Diagnosis` (transient-local): solver (with `diagnose: true`) -> anyone.
    pub const DIAGNOSIS: &str = "/diagnosis";
    /// `BeamState`: the true simulated beam. Sim instruments only; never read by the solver.
    pub const TRUTH_BEAM: &str = "/sim/truth/beam";
    /// `ReflectorTruth`: the true simulated reflector position. Sim instruments only.
    pub const TRUTH_REFLECTOR: &str = "/sim/truth/reflector";
    /// Prefix of every simulation-truth topic.
    pub const TRUTH_PREFIX: &str = "/sim/truth/";
}

impl Time {
    /// From nanoseconds since the epoch.
    pub fn from_nanos(ns: i64) -> Time {
        Time { sec: ns.div_euclid(1_000_000_000) as i32, nanosec: ns.rem_euclid(1_000_000_000) as u32 }
    }

    /// Nanoseconds since the epoch.
    pub fn to_nanos(&self) -> i64 {
        self.sec as i64 * 1_000_000_000 + self.nanosec as i64
    }

    /// Seconds since the epoch.
    pub fn to_secs(&self) -> f64 {
        self.sec as f64 + self.nanosec as f64 * 1e-9
    }
}

impl Header {
    /// A header stamped at `ns` nanoseconds since the epoch.
    pub fn at(ns: i64, frame_id: &str) -> Header {
        Header { stamp: Time::from_nanos(ns), frame_id: frame_id.to_string() }
    }
}

#[cfg(test)]
mod tests {
    use super::msg::*;
    use super::*;

    fn defs_dir() -> std::path::PathBuf {
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("msg")
    }

    #[test]
    fn names_follow_ros2() {
        assert_eq!(Abscissa::type_name(), "volcal_msgs/msg/Abscissa");
        assert_eq!(Abscissa::TYPE_NAME, format!("{}/msg/{}", Abscissa::PACKAGE, Abscissa::NAME));
        assert_eq!(Abscissa::dds_type_name(), "volcal_msgs::msg::dds_::Abscissa_");
        assert_eq!(dds_topic_name(topics::ABSCISSA), "rt/interferometer/abscissa");
        assert_eq!(Header::type_name(), "std_msgs/msg/Header");
    }

    #[test]
    fn definitions_are_the_msg_files() {
        // Every .msg file has a type whose DEFINITION is the file verbatim, and nothing else.
        let mut n = 0;
        for e in std::fs::read_dir(defs_dir()).unwrap() {
            let p = e.unwrap().path();
            let name = format!("volcal_msgs/msg/{}", p.file_stem().unwrap().to_str().unwrap());
            let schema = schema_of(&name).unwrap_or_else(|| panic!("no generated type for {name}"));
            let text = std::fs::read_to_string(&p).unwrap();
            assert!(schema.starts_with(text.trim_end()), "{name}: schema does not start with the .msg text");
            n += 1;
        }
        let ours = ALL_SCHEMAS.iter().filter(|(n, _)| n.starts_with("volcal_msgs/")).count();
        assert_eq!(n, ours);
    }

    #[test]
    fn schema_appends_dependencies_like_rosbag2() {
        let s = Abscissa::SCHEMA;
        let sep = "\n================================================================================\n";
        let parts: Vec<&str> = s.split(sep).collect();
        assert_eq!(parts.len(), 3, "{s}");
        assert!(parts[1].starts_with("MSG: std_msgs/Header\n"));
        assert!(parts[2].starts_with("MSG: builtin_interfaces/Time\n"));
        // Dependencies appear once even when used twice (ErrorModel uses Header and ErrorFunction).
        assert_eq!(ErrorModel::SCHEMA.matches("MSG: builtin_interfaces/Time").count(), 1);
        assert!(ErrorModel::SCHEMA.contains("MSG: volcal_msgs/ErrorFunction\n"));
        // A type without nested types has no separator.
        assert!(!ErrorFunction::SCHEMA.contains("MSG:"));
    }

    #[test]
    fn constants_and_fixed_arrays() {
        assert_eq!(Trigger::SEGMENT_END, 3);
        assert_eq!(SyncedPair::PAIRING_INTERPOLATED, 1);
        let m = MachinePosition::default();
        assert_eq!(m.probe_offset_m.len(), 3);
        let e = ErrorModel::default();
        assert_eq!(e.travel_m.len(), 6);
    }

    #[test]
    fn time_round_trip() {
        for ns in [0i64, 1, 999_999_999, 1_700_000_000_123_456_789, -1_700_000_000] {
            assert_eq!(Time::from_nanos(ns).to_nanos(), ns);
        }
        assert_eq!(Time::from_nanos(-300_000_000), Time { sec: -1, nanosec: 700_000_000 });
    }
}
