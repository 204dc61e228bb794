//! XYZ text: one point a line, its numbers separated by whitespace or commas, or by
//! semicolons with decimal points or commas (as spreadsheets write CSV where the comma is the
//! decimal mark); `#` comments are skipped. A header line before the points names the columns
//! (`x y z r g b intensity`, CloudCompare's `//X,Y,Z,R,G,B,…`); without one, the columns are
//! read by their count ([`Layout::by_count`]). A first line holding one count, as PTS files
//! begin, is skipped.

use super::{max_points, Problem};
use crate::core::cloud::{Attribute, PointCloud, ScalarKind};
use std::io::Write;
use std::path::Path;

/// The attribute a fourth column of four, or PTS's, is read as and written from.
pub(super) const INTENSITY: &str = "intensity";

/// What one column of the file holds.
#[derive(Debug, Clone, PartialEq)]
enum Column {
    /// Coordinate 0–2.
    Position(usize),
    /// Colour channel 0–2.
    Color(usize),
    Attribute(String),
}

/// The columns of every line, in order.
#[derive(Debug, PartialEq)]
struct Layout(Vec<Column>);

impl Layout {
    /// Columns as a header names them: x, y and z (any case) must be among them; r/red, g/green
    /// and b/blue are the colour where all three are, anything else an attribute of its name.
    fn by_name(names: &[String]) -> Option<Layout> {
        let find = |wanted: &[&str]| {
            names
                .iter()
                .position(|n| wanted.iter().any(|w| n.eq_ignore_ascii_case(w)))
        };
        let xyz = [find(&["x"])?, find(&["y"])?, find(&["z"])?];
        let rgb = [
            find(&["r", "red"]),
            find(&["g", "green"]),
            find(&["b", "blue"]),
        ];
        let has_color = rgb.iter().all(Option::is_some);
        let columns = names
            .iter()
            .enumerate()
            .map(|(k, name)| {
                if let Some(axis) = xyz.iter().position(|&at| at == k) {
                    Column::Position(axis)
                } else if let Some(channel) = rgb.iter().position(|&at| has_color && at == Some(k))
                {
                    Column::Color(channel)
                } else {
                    Column::Attribute(name.clone())
                }
            })
            .collect();
        Some(Layout(columns))
    }

    /// Columns without a header, by their count: `x y z`, `x y z intensity`, `x y z r g b`
    /// (PTS: `x y z intensity r g b`); columns beyond, and columns 4–6 where they are not
    /// colours, are attributes named by their place (`column_4`).
    fn by_count(n: usize, pts: bool, colors_at_4: bool) -> Layout {
        let first_color = match n {
            4 => return Layout::named(&["x", "y", "z", INTENSITY]),
            7 if pts => Some(4),
            _ if n >= 6 && colors_at_4 => Some(3),
            _ => None,
        };
        let columns = (0..n).map(|k| match (k, first_color) {
            (0..=2, _) => Column::Position(k),
            (_, Some(first)) if (first..first + 3).contains(&k) => Column::Color(k - first),
            (3, _) if pts && n == 7 => Column::Attribute(INTENSITY.into()),
            _ => Column::Attribute(format!("column_{}", k + 1)),
        });
        Layout(columns.collect())
    }

    fn named(names: &[&str]) -> Layout {
        let names: Vec<String> = names.iter().map(|n| n.to_string()).collect();
        Layout::by_name(&names).expect("x, y and z are named")
    }
}

/// The numbers of the text's lines that hold points, a column each, and the header's names
/// where one came before them.
struct Table {
    header: Option<Vec<String>>,
    columns: Vec<Vec<f64>>,
}

pub(super) fn read(path: &Path) -> Result<PointCloud, Problem> {
    let text = std::fs::read_to_string(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::InvalidData => Problem::Malformed("file is not text".into()),
        _ => Problem::Io(e),
    })?;
    let table = table(&text)?;
    let pts = is_pts(path);
    let colors_at_4 = table.columns.len() >= 6 && looks_like_colors(&table.columns[3..6]);
    let layout = table
        .header
        .as_deref()
        .filter(|names| names.len() == table.columns.len())
        .and_then(Layout::by_name)
        .unwrap_or_else(|| Layout::by_count(table.columns.len(), pts, colors_at_4));
    Ok(cloud(table.columns, &layout))
}

