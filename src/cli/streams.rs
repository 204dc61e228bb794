//! Lines for the two standard streams. Rust ignores SIGPIPE, so once a reader goes away
//! (`mvpcc eval … | head -1`) every later write to its pipe fails, and `println!` and
//! `eprintln!` answer a failed write with a panic; these do not.

use anyhow::Context;
use std::fmt::Display;
use std::io::{ErrorKind, Write};

/// One line of results on stdout. A reader that went away has read what it wanted, so that is
/// not an error; any other failure to write is.
pub fn say(line: impl Display) -> anyhow::Result<()> {
    match writeln!(std::io::stdout().lock(), "{line}") {
        Err(e) if e.kind() == ErrorKind::BrokenPipe => Ok(()),
        written => written.context("writing to standard output"),
    }
}

/// One line for a person on stderr. Without its reader the work still goes on, and still
/// writes its files: the messages are what is given up.
pub fn tell(line: impl Display) {
    let _unread = writeln!(std::io::stderr().lock(), "{line}");
}
