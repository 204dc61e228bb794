//! View images on disk in the original dataset's layout ("shapenet-views"):
//! `locations_NNN.png` (16-bit RGB holding z, y, x) and `color_NNN.png` (8-bit RGB) per rig
//! camera NNN, so the original dataset and ours are interchangeable.

pub mod projection;
pub mod reprojection;

use crate::core::camera::{MIN_IMAGE_SIZE, RIG_SIZE};
use crate::core::frame::{Frame, UpAxis};
use crate::io::atomic_write;
use crate::views::projection::{ViewImages, CHANNELS};
use image::{ImageBuffer, ImageEncoder, Rgb, RgbImage};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum ViewError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: cannot decode PNG: {message}", path.display())]
    Decode { path: PathBuf, message: String },
    #[error("{}: {problem}", path.display())]
    Invalid { path: PathBuf, problem: String },
    #[error("{}: {source}", path.display())]
    Dir {
        path: PathBuf,
        source: crate::io::DirProblem,
    },
    #[error("{}: no locations_NNN.png view images in this directory", path.display())]
    NoViews { path: PathBuf },
    #[error("{}: view {camera:03} is missing", path.display())]
    MissingView { path: PathBuf, camera: usize },
}

/// Lowest code of an occupied pixel; 0 means empty.
const CODE_MIN: f64 = 300.0;
const CODE_RANGE: f64 = 65000.0;
const COORD_MIN: f64 = -0.51;
const COORD_RANGE: f64 = 1.02;

/// The original's encoding `trunc(300 + 65000·(c + 0.51)/1.02)`, clamped to the code range so
/// an occupied pixel never reads as empty.
pub fn encode_coordinate(c: f32) -> u16 {
    let v = CODE_MIN + CODE_RANGE * (c as f64 - COORD_MIN) / COORD_RANGE;
    v.clamp(CODE_MIN, CODE_MIN + CODE_RANGE) as u16
}

/// Decodes to the centre of the code's bin, half a bin (7.8e-6) above the original's formula:
/// unbiased, and re-encoding a decoded value gives back the same code despite f32 rounding.
pub fn decode_coordinate(v: u16) -> f32 {
    (COORD_MIN + COORD_RANGE * (v as f64 - CODE_MIN + 0.5) / CODE_RANGE) as f32
}

/// What `project` records beside the views (`frame.json`) so that `reproject` can return to
/// the input's frame.
#[derive(Debug, Serialize, Deserialize)]
pub struct ViewsInfo {
    pub frame: Frame,
    pub up: UpAxis,
    pub views: Vec<usize>,
    pub size: usize,
    pub points: usize,
}

/// The name of [`ViewsInfo`]'s file in a view directory.
pub const INFO_FILE: &str = "frame.json";

impl ViewsInfo {
    pub fn write(&self, dir: &Path) -> Result<(), ViewError> {
        let path = dir.join(INFO_FILE);
        atomic_write(&path, |w| {
            serde_json::to_writer_pretty(&mut *w, self).map_err(std::io::Error::other)
        })
        .map_err(|source| ViewError::Io { path, source })
    }

    /// The info of view directory `dir`; `None` when it has none.
    pub fn read(dir: &Path) -> Result<Option<ViewsInfo>, ViewError> {
        let path = dir.join(INFO_FILE);
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => return Err(ViewError::Io { path, source }),
        };
        ViewsInfo::from_json(&bytes)
            .map(Some)
            .map_err(|problem| ViewError::Invalid { path, problem })
    }

    /// Parses a `frame.json`, refusing frames that cannot map points back (zero or non-finite
    /// scale or offsets).
    pub fn from_json(bytes: &[u8]) -> Result<ViewsInfo, String> {
        let info: ViewsInfo =
            serde_json::from_slice(bytes).map_err(|e| format!("not a valid frame file: {e}"))?;
        info.frame.check()?;
        Ok(info)
    }
}

