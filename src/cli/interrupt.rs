//! Ctrl-C and SIGTERM: what a stopped command leaves behind. One handler serves the whole
//! process (a process has one per signal).
//!
//! SIGHUP is left alone, so that `nohup mvpcc …` outlives its terminal. After cleaning up, the
//! process ends by the signal itself rather than by an exit status: a shell running
//! `for f in *.ply; do mvpcc complete "$f" …; done` stops its loop on Ctrl-C only when the
//! command died of SIGINT, and takes an exit status (even 130) for a command that handled it.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

/// Raised by the first Ctrl-C or SIGTERM instead of stopping, once a command asked for it
/// ([`graceful`]).
static GRACEFUL: OnceLock<Arc<AtomicBool>> = OnceLock::new();

/// Installs the handler: the temporary files being written are deleted, then the signal ends
/// the process as it would have without a handler, so that a stopped command leaves no
/// `.mvpcc-*.tmp` beside its outputs and no copy of its standard input. A command that asked to
/// stop gracefully gets the first signal as a request (a scheduler's SIGTERM before its
/// SIGKILL, a user's Ctrl-C); the second stops it so. It replaces a SIGINT the parent ignored
/// (a script's background job), as training's graceful stop always has.
#[cfg(unix)]
pub fn install() -> std::io::Result<()> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM])?;
    std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || signals.forever().for_each(on_signal))?;
    Ok(())
}

/// Installs the handler for Ctrl-C (see the Unix one).
#[cfg(not(unix))]
pub fn install() -> std::io::Result<()> {
    // What an unhandled Ctrl-C ends a Windows process with (STATUS_CONTROL_C_EXIT).
    const CONTROL_C_EXIT: i32 = 0xC000_013A_u32 as i32;
    ctrlc::set_handler(|| on_signal(CONTROL_C_EXIT)).map_err(std::io::Error::other)
}

fn on_signal(signal: i32) {
    let requested = GRACEFUL
        .get()
        .is_some_and(|flag| !flag.swap(true, Ordering::SeqCst));
    if !requested {
        mvpcc::io::remove_unfinished_then(|| stop(signal));
    }
}

#[cfg(unix)]
fn stop(signal: i32) -> ! {
    // Falls back on the shell's status for it where the default action cannot be restored.
    let _ = signal_hook::low_level::emulate_default_handler(signal);
    std::process::exit(128 + signal);
}

#[cfg(not(unix))]
fn stop(status: i32) -> ! {
    std::process::exit(status);
}

/// The flag the first Ctrl-C or SIGTERM raises instead of stopping the process: for a command
/// that can end its work cleanly (training saves a checkpoint and validates once more).
pub fn graceful() -> Arc<AtomicBool> {
    GRACEFUL.get_or_init(Arc::default).clone()
}