/// The most values (all columns together, 128 MiB) reserved before they are read.
const RESERVED_VALUES: usize = 1 << 24;

/// The numbers of every line of `text`, each line holding as many as the first.
fn table(text: &str) -> Result<Table, Problem> {
    let limit = max_points();
    let mut header = None;
    let mut columns: Option<Vec<Vec<f64>>> = None;
    let mut row: Vec<f64> = Vec::with_capacity(8);
    for (line_no, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let at = |problem: String| Problem::Malformed(format!("line {}: {problem}", line_no + 1));
        if let Err(tok) = parse_values(line, &mut row) {
            // A column-name line before the first point is a header, not an error; one that
            // begins like a number is a point that could not be read.
            if columns.is_none()
                && tok.starts_with(|c: char| c.is_alphabetic() || "/_\"'".contains(c))
            {
                header = Some(names(line));
                continue;
            }
            return Err(at(format!("{tok:?} is not a number")));
        }
        let n = row.len();
        if columns.is_none() && n == 1 && row[0] >= 0.0 && row[0].fract() == 0.0 {
            // The point count PTS files begin with.
            continue;
        }
        if n < 3 {
            let values = if n == 1 {
                "one value".into()
            } else {
                format!("{n} values")
            };
            return Err(at(format!("{values}, expected at least x y z")));
        }
        // Sized for the lines left, so that no column is copied as it grows, up to a bound: the
        // lines may be comments, and a file of newlines must not reserve gigabytes.
        let columns = columns.get_or_insert_with(|| {
            let lines = text.bytes().filter(|&b| b == b'\n').count() + 1 - line_no;
            let reserve = lines.min(RESERVED_VALUES / n);
            (0..n).map(|_| Vec::with_capacity(reserve)).collect()
        });
        if columns.len() != n {
            let c = columns.len();
            return Err(at(format!("{n} values where earlier lines have {c}")));
        }
        if columns[0].len() >= limit {
            return Err(Problem::TooManyPoints {
                points: columns[0].len() + 1,
                limit,
            });
        }
        columns.iter_mut().zip(&row).for_each(|(c, &v)| c.push(v));
    }
    Ok(Table {
        header,
        columns: columns.unwrap_or_default(),
    })
}

/// A header line's names: separated by semicolons or else commas where it has any (names may
/// hold spaces then, which become `_`), else by whitespace; without quotes or CloudCompare's
/// leading `//`; a name that comes again gets a number.
fn names(line: &str) -> Vec<String> {
    let line = line.trim_start_matches('/');
    let tokens: Vec<&str> =
        if let Some(separator) = [';', ','].into_iter().find(|&s| line.contains(s)) {
            line.split(separator).collect()
        } else {
            line.split_whitespace().collect()
        };
    let mut names: Vec<String> = Vec::with_capacity(tokens.len());
    for token in tokens.into_iter().filter(|t| !t.trim().is_empty()) {
        let base: String = token
            .trim()
            .trim_matches(|c| c == '"' || c == '\'')
            .split_whitespace()
            .collect::<Vec<_>>()
            .join("_");
        let name = super::free_name(&base, |n| names.iter().any(|m| m == n));
        names.push(name);
    }
    names
}

/// Whether three columns hold colours: 0–255 in whole numbers, or 0–1.
fn looks_like_colors(columns: &[Vec<f64>]) -> bool {
    let values = || columns.iter().flatten();
    values().all(|v| (0.0..=255.0).contains(v))
        && (values().all(|v| v.fract() == 0.0) || values().all(|&v| v <= 1.0))
}

