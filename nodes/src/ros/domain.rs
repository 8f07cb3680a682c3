//! Picking a ROS domain nobody else on this host uses: tests, the demo and benchmarks each
//! lease one, so that parallel runs (several test binaries, several developers) never hear each
//! other. A lease is an exclusive `flock` on `/tmp/volcal-ros-domain-<id>.lock`, released when
//! the lease is dropped or the process dies.

use anyhow::{bail, Context, Result};
use std::fs::File;
use std::os::unix::io::AsRawFd;

/// A leased `ROS_DOMAIN_ID`.
#[derive(Debug)]
pub struct DomainLease {
    pub id: u16,
    _lock: File,
}

/// Domains handed out by [`lease`]; 0 (the default) and the low ids that people use by hand
/// are left alone.
pub const RANGE: std::ops::RangeInclusive<u16> = 101..=232;

/// Leases a free domain id, starting the search at a pseudo-random offset (process id) so that
/// concurrent processes rarely contend for the same lock.
pub fn lease() -> Result<DomainLease> {
    let n = (RANGE.end() - RANGE.start() + 1) as u32;
    let start = std::process::id() % n;
    for k in 0..n {
        let id = RANGE.start() + ((start + k) % n) as u16;
        let path = std::env::temp_dir().join(format!("volcal-ros-domain-{id}.lock"));
        let f = File::options()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&path)
            .with_context(|| format!("cannot open {}", path.display()))?;
        // SAFETY: flock on a file descriptor we own.
        let r = unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
        if r == 0 {
            return Ok(DomainLease { id, _lock: f });
        }
    }
    bail!("every ROS domain id in {}..={} is leased by another volcal process", RANGE.start(), RANGE.end())
}

#[cfg(test)]
mod tests {
    #[test]
    fn leases_are_exclusive() {
        let a = super::lease().unwrap();
        let b = super::lease().unwrap();
        assert_ne!(a.id, b.id);
        let id = a.id;
        drop(a);
        // Released: someone can take it again (we may get another free one first; both fine).
        let c = super::lease().unwrap();
        assert!(super::RANGE.contains(&c.id));
        let _ = id;
    }
}
