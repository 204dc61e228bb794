//! `synth`: procedural meshes into a folder, said on stderr.

use super::{Bar, Log};
use crate::cli::args::SynthArgs;
use mvpcc::app::synth::{check_count, generate, generate_streets, Generated};
use mvpcc::datagen::synth::street::StreetParams;
use std::path::Path;

pub(super) fn run(args: SynthArgs, log: Log) -> anyhow::Result<()> {
    check_count(args.count, "--count")?;
    let options = &args.synth_options;
    if args.scene {
        let params = StreetParams {
            length: args.length,
            ..StreetParams::default()
        };
        let start = std::time::Instant::now();
        let written =
            generate_streets(&args.out, args.count, options.seed, &params, &Bar::new(log))?;
        let streets = if written.len() == 1 {
            "street"
        } else {
            "streets"
        };
        log.info(format!(
            "wrote {} {streets} of {} m to {} in {:.1} s",
            written.len(),
            params.length,
            args.out.display(),
            start.elapsed().as_secs_f64()
        ));
        return Ok(());
    }
    let draws = &options.category;
    let done = generate(
        &args.out,
        args.count,
        draws,
        options.seed,
        args.preview,
        &Bar::new(log),
    )?;
    say_generated(&done, &args.out, log);
    Ok(())
}

/// Says what generating the objects into `out` did.
pub(super) fn say_generated(done: &Generated, out: &Path, log: Log) {
    let count = done.manifest.objects.len();
    log.info(if done.already {
        format!("{}: {count} objects already generated", out.display())
    } else {
        format!(
            "wrote {count} objects to {} in {:.1} s",
            out.display(),
            done.seconds
        )
    });
    if let Some(path) = &done.preview {
        log.info(format!("preview: {}", path.display()));
    }
}