/// The cloud `columns` hold when read as `layout` says.
fn cloud(columns: Vec<Vec<f64>>, layout: &Layout) -> PointCloud {
    let points = columns.first().map_or(0, Vec::len);
    let mut positions = vec![[0.0; 3]; points];
    let mut rgb: [Vec<f64>; 3] = Default::default();
    let mut attributes = Vec::new();
    for (values, what) in columns.into_iter().zip(&layout.0) {
        match what {
            Column::Position(axis) => {
                let axis = *axis;
                positions
                    .iter_mut()
                    .zip(values)
                    .for_each(|(p, v)| p[axis] = v);
            }
            Column::Color(channel) => rgb[*channel] = values,
            Column::Attribute(name) => {
                let (kind, values) = typed(values);
                attributes.push(Attribute {
                    name: name.clone(),
                    kind,
                    values,
                });
            }
        }
    }
    let has_colors = layout.0.iter().any(|c| matches!(c, Column::Color(_)));
    PointCloud {
        positions,
        colors: has_colors.then(|| to_bytes(&rgb)),
        attributes,
        ..Default::default()
    }
}

/// The smallest kind that holds every value exactly, so that a PLY or PCD output stores
/// whole-number columns (intensities, labels) as integers, and the values in it: f32 where
/// every value has at most the 6 significant digits an f32 keeps (0.1 stays 0.1 when printed).
fn typed(mut values: Vec<f64>) -> (ScalarKind, Vec<f64>) {
    let within = |lo: f64, hi: f64| {
        values
            .iter()
            .all(|&v| v.fract() == 0.0 && (lo..=hi).contains(&v))
    };
    let kind = if within(0.0, 255.0) {
        ScalarKind::U8
    } else if within(0.0, 65535.0) {
        ScalarKind::U16
    } else if within(-32768.0, 32767.0) {
        ScalarKind::I16
    } else if within(i32::MIN as f64, i32::MAX as f64) {
        ScalarKind::I32
    } else if values.iter().all(|&v| !v.is_finite() || short(v)) {
        values.iter_mut().for_each(|v| *v = f64::from(*v as f32));
        ScalarKind::F32
    } else {
        ScalarKind::F64
    };
    (kind, values)
}

/// Whether `v` is a decimal of at most 6 significant digits within f32's normal range.
fn short(v: f64) -> bool {
    if v == 0.0 {
        return true;
    }
    if !(v as f32).is_normal() {
        return false;
    }
    let shift = 5 - v.abs().log10().floor() as i32;
    let digits = (v * 10f64.powi(shift)).round();
    digits / 10f64.powi(shift) == v
}

/// The numbers of one line into `values`: separated by semicolons where it has any, else by
/// whitespace where [`decimal_commas`] says its commas are decimal marks, else by whitespace or
/// commas; the first token that is not a number is the error.
fn parse_values<'a>(line: &'a str, values: &mut Vec<f64>) -> Result<(), &'a str> {
    values.clear();
    let semicolons = line.contains(';');
    let comma_decimals = semicolons || decimal_commas(line);
    let separates = |c: char| match (semicolons, comma_decimals) {
        (true, _) => c == ';',
        (false, true) => c.is_whitespace(),
        (false, false) => c == ',' || c.is_whitespace(),
    };
    for tok in line
        .split(separates)
        .map(str::trim)
        .filter(|t| !t.is_empty())
    {
        let number = match tok.parse() {
            Err(_) if comma_decimals => tok.replacen(',', ".", 1).parse(),
            parsed => parsed,
        };
        values.push(number.map_err(|_| tok)?);
    }
    Ok(())
}

/// Whether a line separated by whitespace writes its decimals with commas (`1,5 -2,25 3`): three
/// words or more, one with a comma at least, and every comma alone in its word between two
/// digits. Read as separators, such commas would make six numbers of three, silently.
fn decimal_commas(line: &str) -> bool {
    let decimal = |word: &str| {
        word.split_once(',').is_none_or(|(whole, fraction)| {
            whole.ends_with(|c: char| c.is_ascii_digit())
                && fraction.starts_with(|c: char| c.is_ascii_digit())
                && !fraction.contains(',')
        })
    };
    line.contains(',')
        && line.split_whitespace().nth(2).is_some()
        && line.split_whitespace().all(decimal)
}

/// Colours are 0–255, unless every value lies in [0, 1] and one is fractional.
fn to_bytes(rgb: &[Vec<f64>; 3]) -> Vec<[u8; 3]> {
    let values = || rgb.iter().flatten();
    let unit = values().all(|v| (0.0..=1.0).contains(v)) && values().any(|v| v.fract() != 0.0);
    let scale = if unit { 255.0 } else { 1.0 };
    let byte = |v: f64| (v * scale).round().clamp(0.0, 255.0) as u8;
    (0..rgb[0].len())
        .map(|i| [byte(rgb[0][i]), byte(rgb[1][i]), byte(rgb[2][i])])
        .collect()
}

