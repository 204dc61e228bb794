use super::Log;
use crate::cli::args::ReprojectArgs;
use crate::cli::count;
use mvpcc::app::views::Reprojection;
use mvpcc::views::reprojection::ReprojectOptions;

pub(super) fn run(args: ReprojectArgs, log: Log) -> anyhow::Result<()> {
    let reprojection = Reprojection {
        cameras: args.views.as_ref().map(|v| v.0.clone()),
        options: ReprojectOptions {
            erode: args.erode,
            dedup_tolerance: args.dedup,
            smooth: args.smooth,
        },
        sor: args.sor.params(),
        normalized: args.normalized,
        out_format: args.output_options.out_format,
        encoding: args.output_options.encoding,
    };
    let done = reprojection.run(&args.viewdir, &args.output)?;
    log.info(format!(
        "{}: {} from {} ({} occupied, {} after erosion and de-duplication, {} removed)",
        args.output.display(),
        count(done.points, "point"),
        count(done.views, "view"),
        count(done.occupied, "pixel"),
        done.merged,
        count(done.merged - done.points, "outlier")
    ));
    Ok(())
}
