//! The paper's virtual camera rig: the 20 vertices of a dodecahedron around the unit box,
//! each camera looking at the origin with image x horizontal.

use nalgebra::{Matrix3, Vector3};
use thiserror::Error;

/// Number of cameras in the rig.
pub const RIG_SIZE: usize = 20;
/// The paper's 4-view rig: above the object, 35° down, at the four diagonal corners.
pub const DEFAULT_VIEWS: [usize; 4] = [5, 6, 7, 8];
/// Image size the rig's intrinsics were defined for.
pub const REFERENCE_SIZE: usize = 256;
/// Focal length in pixels at [`REFERENCE_SIZE`].
pub const REFERENCE_FOCAL: f64 = 480.0;
/// The largest image side a camera renders: 16× the paper's 256². Four views of it already
/// take gigabytes, and a side of 100,000 asked a projection for 960 GB and aborted.
pub const MAX_IMAGE_SIZE: usize = 4096;

/// The smallest image side a camera renders: below it the rig's views hold too few pixels to
/// show any shape.
pub const MIN_IMAGE_SIZE: usize = 8;

#[derive(Debug, Error, PartialEq)]
pub enum CameraError {
    #[error("camera index {0} is outside the rig (1..={RIG_SIZE})")]
    OutOfRange(usize),
    #[error("camera {0} is listed twice")]
    Duplicate(usize),
    #[error("no cameras given")]
    NoViews,
    #[error("'{0}' is not a camera index")]
    NotAnIndex(String),
    #[error("image size must be at least {MIN_IMAGE_SIZE} pixels, got {0}")]
    TooSmall(usize),
    #[error("image size {0} is above the largest this build renders ({MAX_IMAGE_SIZE})")]
    TooLarge(usize),
}

/// Camera centres in units of `a = 1.2`, ordered as the original `cam_RT_NNN.txt` files.
fn unit_center(index: usize) -> [f64; 3] {
    let phi = (1.0 + 5f64.sqrt()) / 2.0;
    let ip = 1.0 / phi;
    const CUBE: [[f64; 3]; 8] = [
        [-1.0, -1.0, 1.0],
        [1.0, -1.0, 1.0],
        [1.0, -1.0, -1.0],
        [-1.0, -1.0, -1.0],
        [-1.0, 1.0, 1.0],
        [1.0, 1.0, 1.0],
        [1.0, 1.0, -1.0],
        [-1.0, 1.0, -1.0],
    ];
    match index {
        1..=8 => CUBE[index - 1],
        9 => [0.0, -ip, phi],
        10 => [0.0, ip, phi],
        11 => [0.0, -ip, -phi],
        12 => [0.0, ip, -phi],
        13 => [-ip, -phi, 0.0],
        14 => [-ip, phi, 0.0],
        15 => [ip, -phi, 0.0],
        16 => [ip, phi, 0.0],
        17 => [-phi, 0.0, ip],
        18 => [-phi, 0.0, -ip],
        19 => [phi, 0.0, ip],
        20 => [phi, 0.0, -ip],
        _ => unreachable!("camera index checked by the caller"),
    }
}

/// A pinhole camera, world → camera `q = R·p + t`, looking along its +z;
/// `col = f·qx/qz + c`, `row = f·qy/qz + c`.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// Rig index, 1-based as in the original file names.
    pub index: usize,
    pub rotation: Matrix3<f64>,
    pub translation: Vector3<f64>,
    pub focal: f64,
    pub principal: f64,
    pub size: usize,
}

impl Camera {
    /// Rig camera `index` (1..=20) for `size`×`size` images; the focal length scales with the
    /// image so every size sees the same field of view.
    pub fn rig(index: usize, size: usize) -> Result<Camera, CameraError> {
        if !(1..=RIG_SIZE).contains(&index) {
            return Err(CameraError::OutOfRange(index));
        }
        if size < MIN_IMAGE_SIZE {
            return Err(CameraError::TooSmall(size));
        }
        if size > MAX_IMAGE_SIZE {
            return Err(CameraError::TooLarge(size));
        }
        let center = Vector3::from(unit_center(index)) * 1.2;
        let forward = -center.normalize();
        let right = forward.cross(&Vector3::y()).normalize();
        let down = forward.cross(&right);
        let rotation =
            Matrix3::from_rows(&[right.transpose(), down.transpose(), forward.transpose()]);
        let translation = -(rotation * center);
        let scale = size as f64 / REFERENCE_SIZE as f64;
        Ok(Camera {
            index,
            rotation,
            translation,
            focal: REFERENCE_FOCAL * scale,
            principal: size as f64 / 2.0,
            size,
        })
    }

