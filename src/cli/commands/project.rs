use super::{load, Log};
use crate::cli::args::ProjectArgs;
use crate::cli::count;
use mvpcc::app::views::project_into;
use mvpcc::core::camera::{Camera, CameraError};
use mvpcc::io::default_up;

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
    let views = project_into(&cloud, &args.input, up, &cameras, outdir)?;
    log.info(format!(
        "{}: {} → {} of {}×{} px, {} occupied",
        outdir.display(),
        count(cloud.len(), "point"),
        count(views.views, "view"),
        args.size,
        args.size,
        count(views.occupied, "pixel")
    ));
    Ok(())
}
