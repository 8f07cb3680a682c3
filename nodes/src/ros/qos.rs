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

/// The simulated reflector truth (`/sim/truth/reflector`), published at the machine's rate
/// whether or not it moves: 2 kHz on the on-the-fly runs. [`data`]'s 4 096 samples are 2 s of
/// it, and a subscriber starved for longer (the recorder, with the node set sharing two cores
/// with other work: a 2.2 s stall, 125 ms of truth lost) would lose samples, and the simulated
/// instruments would interpolate across the hole. 65 536 samples are half a minute of it.
pub fn truth() -> QosProfile {
    data().history(History::KeepLast { depth: 65_536 })
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