    /// The cameras of a view set.
    pub fn set(indices: &[usize], size: usize) -> Result<Vec<Camera>, CameraError> {
        check_view_set(indices)?;
        indices.iter().map(|&i| Camera::rig(i, size)).collect()
    }

    pub fn center(&self) -> Vector3<f64> {
        -(self.rotation.transpose() * self.translation)
    }

    /// `[R | t]` as the original `cam_RT_NNN.txt` holds it (3 rows of 4).
    pub fn extrinsics(&self) -> [[f64; 4]; 3] {
        [0, 1, 2].map(|r| {
            [
                self.rotation[(r, 0)],
                self.rotation[(r, 1)],
                self.rotation[(r, 2)],
                self.translation[r],
            ]
        })
    }

    /// The point at `p`'s depth (its distance along the optical axis) on the ray through the
    /// centre of pixel (`row`, `col`).
    pub fn on_ray(&self, row: usize, col: usize, p: [f64; 3]) -> [f64; 3] {
        let depth = (self.rotation * Vector3::from(p) + self.translation)[2];
        let at = |pixel: usize| (pixel as f64 + 0.5 - self.principal) / self.focal * depth;
        let q = Vector3::new(at(col), at(row), depth);
        (self.rotation.transpose() * (q - self.translation)).into()
    }

    /// The f32 projector the hot loop uses.
    pub fn projector(&self) -> Projector {
        let r = self.rotation.map(|v| v as f32);
        Projector {
            rows: [0, 1, 2].map(|i| [r[(i, 0)], r[(i, 1)], r[(i, 2)]]),
            t: self.translation.map(|v| v as f32).into(),
            focal: self.focal as f32,
            principal: self.principal as f32,
            size: self.size,
        }
    }
}

/// World → pixel in f32, with the window test.
#[derive(Debug, Clone, Copy)]
pub struct Projector {
    rows: [[f32; 3]; 3],
    t: [f32; 3],
    focal: f32,
    principal: f32,
    size: usize,
}

impl Projector {
    /// `(row, col, depth)` of a point, or `None` when it is behind the camera or outside the
    /// window (dropped, never clamped onto the border).
    #[inline]
    pub fn project(&self, p: [f32; 3]) -> Option<(usize, usize, f32)> {
        let q = [0, 1, 2].map(|i| {
            self.rows[i][0] * p[0] + self.rows[i][1] * p[1] + self.rows[i][2] * p[2] + self.t[i]
        });
        if q[2] <= 0.0 {
            return None;
        }
        let col = (self.focal * q[0] / q[2] + self.principal).floor();
        let row = (self.focal * q[1] / q[2] + self.principal).floor();
        let s = self.size as f32;
        if col >= 0.0 && col < s && row >= 0.0 && row < s {
            Some((row as usize, col as usize, q[2]))
        } else {
            None
        }
    }
}

pub fn check_view_set(indices: &[usize]) -> Result<(), CameraError> {
    if indices.is_empty() {
        return Err(CameraError::NoViews);
    }
    for (k, &i) in indices.iter().enumerate() {
        if !(1..=RIG_SIZE).contains(&i) {
            return Err(CameraError::OutOfRange(i));
        }
        if indices[..k].contains(&i) {
            return Err(CameraError::Duplicate(i));
        }
    }
    Ok(())
}

