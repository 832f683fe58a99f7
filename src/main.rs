//! The `irs-planner` binary: see [`irs_planner::cli`]. Without a command it serves with the
//! defaults (flags and `IRS_*` environment variables still apply through `serve`).

use clap::Parser;
use irs_planner::cli::{self, Cli, Command};
use irs_planner::service::{self, config::ServeArgs};
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Command::Map(args)) => cli::run_map(&args),
        Some(Command::Plan(args)) => cli::run_plan(&args),
        Some(Command::Export(args)) => cli::run_export(&args),
        Some(Command::Scenario(args)) => cli::run_scenario(&args),
        Some(Command::Place(args)) => cli::run_place(&args),
        Some(Command::Healthcheck(args)) => cli::run_healthcheck(&args),
        Some(Command::Serve(args)) => serve(args),
        None => serve(ServeArgs::default()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => f.into(),
    }
}

fn serve(args: ServeArgs) -> Result<(), cli::Failure> {
    service::run(args).map_err(|e| match e {
        service::ServeError::Config(message) => cli::Failure::input(message),
        service::ServeError::Runtime(message) => cli::Failure::runtime(message),
    })
}
