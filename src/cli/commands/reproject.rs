use super::Log;
use crate::cli::args::ReprojectArgs;
use crate::cli::count;
use anyhow::bail;
use mvpcc::complete::filter::inliers;
use mvpcc::io::{check_output, output_format, write_cloud};
use mvpcc::views::reprojection::{reproject, ReprojectOptions};
use mvpcc::views::{color_path, find_views, locations_path, read_views, ViewsInfo, INFO_FILE};
use std::path::{Path, PathBuf};

pub(super) fn run(args: ReprojectArgs, log: Log) -> anyhow::Result<()> {
    let cameras = match &args.views {
        Some(v) => v.0.clone(),
        None => find_views(&args.viewdir)?,
    };
    let inputs = view_files(&args.viewdir, &cameras);
    check_output(
        &args.output,
        &inputs.iter().map(|p| p.as_path()).collect::<Vec<_>>(),
    )?;
    output_format(&args.output, args.output_options.out_format)?;
    let views = read_views(&args.viewdir, Some(&cameras))?;
    let merged = reproject(
        &views,
        ReprojectOptions {
            erode: args.erode,
            dedup_tolerance: args.dedup,
            smooth: args.smooth,
        },
    );
    if merged.is_empty() {
        bail!(
            "{}: no occupied pixels left to re-project (try a smaller --erode; raw sparse scans need --erode 0)",
            args.viewdir.display()
        );
    }
    let filtered = merged.filter(&inliers(&merged.positions, args.sor.params()));
    let info = if args.normalized {
        None
    } else {
        ViewsInfo::read(&args.viewdir)?
    };
    let output = match info {
        Some(info) => info.frame.denormalize(&filtered),
        None => filtered,
    };
    write_cloud(
        &args.output,
        &output,
        args.output_options.out_format,
        args.output_options.encoding,
    )?;
    log.info(format!(
        "{}: {} from {} ({} occupied, {} after erosion and de-duplication, {} removed)",
        args.output.display(),
        count(output.len(), "point"),
        count(views.views(), "view"),
        count(views.occupied(), "pixel"),
        merged.len(),
        count(merged.len() - output.len(), "outlier")
    ));
    Ok(())
}

/// The files a view directory's re-projection reads: each camera's two images and the info file,
/// none of which the output may overwrite.
fn view_files(viewdir: &Path, cameras: &[usize]) -> Vec<PathBuf> {
    cameras
        .iter()
        .flat_map(|&c| [locations_path(viewdir, c), color_path(viewdir, c)])
        .chain([viewdir.join(INFO_FILE)])
        .collect()
}
