mod cli;

use cli::args::Cli;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = Cli::parse_negatives();
    let result = cli::commands::run(cli);
    mvpcc::io::stdio::release_spooled();
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            cli::streams::tell(format_args!("error: {}", cli::one_line(&e)));
            ExitCode::FAILURE
        }
    }
}
