//! How much a run may read: the readers' budget ([`ReadLimits`], 2 GiB and 2^28 pixels by
//! default), raised for truly huge scans by `--max-read-bytes` / `--max-read-pixels`. Set
//! once per process, before anything is read; every reader of the command line uses it.

use std::sync::OnceLock;

use dhct_sm4_io::ReadLimits;

static LIMITS: OnceLock<ReadLimits> = OnceLock::new();

/// Sets the budget of this process (the first call wins; later calls are ignored and
/// return `false`).
pub fn set(limits: ReadLimits) -> bool {
    LIMITS.set(limits).is_ok()
}

/// The budget in force: the one set, else the readers' default.
pub fn get() -> ReadLimits {
    LIMITS.get().copied().unwrap_or_default()
}
