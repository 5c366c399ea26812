//! The `chicktrain` binary: flags in, one library call, errors printed once (exit code 2).
//! The command tree and the request structs it fills live in the library
//! (`chicktrain::commands::cli`), so tests walk the same tree the binary parses.

use std::process::ExitCode;

use clap::Parser;

use chicktrain::commands::cli::Cli;

fn main() -> ExitCode {
    match Cli::parse().run() {
        Ok(msg) => {
            if !msg.is_empty() {
                println!("{}", msg.trim_end());
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
