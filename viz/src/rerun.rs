//! The part of the Rerun SDK that volcal uses, named as the `rerun` umbrella crate names it.
//!
//! It comes from the SDK's own crates (`re_sdk`, `re_sdk_types`) rather than from `rerun`:
//! that crate also requires the viewer-side chunk store, entity database and query engine and
//! the Rerun Data Platform client with its authentication (49 crates in all), none of which a
//! logger needs. Recordings, gRPC streaming to a viewer and spawning one are all `re_sdk`'s,
//! so the `.rrd` files and the wire protocol are the same.

pub use re_sdk::log::TimeColumn;
pub use re_sdk::*;
pub use re_sdk_types::archetypes::*;
pub use re_sdk_types::components::Radius;
pub use re_sdk_types::{archetypes, components, datatypes};

/// Other crates of the SDK, as `rerun::external` re-exports them.
pub mod external {
    pub use re_sdk::external::*;
    pub use re_sdk_types;
}
