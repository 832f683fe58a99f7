//! The `irs-planner` binary: see [`crate::cli`]. Without a command it serves with the
//! defaults (flags and `IRS_*` environment variables still apply through `serve`).

use clap::Parser;
mod cli;

use cli::{Cli, Command};
use irs_service::config::ServeArgs;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Command::Map(args)) => cli::run_map(&args),
        Some(Command::Plan(args)) => cli::run_plan(&args),
        Some(Command::Export(args)) => cli::run_export(&args),
        Some(Command::Estimate(args)) => cli::run_estimate(&args),
        Some(Command::Scenario(args)) => cli::run_scenario(&args),
        Some(Command::Zones(args)) => cli::run_zones(&args),
        Some(Command::Graph(args)) => cli::run_graph(&args),
        Some(Command::Roadmap(args)) => cli::run_roadmap(&args),
        Some(Command::Fleet(args)) => cli::run_fleet(&args),
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
    irs_service::serve(args).map_err(|e| match e {
        irs_service::ServeError::Config(message) => cli::Failure::input(message),
        irs_service::ServeError::Runtime(message) => cli::Failure::runtime(message),
    })
}
