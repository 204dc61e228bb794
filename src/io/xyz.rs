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
        values.clear();
        let mut bad = None;
        for tok in line
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|t| !t.is_empty())
        {
            match tok.parse::<f64>() {
                Ok(v) => values.push(v),
                Err(_) => {
                    bad = Some(tok);
                    break;
                }
            }
        }
        if let Some(tok) = bad {
            // A column-name line before the first point is a header, not an error.
            if columns.is_none()
                && positions.is_empty()
                && !tok.starts_with(|c: char| c.is_ascii_digit())
            {
                continue;
            }
            return Err(Problem::Malformed(format!(
                "line {}: {tok:?} is not a number",
                line_no + 1
            )));
        }
        if positions.len() >= limit {
            return Err(Problem::TooManyPoints {
                points: positions.len() + 1,
                limit,
            });
        }
        let n = values.len();
        if n != 3 && n < 6 {
            return Err(Problem::Malformed(format!(
                "line {}: {n} values, expected x y z or x y z r g b",
                line_no + 1
            )));
        }
        match columns {
            None => columns = Some(n),
            Some(c) if c != n => {
                return Err(Problem::Malformed(format!(
                    "line {}: {n} values where earlier lines have {c}",
                    line_no + 1
                )))
            }
            Some(_) => {}
        }
        positions.push([values[0], values[1], values[2]]);
        if n >= 6 {
            colors.push([values[3], values[4], values[5]]);
        }
    }
    // Colours are 0–255, unless every value lies in [0, 1] and one is fractional.
    let unit = colors.iter().flatten().all(|v| (0.0..=1.0).contains(v))
        && colors.iter().flatten().any(|v| v.fract() != 0.0);
    let scale = if unit { 255.0 } else { 1.0 };
    let colors = (!colors.is_empty()).then(|| {
        colors
            .iter()
            .map(|c| c.map(|v| (v * scale).round().clamp(0.0, 255.0) as u8))
            .collect()
    });
    Ok(PointCloud {
        positions,
        colors,
        ..Default::default()
    })
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
    fn bad_tokens_and_ragged_lines_are_errors() {
        assert!(read_str("1 2 3\n4 five 6\n")
            .unwrap_err()
            .to_string()
            .contains("line 2"));
        assert!(read_str("1 2 3\n4 5 6 7 8 9\n").is_err());
        assert!(read_str("1 2\n").is_err());
    }
}
