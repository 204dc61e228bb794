//! Ctrl-C: what a stopped command leaves behind. One handler serves the whole process (a
//! process has one per signal).
//!
//! Only SIGINT is caught. `ctrlc` can take SIGTERM only with SIGHUP, and a SIGHUP that `nohup`
//! ignores must stay ignored; SIGTERM and SIGKILL leave the hidden temporary files, which are
//! never taken for outputs.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

/// Exit status of a command stopped by Ctrl-C, as a shell reports it.
const STOPPED: i32 = 130;

/// Raised by the first Ctrl-C instead of stopping, once a command asked for it ([`graceful`]).
static GRACEFUL: OnceLock<Arc<AtomicBool>> = OnceLock::new();

/// Installs the handler: the temporary files being written are deleted and the process exits
/// with status 130, so that a stopped command leaves no `.mvpcc-*.tmp` beside its outputs and
/// no copy of its standard input; a command that asked to stop gracefully gets the first Ctrl-C
/// as a request, and the second stops it so. It replaces a SIGINT the parent ignored (a
/// script's background job), as training's graceful stop always has.
pub fn install() -> anyhow::Result<()> {
    ctrlc::set_handler(|| {
        if GRACEFUL
            .get()
            .is_some_and(|flag| !flag.swap(true, Ordering::SeqCst))
        {
            return;
        }
        mvpcc::io::remove_unfinished();
        std::process::exit(STOPPED);
    })?;
    Ok(())
}

/// The flag the first Ctrl-C raises instead of stopping the process: for a command that can
/// end its work cleanly (training saves a checkpoint and validates once more).
pub fn graceful() -> Arc<AtomicBool> {
    GRACEFUL.get_or_init(Arc::default).clone()
}
