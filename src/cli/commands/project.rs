use super::{load, Log};
use crate::cli::args::ProjectArgs;
use crate::cli::count;
use anyhow::Context;
use mvpcc::core::camera::{Camera, CameraError};
use mvpcc::core::frame::Frame;
use mvpcc::io::default_up;
use mvpcc::views::projection::project;
use mvpcc::views::{write_views, ViewsInfo};

pub(super) fn run(args: ProjectArgs, log: Log) -> anyhow::Result<()> {
    let cameras = Camera::set(&args.views.0, args.size).map_err(|e| match e {
        CameraError::TooSmall(_) | CameraError::TooLarge(_) => anyhow::anyhow!("--size: {e}"),
        other => other.into(),
    })?;
    let outdir = &args.outdir;
    super::check_out_dir(outdir)?;
    let cloud = load(&args.input, args.input_options.format, log)?;
    let up = args
        .up
        .unwrap_or_else(|| default_up(&args.input, args.input_options.format));
    let frame = Frame::fit(&cloud, up).with_context(|| args.input.display().to_string())?;
    let normalized = frame.normalize(&cloud);
    let views = project(
        &normalized.positions_f32(),
        normalized.colors.as_deref(),
        &cameras,
    );
    if !outdir.is_dir() {
        std::fs::create_dir(outdir)
            .with_context(|| format!("{}: cannot create", outdir.display()))?;
    }
    write_views(outdir, &views)?;
    let info = ViewsInfo {
        frame,
        up,
        views: args.views.0.clone(),
        size: args.size,
        points: cloud.len(),
    };
    info.write(outdir)?;
    log.info(format!(
        "{}: {} → {} of {}×{} px, {} occupied",
        outdir.display(),
        count(cloud.len(), "point"),
        count(views.views(), "view"),
        args.size,
        args.size,
        count(views.occupied(), "pixel")
    ));
    Ok(())
}
