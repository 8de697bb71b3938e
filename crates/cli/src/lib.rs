//! `lightfarm`: the command line of the virtual light stage. The binary is `main()`; it is a
//! library so that the workspace's cross-service tests (`tests/`) can build the same program
//! under their own package and run it as real processes.

mod adapt_cmd;
mod demo_cmd;
mod farm_cmd;
mod olat_cmd;
mod people_cmd;
mod preview_cmd;
mod remote_job;
mod render_cmd;
mod sheet;
mod spec_cmd;
mod train_cmd;

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
    /// Render a few samples of a dataset spec small and write a labelled contact sheet
    /// (lit0 | lit1 | albedo | normal | normal_lens | mask per sample).
    Preview(Box<preview_cmd::PreviewArgs>),
    /// Synthetic people: check that consecutive identities generate, dress and render cleanly.
    #[command(subcommand)]
    People(people_cmd::PeopleCommand),
    /// The one-machine case: an in-process coordinator and worker render a small dataset from
    /// the built-in assets, export it and draw a contact sheet (out/demo/).
    Demo(Box<demo_cmd::DemoArgs>),
    /// Run a service: the coordinator or a render worker.
    #[command(subcommand)]
    Serve(farm_cmd::Serve),
    /// Submit a dataset spec to the coordinator; prints the job id.
    Submit(farm_cmd::SubmitArgs),
    /// Follow a job's progress (rate, ETA) until it ends.
    Watch(farm_cmd::JobArgs),
    /// List jobs.
    Jobs(farm_cmd::JobsArgs),
    /// Cancel a job.
    Cancel(farm_cmd::JobArgs),
    /// Pause a job (no new leases; running samples finish).
    Pause(farm_cmd::JobArgs),
    /// Resume a paused job.
    Resume(farm_cmd::JobArgs),
    /// List committed samples.
    Samples(farm_cmd::SamplesArgs),
    /// Export a job's committed samples as WebDataset tar shards or a folder of EXR + JSON.
    Export(farm_cmd::ExportArgs),
    /// Train the relighting network on a folder export (resumes from the run's newest
    /// checkpoint; Ctrl-C stops after a checkpoint).
    Train(train_cmd::TrainArgs),
    /// Adapt a trained model to real photos (the paper's synthetic-to-real step): f_Ā learns
    /// from a folder of portraits while the model stays frozen.
    Adapt(adapt_cmd::AdaptArgs),
    /// List the training jobs of a trainer service (`lightfarm serve trainer`).
    TrainJobs(train_cmd::TrainJobsArgs),
    /// Relight a portrait with a trained model under an HDRI.
    Relight(Box<train_cmd::RelightArgs>),
    /// Relight a sample rendered with OLAT images (`olat = 168` under [lighting]) under any
    /// HDRI, as the weighted sum of its OLAT images (no network involved).
    RelightOlat(Box<olat_cmd::RelightOlatArgs>),
    /// Score models on a split (MAE, MSE, SSIM, SH lighting recovery), one row each.
    Eval(train_cmd::EvalArgs),
}

/// The whole program: parses the arguments, runs the command, exits 1 with the error chain.
pub fn main() {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_env("LIGHTFARM_LOG").unwrap_or_else(|_| EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        // Colour codes only on a terminal, not in `docker logs` or log files.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(args) => render_cmd::run(*args),
        Command::Devices => render_cmd::devices(),
        Command::Spec(c) => spec_cmd::spec(c),
        Command::Assets(c) => spec_cmd::assets(c),
        Command::Preview(args) => preview_cmd::run(*args),
        Command::People(c) => people_cmd::people(c),
        Command::Demo(a) => demo_cmd::run(*a),
        Command::Serve(c) => farm_cmd::serve(c),
        Command::Submit(a) => farm_cmd::submit(a),
        Command::Watch(a) => farm_cmd::watch(a),
        Command::Jobs(a) => farm_cmd::jobs(a),
        Command::Cancel(a) => farm_cmd::job_action(a, "cancel"),
        Command::Pause(a) => farm_cmd::job_action(a, "pause"),
        Command::Resume(a) => farm_cmd::job_action(a, "resume"),
        Command::Samples(a) => farm_cmd::samples(a),
        Command::Export(a) => farm_cmd::export(a),
        Command::Train(a) => train_cmd::train(a),
        Command::Adapt(a) => adapt_cmd::run(a),
        Command::TrainJobs(a) => train_cmd::train_jobs(a),
        Command::Relight(a) => train_cmd::relight(*a),
        Command::RelightOlat(a) => olat_cmd::run(*a),
        Command::Eval(a) => train_cmd::eval(a),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