pub fn locations_path(dir: &Path, camera: usize) -> PathBuf {
    dir.join(format!("locations_{camera:03}.png"))
}

pub fn color_path(dir: &Path, camera: usize) -> PathBuf {
    dir.join(format!("color_{camera:03}.png"))
}

fn encode_png(
    path: &Path,
    width: u32,
    bytes: &[u8],
    color: image::ExtendedColorType,
) -> Result<(), ViewError> {
    atomic_write(path, |w| {
        image::codecs::png::PngEncoder::new(w)
            .write_image(bytes, width, width, color)
            .map_err(std::io::Error::other)
    })
    .map_err(|source| ViewError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes every view as a `locations_NNN.png` / `color_NNN.png` pair into `dir`.
pub fn write_views(dir: &Path, images: &ViewImages) -> Result<(), ViewError> {
    let s = images.size;
    let plane = s * s;
    for (v, &camera) in images.cameras.iter().enumerate() {
        let px = images.view_pixels(v);
        let occ = images.view_occupancy(v);
        let mut locations = vec![0u8; plane * 6];
        let mut colors = vec![0u8; plane * 3];
        for at in 0..plane {
            if !occ[at] {
                continue;
            }
            // R, G, B = z, y, x.
            for (slot, channel) in [2, 1, 0].into_iter().enumerate() {
                let code = encode_coordinate(px[channel * plane + at]);
                // The encoder takes 16-bit samples in memory order and swaps them for PNG.
                locations[at * 6 + slot * 2..at * 6 + slot * 2 + 2]
                    .copy_from_slice(&code.to_ne_bytes());
            }
            for c in 0..3 {
                colors[at * 3 + c] =
                    (px[(3 + c) * plane + at] * 255.0).round().clamp(0.0, 255.0) as u8;
            }
        }
        encode_png(
            &locations_path(dir, camera),
            s as u32,
            &locations,
            image::ExtendedColorType::Rgb16,
        )?;
        if images.has_color {
            encode_png(
                &color_path(dir, camera),
                s as u32,
                &colors,
                image::ExtendedColorType::Rgb8,
            )?;
        }
    }
    Ok(())
}

/// The largest view side read, the largest the cameras render: a 16-bit RGB image of it decodes
/// to 96 MiB, so a header claiming more is refused before anything is decoded.
pub const MAX_VIEW_SIZE: u32 = crate::core::camera::MAX_IMAGE_SIZE as u32;

fn open(path: &Path) -> Result<image::DynamicImage, ViewError> {
    let io = |source| ViewError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut reader = image::ImageReader::open(path)
        .map_err(io)?
        .with_guessed_format()
        .map_err(io)?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_VIEW_SIZE);
    limits.max_image_height = Some(MAX_VIEW_SIZE);
    reader.limits(limits);
    reader.decode().map_err(|e| match e {
        image::ImageError::Limits(_) => ViewError::Invalid {
            path: path.to_path_buf(),
            problem: format!(
                "the image exceeds {MAX_VIEW_SIZE}×{MAX_VIEW_SIZE} px, the largest view read"
            ),
        },
        e => ViewError::Decode {
            path: path.to_path_buf(),
            message: e.to_string(),
        },
    })
}

fn list(dir: &Path) -> Result<std::fs::ReadDir, ViewError> {
    crate::io::read_dir(dir).map_err(|source| ViewError::Dir {
        path: dir.to_path_buf(),
        source,
    })
}

/// Rig cameras that have a `locations_NNN.png` in `dir`, ascending.
pub fn find_views(dir: &Path) -> Result<Vec<usize>, ViewError> {
    let entries = list(dir)?;
    let mut cameras: Vec<usize> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            let n = name.strip_prefix("locations_")?.strip_suffix(".png")?;
            n.parse::<usize>()
                .ok()
                .filter(|i| (1..=RIG_SIZE).contains(i))
        })
        .collect();
    cameras.sort_unstable();
    if cameras.is_empty() {
        return Err(ViewError::NoViews {
            path: dir.to_path_buf(),
        });
    }
    Ok(cameras)
}

