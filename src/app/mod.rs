//! Application services: what each command does, without parsing arguments or printing —
//! completing files and batches ([`complete`]), scoring ([`eval`]), making training data
//! ([`prepare`], [`synth`]), timing the network ([`profile`]), view folders ([`views`]) and the
//! typed reports' export as a table or JSON ([`table`]). The command line and the examples call
//! these.

pub mod complete;
pub mod eval;
pub mod prepare;
pub mod profile;
pub mod synth;
pub mod table;
pub mod views;

/// What a long service tells its caller as it goes, for a progress bar; callers without one
/// pass [`Quiet`]. Called from worker threads.
pub trait Progress: Sync {
    /// `total` items are about to be worked on.
    fn start(&self, _total: usize, _label: &str) {}
    /// One item is done.
    fn done(&self, _item: &str) {}
    /// All are done.
    fn finish(&self) {}
    /// Something worth a warning happened to one item; the work goes on.
    fn warn(&self, _message: &str) {}
    /// Something the person running it would want to know, not a problem.
    fn note(&self, _message: &str) {}
}

/// No progress shown.
pub struct Quiet;

impl Progress for Quiet {}