/// Whether `path` names a Leica PTS file: its point count, then `x y z intensity [r g b]`.
pub(super) fn is_pts(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("pts"))
}

/// `x y z [r g b]` a line; for PTS, the count first and the intensity after the coordinates
/// wherever there is one or colours follow (0 where the cloud has none).
pub(super) fn write(w: &mut impl Write, cloud: &PointCloud, pts: bool) -> std::io::Result<()> {
    let intensity = cloud.attribute(INTENSITY).map(|a| &a.values[..]);
    let intensity = (pts && (intensity.is_some() || cloud.colors.is_some()))
        .then_some(intensity.unwrap_or(&[]));
    if pts {
        writeln!(w, "{}", cloud.len())?;
    }
    for (i, p) in cloud.positions.iter().enumerate() {
        write!(w, "{} {} {}", p[0], p[1], p[2])?;
        if let Some(values) = intensity {
            write!(w, " {}", values.get(i).copied().unwrap_or(0.0))?;
        }
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
        read_named("t.xyz", text)
    }

    fn read_named(name: &str, text: &str) -> Result<PointCloud, Problem> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        read(&path)
    }

    fn column(cloud: &PointCloud, name: &str) -> (ScalarKind, Vec<f64>) {
        let a = cloud.attribute(name).unwrap_or_else(|| panic!("no {name}"));
        (a.kind, a.values.clone())
    }

    /// A PTS file (a count, then `x y z intensity r g b`) failed on its count line ("1
    /// values"), and would have read its intensity as red; `x y z intensity` was refused.
    #[test]
    fn pts_files_and_intensity_columns() {
        let pts = "2\n1 2 3 -1200 255 10 0\n4 5 6 300 0 20 255\n";
        let c = read_named("scan.pts", pts).unwrap();
        assert_eq!(c.positions, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!(c.colors.as_deref(), Some(&[[255, 10, 0], [0, 20, 255]][..]));
        assert_eq!(
            column(&c, "intensity"),
            (ScalarKind::I16, vec![-1200.0, 300.0])
        );
        let c = read_str("1 2 3 0.25\n4 5 6 0.5\n").unwrap();
        assert_eq!(column(&c, "intensity"), (ScalarKind::F32, vec![0.25, 0.5]));
        assert!(c.colors.is_none());
    }

    /// A `.pts` output was `x y z r g b` lines without the count, which PTS readers take for
    /// a point and whose fourth column they read as the intensity. It is written as PTS, and
    /// reads back as it was (a cloud with colours and no intensity gets intensity 0).
    #[test]
    fn pts_files_are_written_as_pts() {
        let source = "3\n1 2 3 -1200 255 10 0\n4 5 6 300 0 20 255\n7 8 9.5 0 1 2 3\n";
        let cloud = read_named("scan.pts", source).unwrap();
        let written = |cloud: &PointCloud, pts| {
            let mut text = Vec::new();
            write(&mut text, cloud, pts).unwrap();
            String::from_utf8(text).unwrap()
        };
        assert_eq!(written(&cloud, true), source);
        assert_eq!(
            read_named("again.pts", source).unwrap().positions,
            cloud.positions
        );
        assert!(written(&cloud, false).starts_with("1 2 3 255 10 0\n"));
        let mut bare = cloud.clone();
        bare.attributes.clear();
        assert!(written(&bare, true).starts_with("3\n1 2 3 0 255 10 0\n"));
        bare.colors = None;
        assert!(written(&bare, true).starts_with("3\n1 2 3\n"));
        let with_intensity = read_named("b.pts", "2\n1 2 3 7\n4 5 6 8\n").unwrap();
        assert_eq!(written(&with_intensity, true), "2\n1 2 3 7\n4 5 6 8\n");
    }

    /// A header names the columns, in any order and case (CloudCompare's `//X,Y,Z,…`, names
    /// with spaces between commas); columns past the colour were dropped, and are kept.
    #[test]
    fn a_header_names_the_columns() {
        let c = read_str("//X,Y,Z,R,G,B,Scalar field\n1,2,3,10,20,30,0.1\n").unwrap();
        assert_eq!(c.positions, vec![[1.0, 2.0, 3.0]]);
        assert_eq!(c.colors.as_deref(), Some(&[[10, 20, 30]][..]));
        assert_eq!(column(&c, "Scalar_field").1, [f64::from(0.1f32)]);
        let c = read_str("label z y x\n7 3 2 1\n").unwrap();
        assert_eq!(c.positions, vec![[1.0, 2.0, 3.0]]);
        assert_eq!(column(&c, "label"), (ScalarKind::U8, vec![7.0]));
        let c = read_str("x y z a a\n1 2 3 4 5\n").unwrap();
        assert_eq!(column(&c, "a_2").1, [5.0]);
    }

    /// Without a header, columns 4–6 are the colour only where they hold colours; normals
    /// (`x y z nx ny nz`) were read as colours and are attributes now; a seventh column is
    /// kept by its place.
    #[test]
    fn columns_without_a_header_are_read_by_their_count() {
        let c = read_str("1 2 3 0.1 -0.5 0.8\n").unwrap();
        assert!(c.colors.is_none());
        assert_eq!(column(&c, "column_5").1, [-0.5]);
        let c = read_str("1 2 3 10 20 30 1e300 9\n4 5 6 0 0 0 1e-40 9\n").unwrap();
        assert_eq!(c.colors.as_deref(), Some(&[[10, 20, 30], [0, 0, 0]][..]));
        assert_eq!(
            column(&c, "column_7"),
            (ScalarKind::F64, vec![1e300, 1e-40])
        );
        assert_eq!(column(&c, "column_8"), (ScalarKind::U8, vec![9.0; 2]));
        let c = read_str("1 2 3 1 2\n").unwrap();
        assert_eq!(c.attributes.len(), 2);
    }

    #[test]
    fn comma_and_space_separated_with_header_and_unit_colors() {
        let c = read_str("x,y,z,r,g,b\n1,2,3,0.5,1,0\n# note\n4 5 6 0 0.25 1\n").unwrap();
        assert_eq!(c.positions, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!(
            c.colors.as_deref(),
            Some(&[[128, 255, 0], [0, 64, 255]][..])
        );
    }

    /// Semicolon-separated CSV, as spreadsheets write it where the comma is the decimal mark,
    /// was read as one header line after another and said to contain no points; decimal commas
    /// between tabs or spaces were taken for separators.
    #[test]
    fn semicolons_separate_values_that_may_have_decimal_commas() {
        let c = read_str("X;Y;Z;Intensity\n-1,5;2.25;3;7\n4;-0,125 ; 6;8\n").unwrap();
        assert_eq!(c.positions, vec![[-1.5, 2.25, 3.0], [4.0, -0.125, 6.0]]);
        assert_eq!(column(&c, "Intensity").1, [7.0, 8.0]);
        // The same with tabs: each comma was a separator, so three numbers were read as six.
        let c = read_str("1,5\t-2,25\t3\n4\t-0,125\t6,0\n").unwrap();
        assert_eq!(c.positions, vec![[1.5, -2.25, 3.0], [4.0, -0.125, 6.0]]);
        let c = read_str("1, 2, 3\n1,2,3\n").unwrap();
        assert_eq!(c.positions, vec![[1.0, 2.0, 3.0]; 2]);
    }

    #[test]
    fn bad_tokens_and_ragged_lines_are_errors_naming_the_line() {
        for (text, problem) in [
            ("-1|2|3\n", "line 1: \"-1|2|3\" is not a number"),
            ("1;2,5,0;3\n", "line 1: \"2,5,0\" is not a number"),
            ("1 2 3\n4 five 6\n", "line 2: \"five\" is not a number"),
            (
                "1 2 3\n4 5 6 7 8 9\n",
                "line 2: 6 values where earlier lines have 3",
            ),
            ("1 2\n", "line 1: 2 values, expected at least x y z"),
        ] {
            let error = read_str(text).unwrap_err().to_string();
            assert!(error.contains(problem), "{error}");
        }
    }
}