/// Reads the views `cameras` (or all found) from `dir`. Colour is read when the first view has
/// a `color_NNN.png`; a later view without one keeps zero RGB.
pub fn read_views(dir: &Path, cameras: Option<&[usize]>) -> Result<ViewImages, ViewError> {
    let cameras = match cameras {
        Some(c) => {
            // A missing folder is said as such, not as its first view missing.
            list(dir)?;
            c.to_vec()
        }
        None => find_views(dir)?,
    };
    let mut images: Option<ViewImages> = None;
    for (v, &camera) in cameras.iter().enumerate() {
        let lpath = locations_path(dir, camera);
        let locations = read_locations(dir, camera)?;
        let s = locations.width() as usize;
        let cpath = color_path(dir, camera);
        let images =
            images.get_or_insert_with(|| ViewImages::empty(cameras.clone(), s, cpath.exists()));
        if images.size != s {
            return Err(ViewError::Invalid {
                path: lpath,
                problem: format!("size {s} differs from the first view's {}", images.size),
            });
        }
        let color = if images.has_color && cpath.exists() {
            Some(read_color(&cpath, locations.dimensions())?)
        } else {
            None
        };
        let plane = s * s;
        let px = &mut images.pixels[v * CHANNELS * plane..(v + 1) * CHANNELS * plane];
        let occ = &mut images.occupancy[v * plane..(v + 1) * plane];
        decode_view(&locations, color.as_ref(), px, occ);
    }
    Ok(images.expect("find_views returns at least one camera"))
}

/// Camera `camera`'s `locations_NNN.png` in `dir`: a square 16-bit RGB image of at least 8 px.
fn read_locations(dir: &Path, camera: usize) -> Result<ImageBuffer<Rgb<u16>, Vec<u16>>, ViewError> {
    let path = locations_path(dir, camera);
    if !path.exists() {
        return Err(ViewError::MissingView {
            path: dir.to_path_buf(),
            camera,
        });
    }
    let invalid = |problem: String| ViewError::Invalid {
        path: path.clone(),
        problem,
    };
    let locations = match open(&path)? {
        image::DynamicImage::ImageRgb16(buf) => buf,
        other => {
            return Err(invalid(format!(
                "expected a 16-bit RGB image, found {:?}",
                other.color()
            )))
        }
    };
    let (w, h) = locations.dimensions();
    if w != h || (w as usize) < MIN_IMAGE_SIZE {
        return Err(invalid(format!(
            "expected a square image of at least {MIN_IMAGE_SIZE} px, found {w}×{h}"
        )));
    }
    Ok(locations)
}

/// A `color_NNN.png` that must be as large as its locations image, `size`.
fn read_color(path: &Path, size: (u32, u32)) -> Result<RgbImage, ViewError> {
    let color = open(path)?.to_rgb8();
    if color.dimensions() != size {
        return Err(ViewError::Invalid {
            path: path.to_path_buf(),
            problem: format!(
                "size {:?} differs from its locations image",
                color.dimensions()
            ),
        });
    }
    Ok(color)
}

