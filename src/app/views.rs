//! Clouds to view folders and back, as `project` and `reproject` do: a cloud normalized and
//! projected into the original dataset's PNG pairs with the frame that undoes it, and a view
//! folder eroded, merged, filtered and returned to that frame.

use super::PathError;
use crate::complete::filter::{inliers, SorParams};
use crate::core::camera::{Camera, CameraError};
use crate::core::cloud::PointCloud;
use crate::core::frame::{Frame, FrameError, UpAxis};
use crate::io::{check_output, output_format, write_cloud, CloudIoError, Encoding, Format};
use crate::views::projection::project;
use crate::views::reprojection::{reproject, ReprojectOptions};
use crate::views::{
    color_path, find_views, locations_path, read_views, write_views, ViewError, ViewsInfo,
    INFO_FILE,
};
use std::path::{Path, PathBuf};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum ViewsRunError {
    #[error(transparent)]
    Path(#[from] PathError),
    #[error(transparent)]
    Cloud(#[from] CloudIoError),
    #[error(transparent)]
    Views(#[from] ViewError),
    #[error(transparent)]
    Camera(#[from] CameraError),
    #[error("{}: {source}", path.display())]
    Frame { path: PathBuf, source: FrameError },
    #[error("{}: exists and is not a directory", .0.display())]
    NotADirectory(PathBuf),
    #[error("{}: no occupied pixels left to re-project (try a smaller --erode; raw sparse scans need --erode 0)", .0.display())]
    NothingLeft(PathBuf),
}

/// What a projection made.
#[derive(Debug)]
pub struct Projected {
    pub views: usize,
    pub occupied: usize,
}

/// Projects `cloud` (read from `input`, up axis `up`) with the rig cameras `cameras` into
/// `outdir`, with the `frame.json` that maps it back.
pub fn project_into(
    cloud: &PointCloud,
    input: &Path,
    up: UpAxis,
    cameras: &[Camera],
    outdir: &Path,
) -> Result<Projected, ViewsRunError> {
    if outdir.exists() && !outdir.is_dir() {
        return Err(ViewsRunError::NotADirectory(outdir.to_path_buf()));
    }
    let frame = Frame::fit(cloud, up).map_err(|source| ViewsRunError::Frame {
        path: input.to_path_buf(),
        source,
    })?;
    let normalized = frame.normalize(cloud);
    let views = project(
        &normalized.positions_f32(),
        normalized.colors.as_deref(),
        cameras,
    );
    if !outdir.is_dir() {
        std::fs::create_dir(outdir).map_err(PathError::create(outdir))?;
    }
    write_views(outdir, &views)?;
    let info = ViewsInfo {
        frame,
        up,
        views: cameras.iter().map(|c| c.index).collect(),
        size: cameras.first().map_or(0, |c| c.size),
        points: cloud.len(),
    };
    info.write(outdir)?;
    Ok(Projected {
        views: views.views(),
        occupied: views.occupied(),
    })
}

/// How a view folder is turned back into a cloud and written.
#[derive(Debug, Clone)]
pub struct Reprojection {
    /// The cameras to read; all the folder holds when `None`.
    pub cameras: Option<Vec<usize>>,
    pub options: ReprojectOptions,
    pub sor: SorParams,
    /// Keep the normalized coordinates even when the folder has its frame.
    pub normalized: bool,
    pub out_format: Option<Format>,
    pub encoding: Encoding,
}

/// What a re-projection made.
#[derive(Debug)]
pub struct Reprojected {
    pub points: usize,
    pub views: usize,
    pub occupied: usize,
    /// Points after erosion and de-duplication, before the outlier filter.
    pub merged: usize,
}

impl Reprojection {
    /// Re-projects the views in `viewdir` into `output`, which may overwrite none of them.
    pub fn run(&self, viewdir: &Path, output: &Path) -> Result<Reprojected, ViewsRunError> {
        let cameras = match &self.cameras {
            Some(c) => c.clone(),
            None => find_views(viewdir)?,
        };
        let inputs: Vec<PathBuf> = cameras
            .iter()
            .flat_map(|&c| [locations_path(viewdir, c), color_path(viewdir, c)])
            .chain([viewdir.join(INFO_FILE)])
            .collect();
        check_output(
            output,
            &inputs.iter().map(|p| p.as_path()).collect::<Vec<_>>(),
        )?;
        output_format(output, self.out_format)?;
        let views = read_views(viewdir, Some(&cameras))?;
        let merged = reproject(&views, self.options);
        if merged.is_empty() {
            return Err(ViewsRunError::NothingLeft(viewdir.to_path_buf()));
        }
        let filtered = merged.filter(&inliers(&merged.positions, self.sor));
        let info = if self.normalized {
            None
        } else {
            ViewsInfo::read(viewdir)?
        };
        let cloud = match info {
            Some(info) => info.frame.denormalize(&filtered),
            None => filtered,
        };
        write_cloud(output, &cloud, self.out_format, self.encoding)?;
        Ok(Reprojected {
            points: cloud.len(),
            views: views.views(),
            occupied: views.occupied(),
            merged: merged.len(),
        })
    }
}
