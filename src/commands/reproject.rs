use super::project::{ViewsInfo, INFO_FILE};
use super::Log;
use crate::cli::ReprojectArgs;
use crate::filter::inliers;
use crate::io::{check_output, write_cloud};
use crate::reprojection::{reproject, ReprojectOptions};
use crate::views::{find_views, locations_path, read_views};
use anyhow::{bail, Context};

pub(super) fn run(args: ReprojectArgs, log: Log) -> anyhow::Result<()> {
    let cameras = match &args.views {
        Some(v) => v.0.clone(),
        None => find_views(&args.viewdir)?,
    };
    let inputs: Vec<_> = cameras
        .iter()
        .map(|&c| locations_path(&args.viewdir, c))
        .collect();
    check_output(
        &args.output,
        &inputs.iter().map(|p| p.as_path()).collect::<Vec<_>>(),
    )?;
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
    let info_path = args.viewdir.join(INFO_FILE);
    let output = if !args.normalized && info_path.exists() {
        let text =
            std::fs::read_to_string(&info_path).with_context(|| info_path.display().to_string())?;
        let info: ViewsInfo = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a valid frame file", info_path.display()))?;
        info.frame.denormalize(&filtered)
    } else {
        filtered
    };
    write_cloud(
        &args.output,
        &output,
        args.output_options.out_format,
        args.output_options.encoding,
    )?;
    log.info(format!(
        "{}: {} points from {} views ({} occupied pixels, {} after erosion and de-duplication, {} outliers removed)",
        args.output.display(),
        output.len(),
        views.views(),
        views.occupied(),
        merged.len(),
        merged.len() - output.len()
    ));
    Ok(())
}
