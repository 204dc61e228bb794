//! Panics inside third-party decoders turned into errors. The LAS/LAZ, glTF and OBJ readers
//! this tool builds on panic on some damaged files (the fuzzers found several); a user must get
//! a one-line error naming the file instead. Panics elsewhere still reach the panic hook as
//! before.

use std::cell::Cell;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Once;

thread_local! {
    /// Set while this thread runs a guarded call, so the hook stays quiet for it.
    static GUARDED: Cell<bool> = const { Cell::new(false) };
}

/// Wraps the panic hook once, so that a panic inside [`guarded`] prints nothing: it becomes
/// the call's error instead.
fn install_hook() {
    static INSTALL: Once = Once::new();
    INSTALL.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !GUARDED.with(Cell::get) {
                previous(info);
            }
        }));
    });
}

/// Runs `f`; a panic in it is returned as `Err` with its message.
pub fn guarded<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    install_hook();
    let was = GUARDED.with(|g| g.replace(true));
    let result = catch_unwind(AssertUnwindSafe(f));
    GUARDED.with(|g| g.set(was));
    result.map_err(|payload| {
        payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "an unknown failure".to_string())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_becomes_an_error_and_other_results_pass_through() {
        assert_eq!(guarded(|| 7), Ok(7));
        let v: Vec<u8> = Vec::new();
        let index = 3;
        let message = guarded(|| v[index]).unwrap_err();
        assert!(message.contains("index out of bounds"), "{message}");
        assert_eq!(
            guarded(|| -> u8 { panic!("bad chunk") }),
            Err("bad chunk".into())
        );
    }
}
