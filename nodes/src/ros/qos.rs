//! QoS profiles of the node set. Everything is reliable: a lost reading is a lost calibration
//! point. Data topics keep a deep history so that a briefly busy subscriber (the recorder
//! flushing a chunk) does not lose samples; state topics are transient-local so that a node
//! that starts or restarts late gets the current state.

use ros2_client::qos::{Durability, History, QosProfile, WhenFull};
use std::time::Duration;

/// Streams of readings and positions (up to tens of kHz when batched).
pub fn data() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::Wait(Duration::from_millis(200)))
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 4096 })
}

/// Commands and triggers.
pub fn commands() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::Wait(Duration::from_millis(200)))
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 256 })
}

/// Latched state (deflector state, instrument info, sequencer status, error model): late
/// joiners receive the last sample.
pub fn latched() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::Wait(Duration::from_millis(200)))
        .durability(Durability::TransientLocal)
        .history(History::KeepLast { depth: 1 })
}