/// Decodes one view's images into its planes: `px` holds the view's six planes of S × S
/// values (x, y, z, r, g, b), `occ` its S × S occupancy. Pixels coded 0 stay empty.
fn decode_view(
    locations: &ImageBuffer<Rgb<u16>, Vec<u16>>,
    color: Option<&RgbImage>,
    px: &mut [f32],
    occ: &mut [bool],
) {
    let plane = occ.len();
    for (at, p) in locations.pixels().enumerate() {
        let [z, y, x] = p.0;
        if x == 0 && y == 0 && z == 0 {
            continue;
        }
        occ[at] = true;
        px[at] = decode_coordinate(x);
        px[plane + at] = decode_coordinate(y);
        px[2 * plane + at] = decode_coordinate(z);
        if let Some(color) = color {
            let rgb = color.as_raw();
            for c in 0..3 {
                px[(3 + c) * plane + at] = rgb[at * 3 + c] as f32 / 255.0;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::camera::Camera;
    use crate::views::projection::project;
    use image::{ImageBuffer, Rgb};

    /// Raw 16-bit samples of a `locations_NNN.png`, for bit-exact comparisons.
    fn read_location_codes(path: &Path) -> Result<ImageBuffer<Rgb<u16>, Vec<u16>>, ViewError> {
        match open(path)? {
            image::DynamicImage::ImageRgb16(buf) => Ok(buf),
            other => Err(ViewError::Invalid {
                path: path.to_path_buf(),
                problem: format!("expected a 16-bit RGB image, found {:?}", other.color()),
            }),
        }
    }

    #[test]
    fn every_code_survives_decode_and_encode() {
        for v in 300..=65300u16 {
            assert_eq!(encode_coordinate(decode_coordinate(v)), v);
        }
    }

    #[test]
    fn coordinates_are_encoded_within_one_bin() {
        for i in 0..=1000 {
            let c = -0.5 + i as f32 / 1000.0;
            let back = decode_coordinate(encode_coordinate(c));
            assert!(
                (back - c).abs() <= 0.5 * 1.02 / 65000.0 + 1e-7,
                "{c} → {back}"
            );
        }
        assert_eq!(encode_coordinate(-0.51), 300);
        assert_eq!(encode_coordinate(-2.0), 300);
        assert_eq!(encode_coordinate(0.6), 65300);
        assert!(encode_coordinate(0.51) >= 65299);
    }

    #[test]
    fn views_round_trip_through_png_files() {
        let dir = tempfile::tempdir().unwrap();
        let points: Vec<[f32; 3]> = (0..500)
            .map(|i| {
                let t = i as f32 / 500.0;
                [0.3 * (t * 20.0).sin(), 0.2 * (t * 7.0).cos(), t - 0.5]
            })
            .collect();
        let colors: Vec<[u8; 3]> = (0..500).map(|i| [i as u8, 255 - i as u8, 7]).collect();
        let img = project(
            &points,
            Some(&colors),
            &Camera::set(&[5, 10, 17], 64).unwrap(),
        );
        write_views(dir.path(), &img).unwrap();
        assert_eq!(find_views(dir.path()).unwrap(), vec![5, 10, 17]);
        let back = read_views(dir.path(), None).unwrap();
        assert_eq!(back.occupancy, img.occupancy);
        for (a, b) in img.pixels.iter().zip(&back.pixels) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
    }

    #[ignore = "needs ../shared/reference"]
    #[test]
    fn reference_bus_views_re_encode_bit_identically() {
        let root =
            std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/reference/views");
        assert!(root.is_dir(), "{} is absent", root.display());
        let out = tempfile::tempdir().unwrap();
        let model = "02924116/3e0c9a10f8e200be17b44457cd291bcc";
        for dir in [
            root.join("GT/train").join(model),
            root.join("in/train").join(model).join("1"),
        ] {
            let views = read_views(&dir, None).unwrap();
            assert_eq!(views.cameras, (5..=15).collect::<Vec<_>>());
            assert!(views.occupied() > 1000);
            write_views(out.path(), &views).unwrap();
            for &cam in &views.cameras {
                let a = read_location_codes(&locations_path(&dir, cam)).unwrap();
                let b = read_location_codes(&locations_path(out.path(), cam)).unwrap();
                assert!(a == b, "locations_{cam:03} differs");
                let a = open(&color_path(&dir, cam)).unwrap().to_rgb8();
                let b = open(&color_path(out.path(), cam)).unwrap().to_rgb8();
                assert!(a == b, "color_{cam:03} differs");
            }
        }
    }
}
