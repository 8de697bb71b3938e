//! `lightfarm`: the command line of the virtual light stage.

mod render_cmd;
mod spec_cmd;

use clap::{Parser, Subcommand};
use tracing_subscriber::EnvFilter;

#[derive(Parser)]
#[command(
    name = "lightfarm",
    version,
    about = "A virtual light stage: renders paired relighting data"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a glTF scene under one or more HDR environment maps into a multi-layer EXR.
    Render(Box<render_cmd::RenderArgs>),
    /// List the Vulkan devices lightfarm can render on.
    Devices,
    /// Dataset specs: expand a sample index into its full description, check a spec.
    #[command(subcommand)]
    Spec(spec_cmd::SpecCommand),
    /// The asset catalog: list, verify hashes.
    #[command(subcommand)]
    Assets(spec_cmd::AssetsCommand),
}

fn main() {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_env("LIGHTFARM_LOG").unwrap_or_else(|_| EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(args) => render_cmd::run(*args),
        Command::Devices => render_cmd::devices(),
        Command::Spec(c) => spec_cmd::spec(c),
        Command::Assets(c) => spec_cmd::assets(c),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
