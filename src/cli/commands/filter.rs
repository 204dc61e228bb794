use super::{load, Log};
use crate::cli::args::FilterArgs;
use crate::cli::count;
use mvpcc::complete::filter::inliers;
use mvpcc::io::{check_output, output_format, unwritten, write_cloud};

pub(super) fn run(args: FilterArgs, log: Log) -> anyhow::Result<()> {
    check_output(&args.output, &[&args.input])?;
    let format = output_format(&args.output, args.output_options.out_format)?;
    let cloud = load(&args.input, args.input_options.format, log)?;
    for warning in unwritten(&cloud, format, &args.output) {
        log.warn(format!("{}: {warning}", args.input.display()));
    }
    let filtered = cloud.filter(&inliers(&cloud.positions, args.sor.params()));
    write_cloud(
        &args.output,
        &filtered,
        args.output_options.out_format,
        args.output_options.encoding,
    )?;
    log.info(format!(
        "{}: kept {} of {} ({} removed, k = {}, σ = {})",
        args.output.display(),
        filtered.len(),
        count(cloud.len(), "point"),
        count(cloud.len() - filtered.len(), "outlier"),
        args.sor.sor_k,
        args.sor.sor_std
    ));
    Ok(())
}
