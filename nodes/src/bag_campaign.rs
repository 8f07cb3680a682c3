//! Reading a campaign from an MCAP bag recorded by the node set.

use anyhow::{bail, Result};
use std::path::Path;
use volcal::campaign::Campaign;

/// Reads the synchronised pairs of a bag as a campaign.
pub fn read(path: &Path) -> Result<Campaign> {
    bail!("{}: reading MCAP bags is not available in this build yet; export the campaign as CSV", path.display())
}
