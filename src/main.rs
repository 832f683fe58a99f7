//! The `irs-planner` binary: see [`irs_planner::cli`].

use clap::Parser;
use irs_planner::cli::{self, Cli, Command};
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Command::Map(args)) => cli::run_map(&args),
        Some(Command::Plan(args)) => cli::run_plan(&args),
        None => Err(cli::Failure {
            message: "no command given (try --help)".into(),
            bad_input: true,
        }),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => f.into(),
    }
}