/// Parses a view set such as `5,6,7,8`.
pub fn parse_view_set(text: &str) -> Result<Vec<usize>, CameraError> {
    let views = text
        .split(',')
        .map(|s| {
            let s = s.trim();
            s.parse::<usize>()
                .map_err(|_| CameraError::NotAnIndex(s.to_string()))
        })
        .collect::<Result<Vec<_>, _>>()?;
    check_view_set(&views)?;
    Ok(views)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::{Path, PathBuf};

    /// Reads an original `cam_RT_NNN.txt` (3 rows of `R | t`).
    fn read_extrinsics(path: &Path) -> std::io::Result<[[f64; 4]; 3]> {
        let text = std::fs::read_to_string(path)?;
        let values: Vec<f64> = text
            .split_whitespace()
            .map(|t| t.parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))?;
        if values.len() != 12 {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("expected 12 numbers, found {}", values.len()),
            ));
        }
        let mut m = [[0.0; 4]; 3];
        for (k, v) in values.into_iter().enumerate() {
            m[k / 4][k % 4] = v;
        }
        Ok(m)
    }

    fn reference_cameras() -> PathBuf {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/reference/cameras");
        assert!(dir.is_dir(), "{} is absent", dir.display());
        dir
    }

    #[ignore = "needs ../shared/reference"]
    #[test]
    fn rig_matches_the_original_camera_files() {
        let dir = reference_cameras();
        for i in 1..=RIG_SIZE {
            let expected = read_extrinsics(&dir.join(format!("rig20/cam_RT_{i:03}.txt"))).unwrap();
            let got = Camera::rig(i, 256).unwrap().extrinsics();
            for r in 0..3 {
                for c in 0..4 {
                    assert!(
                        (expected[r][c] - got[r][c]).abs() < 1e-5,
                        "camera {i} [{r}][{c}]: {} vs {}",
                        expected[r][c],
                        got[r][c]
                    );
                }
            }
        }
        for (k, i) in DEFAULT_VIEWS.iter().enumerate() {
            let four = read_extrinsics(&dir.join(format!("rig4/cam_RT_{:03}.txt", k + 1))).unwrap();
            let twenty = read_extrinsics(&dir.join(format!("rig20/cam_RT_{i:03}.txt"))).unwrap();
            assert_eq!(four, twenty);
        }
    }

    #[test]
    fn rig_is_a_dodecahedron_at_the_papers_distance() {
        for i in 1..=RIG_SIZE {
            let cam = Camera::rig(i, 256).unwrap();
            assert!((cam.center().norm() - 2.0785).abs() < 1e-4);
            // Orthonormal and proper.
            let r = cam.rotation;
            assert!((r * r.transpose() - Matrix3::identity()).norm() < 1e-12);
            assert!((r.determinant() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn origin_lands_on_the_principal_point_at_any_size() {
        for size in [64, 256, 512] {
            let p = Camera::rig(6, size).unwrap().projector();
            let (row, col, depth) = p.project([0.0, 0.0, 0.0]).unwrap();
            assert_eq!((row, col), (size / 2, size / 2));
            assert!((depth - 2.0785).abs() < 1e-3);
        }
    }

    #[test]
    fn upper_views_see_up_as_image_up() {
        let p = Camera::rig(5, 256).unwrap().projector();
        let (row_low, _, _) = p.project([0.0, -0.4, 0.0]).unwrap();
        let (row_high, _, _) = p.project([0.0, 0.4, 0.0]).unwrap();
        assert!(row_high < row_low);
    }

    #[test]
    fn a_point_moved_onto_its_pixels_ray_keeps_its_depth() {
        let cam = Camera::rig(6, 64).unwrap();
        let p = [0.1, -0.2, 0.05];
        let (row, col, depth) = cam.projector().project(p.map(|v| v as f32)).unwrap();
        let centred = cam.on_ray(row, col, p);
        let c = cam.rotation * Vector3::from(centred) + cam.translation;
        assert!((c[2] - depth as f64).abs() < 1e-5);
        assert!((cam.focal * c[0] / c[2] + cam.principal - (col as f64 + 0.5)).abs() < 1e-9);
        assert!((cam.focal * c[1] / c[2] + cam.principal - (row as f64 + 0.5)).abs() < 1e-9);
        assert!((Vector3::from(centred) - Vector3::from(p)).norm() < c[2] / cam.focal);
        // Already on its ray: unmoved. The next pixel's ray at that depth: one pixel across.
        let again = cam.on_ray(row, col, centred);
        assert!((Vector3::from(again) - Vector3::from(centred)).norm() < 1e-12);
        let next = cam.on_ray(row, col + 1, centred);
        let step = (Vector3::from(next) - Vector3::from(centred)).norm();
        assert!((step - c[2] / cam.focal).abs() < 1e-12);
    }

    #[test]
    fn points_outside_the_window_are_dropped() {
        let p = Camera::rig(5, 256).unwrap().projector();
        assert!(p.project([0.0, 3.0, 0.0]).is_none());
        let behind = Camera::rig(5, 256).unwrap().center() * 1.5;
        assert!(p.project(behind.map(|v| v as f32).into()).is_none());
    }

    #[test]
    fn view_sets_are_validated() {
        assert_eq!(parse_view_set("5,6,7,8").unwrap(), vec![5, 6, 7, 8]);
        assert_eq!(parse_view_set(" 1 , 20 ").unwrap(), vec![1, 20]);
        assert_eq!(parse_view_set("0"), Err(CameraError::OutOfRange(0)));
        assert_eq!(parse_view_set("21"), Err(CameraError::OutOfRange(21)));
        assert_eq!(parse_view_set("5,5"), Err(CameraError::Duplicate(5)));
        assert_eq!(
            parse_view_set("5,x"),
            Err(CameraError::NotAnIndex("x".into()))
        );
        assert_eq!(Camera::rig(5, 4), Err(CameraError::TooSmall(4)));
        assert!(Camera::rig(5, MAX_IMAGE_SIZE).is_ok());
        assert_eq!(
            Camera::rig(5, MAX_IMAGE_SIZE + 1),
            Err(CameraError::TooLarge(MAX_IMAGE_SIZE + 1))
        );
    }
}
