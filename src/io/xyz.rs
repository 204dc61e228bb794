//! XYZ text: `x y z [r g b]` per line, separated by whitespace or commas; `#` comments and a
//! non-numeric header line are skipped.

use super::{max_points, Problem};
use crate::core::cloud::PointCloud;
use std::io::Write;
use std::path::Path;

pub(super) fn read(path: &Path) -> Result<PointCloud, Problem> {
    let text = std::fs::read_to_string(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::InvalidData => Problem::Malformed("file is not text".into()),
        _ => Problem::Io(e),
    })?;
    let limit = max_points();
    let mut positions = Vec::new();
    let mut colors: Vec<[f64; 3]> = Vec::new();
    let mut columns = None;
    let mut values: Vec<f64> = Vec::with_capacity(8);
    for (line_no, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let at = |problem: String| Problem::Malformed(format!("line {}: {problem}", line_no + 1));
        if let Err(tok) = parse_values(line, &mut values) {
            // A column-name line before the first point is a header, not an error.
            if columns.is_none()
                && positions.is_empty()
                && !tok.starts_with(|c: char| c.is_ascii_digit())
            {
                continue;
            }
            return Err(at(format!("{tok:?} is not a number")));
        }
        if positions.len() >= limit {
            return Err(Problem::TooManyPoints {
                points: positions.len() + 1,
                limit,
            });
        }
        let n = values.len();
        if n != 3 && n < 6 {
            return Err(at(format!("{n} values, expected x y z or x y z r g b")));
        }
        match columns {
            None => columns = Some(n),
            Some(c) if c != n => {
                return Err(at(format!("{n} values where earlier lines have {c}")))
            }
            Some(_) => {}
        }
        positions.push([values[0], values[1], values[2]]);
        if n >= 6 {
            colors.push([values[3], values[4], values[5]]);
        }
    }
    Ok(PointCloud {
        positions,
        colors: (!colors.is_empty()).then(|| to_bytes(&colors)),
        ..Default::default()
    })
}

/// The numbers of one line, separated by whitespace or commas, into `values`; the first token
/// that is not a number is the error.
fn parse_values<'a>(line: &'a str, values: &mut Vec<f64>) -> Result<(), &'a str> {
    values.clear();
    for tok in line
        .split(|c: char| c == ',' || c.is_whitespace())
        .filter(|t| !t.is_empty())
    {
        values.push(tok.parse::<f64>().map_err(|_| tok)?);
    }
    Ok(())
}

/// Colours are 0–255, unless every value lies in [0, 1] and one is fractional.
fn to_bytes(colors: &[[f64; 3]]) -> Vec<[u8; 3]> {
    let unit = colors.iter().flatten().all(|v| (0.0..=1.0).contains(v))
        && colors.iter().flatten().any(|v| v.fract() != 0.0);
    let scale = if unit { 255.0 } else { 1.0 };
    colors
        .iter()
        .map(|c| c.map(|v| (v * scale).round().clamp(0.0, 255.0) as u8))
        .collect()
}

pub(super) fn write(w: &mut impl Write, cloud: &PointCloud) -> std::io::Result<()> {
    for (i, p) in cloud.positions.iter().enumerate() {
        write!(w, "{} {} {}", p[0], p[1], p[2])?;
        if let Some(c) = &cloud.colors {
            write!(w, " {} {} {}", c[i][0], c[i][1], c[i][2])?;
        }
        writeln!(w)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_str(text: &str) -> Result<PointCloud, Problem> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.xyz");
        std::fs::write(&path, text).unwrap();
        read(&path)
    }

    #[test]
    fn comma_and_space_separated_with_header_and_unit_colors() {
        let c = read_str("x,y,z,r,g,b\n1,2,3,0.5,1,0\n# note\n4 5 6 0 0.25 1\n").unwrap();
        assert_eq!(c.positions, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!(c.colors.unwrap(), vec![[128, 255, 0], [0, 64, 255]]);
    }

    #[test]
    fn bad_tokens_and_ragged_lines_are_errors_naming_the_line() {
        for (text, problem) in [
            ("1 2 3\n4 five 6\n", "line 2: \"five\" is not a number"),
            (
                "1 2 3\n4 5 6 7 8 9\n",
                "line 2: 6 values where earlier lines have 3",
            ),
            ("1 2\n", "line 1: 2 values, expected x y z or x y z r g b"),
        ] {
            let error = read_str(text).unwrap_err().to_string();
            assert!(error.contains(problem), "{error}");
        }
    }
}
