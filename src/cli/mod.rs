//! The command line: its arguments ([`args`]) and one module per command ([`commands`]), on
//! top of the library. Not part of the library's API.

pub mod args;
pub mod commands;
