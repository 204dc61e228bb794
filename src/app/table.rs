//! The one way reports reach a person or a program: a typed report renders itself as a text
//! table, and [`export`] writes either that or the report as JSON.

use serde::Serialize;

/// Text rows with a left-aligned name column and right-aligned value columns.
#[derive(Debug, Default)]
pub struct Table {
    pub lines: Vec<String>,
}

impl Table {
    pub fn row(&mut self, name: &str, cells: &[String]) {
        let mut line = format!("{name:<24}");
        for c in cells {
            line += &format!(" {c:>12}");
        }
        self.lines.push(line);
    }

    /// An empty line between two tables (none before the first).
    pub fn blank(&mut self) {
        if !self.lines.is_empty() {
            self.lines.push(String::new());
        }
    }
}

/// A report that a person reads as a table and a program as JSON.
pub trait Report: Serialize {
    fn table(&self) -> Table;
}

/// How a report is written out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Export {
    Json,
    Table,
}

/// The report as pretty JSON or its table's lines.
pub fn export(report: &impl Report, how: Export) -> Result<Vec<String>, serde_json::Error> {
    Ok(match how {
        Export::Json => vec![serde_json::to_string_pretty(report)?],
        Export::Table => report.table().lines,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Serialize)]
    struct One {
        value: f64,
    }

    impl Report for One {
        fn table(&self) -> Table {
            let mut t = Table::default();
            t.row("value", &[format!("{}", self.value)]);
            t
        }
    }

    #[test]
    fn a_report_exports_as_its_table_or_as_json() {
        let report = One { value: 0.5 };
        let table = export(&report, Export::Table).unwrap();
        assert_eq!(table, vec![format!("{:<24} {:>12}", "value", "0.5")]);
        let json = export(&report, Export::Json).unwrap();
        assert_eq!(json, vec!["{\n  \"value\": 0.5\n}".to_string()]);
    }

    #[test]
    fn no_blank_line_opens_a_table() {
        let mut t = Table::default();
        t.blank();
        assert!(t.lines.is_empty());
        t.row("a", &[]);
        t.blank();
        assert_eq!(t.lines.len(), 2);
    }
}
