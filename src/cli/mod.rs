//! The command line: its arguments ([`args`]) and one module per command ([`commands`]), on
//! top of the library. Not part of the library's API.

pub mod args;
pub mod commands;
pub mod interrupt;
pub mod streams;

/// `n` and the noun, plural unless `n` is 1: "1 view", "4 views".
pub fn count(n: usize, noun: &str) -> String {
    format!("{n} {noun}{}", if n == 1 { "" } else { "s" })
}

/// The error and its causes joined by ": " on one line. A cause whose text an outer error
/// already quotes (as `"{path}: {source}"` messages do) is not repeated.
pub fn one_line(e: &anyhow::Error) -> String {
    let mut message = String::new();
    for cause in e.chain() {
        let text = cause.to_string().replace('\n', " ");
        if !message.contains(&text) {
            if !message.is_empty() {
                message.push_str(": ");
            }
            message.push_str(&text);
        }
    }
    message
}

#[cfg(test)]
mod tests {
    use super::one_line;

    #[test]
    fn a_count_of_one_is_singular() {
        let said = [0, 1, 4].map(|n| super::count(n, "view"));
        assert_eq!(said, ["0 views", "1 view", "4 views"]);
    }

    #[test]
    fn causes_are_joined_on_one_line_and_quoted_ones_not_repeated() {
        let cause = || std::io::Error::other("header\ntoo small");
        let e = anyhow::Error::new(cause()).context("reading a.ply");
        assert_eq!(one_line(&e), "reading a.ply: header too small");
        let e = anyhow::Error::new(cause()).context("a.ply: header too small");
        assert_eq!(one_line(&e), "a.ply: header too small");
    }
}
