//! The `clsmap` command: one binary, clap subcommands.

use std::process::ExitCode;

mod cli;

fn main() -> ExitCode {
    let args = cli::Cli::parse_args();
    cli::init_logging(args.verbose, args.quiet, args.shows_progress());
    match cli::run(args) {
        Ok(code) => code,
        // A closed pipe (`clsmap decode rec | head`) is a normal way to stop.
        Err(err) if is_broken_pipe(&err) => ExitCode::SUCCESS,
        Err(err) => {
            // The whole cause chain, outermost first, so the user sees both
            // what failed and why.
            eprintln!("error: {err}");
            for cause in err.chain().skip(1) {
                eprintln!("  caused by: {cause}");
            }
            ExitCode::FAILURE
        }
    }
}

fn is_broken_pipe(err: &anyhow::Error) -> bool {
    err.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
    })
}
