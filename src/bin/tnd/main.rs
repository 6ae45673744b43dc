//! `tnd`: the command-line face of tactile-derender. Runs the same pipeline as the workbench, headless.

mod args;
mod bench;
mod calibrate_cmd;
mod dataset_cmd;
mod eval_cmd;
mod eval_tables;
mod measured;
mod model_cmd;
mod objects_cmd;
mod outputs;
mod pose_cmd;
mod posterior_cmd;
mod progress;
mod recording_cmd;
mod rerun_out;
mod sample_cmd;
mod sim_cmd;
mod track_cmd;
mod train_cmd;

use clap::{Parser, Subcommand};

/// A path in a command's JSON output. A name that is not UTF-8 is shown with replacement characters (the files were
/// written under the real name) instead of stopping the command after its work is done.
pub fn path_json(path: impl AsRef<std::path::Path>) -> serde_json::Value {
    serde_json::Value::String(path.as_ref().to_string_lossy().into_owned())
}

/// Tactile Neural De-rendering for Soft Bubble sensors: simulate, generate data, train, de-render, estimate poses.
#[derive(Parser)]
#[command(name = "tnd", version, about)]
struct Cli {
    /// No progress bars (they are also off when stderr is not a terminal); results still print on stdout.
    #[arg(long, short, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate one contact: depth, elastomer, contact mask, target, signature, reference and imprint.
    Sim(Box<sim_cmd::SimArgs>),
    /// The object library and users' meshes: list, export, check a mesh file, import a folder of meshes, generate a
    /// procedural training set.
    Objects(objects_cmd::ObjectsArgs),
    /// Synthetic and real datasets: generate, import, statistics, preview.
    Dataset(dataset_cmd::DatasetArgs),
    /// Benchmarks printing JSON lines.
    Bench(bench::BenchArgs),
    /// Evaluate a generator and the threshold baseline on a dataset: the paper's Tables I and II.
    Eval(Box<eval_cmd::EvalArgs>),
    /// One signature end to end: samples, pose, uncertainty (CSV + KDE plot).
    Pose(Box<pose_cmd::PoseArgs>),
    /// Diffusion model checkpoints: verify against a diffusers reference, diagnose per timestep, export to and import
    /// from diffusers folders.
    Model(model_cmd::ModelArgs),
    /// De-render: draw N samples of the in-contact depth for one imprint (DDPM or DDIM).
    Sample(Box<sample_cmd::SampleArgs>),
    /// Train (or resume, or fine-tune) the conditional DDPM on a dataset.
    Train(Box<train_cmd::TrainArgs>),
    /// Calibrate the sensor from a recording's no-contact frames: membrane inflation and footprint, camera
    /// position, depth noise; writes a sensor file for --sensor.
    Calibrate(Box<calibrate_cmd::CalibrateArgs>),
    /// Real sensor recordings (MCAP, depth-frame folders): topics, reference, contact per frame; simulated ones.
    Recording(recording_cmd::RecordingArgs),
    /// The pose posterior on `tnd eval --records`: how often its regions hold the truth, per contact size; fit its
    /// calibration to your own labelled recordings (--fit FILE, then --posterior FILE).
    Posterior(Box<posterior_cmd::PosteriorArgs>),
}

fn main() -> std::process::ExitCode {
    // Piped into `head` and the like, end quietly when the reader goes away, as other Unix tools do, instead of
    // panicking in `println!` on the broken pipe (Rust ignores SIGPIPE by default).
    #[cfg(unix)]
    // SAFETY: restores the default disposition of one signal at start-up, before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    progress::set_quiet(cli.quiet);
    // The model's process-wide settings, the same as the workbench's; a variable the user set is kept.
    let kernels = tactile_derender::model::kernels::KernelSettings::default();
    for (name, value) in kernels.environment() {
        if std::env::var_os(name).is_none() {
            std::env::set_var(name, value);
        }
    }
    kernels.apply_allocator_policy();
    let result = match cli.command {
        Command::Sim(a) => sim_cmd::run(*a),
        Command::Objects(a) => objects_cmd::run(a),
        Command::Dataset(a) => dataset_cmd::run(a),
        Command::Bench(a) => bench::run(a),
        Command::Calibrate(a) => calibrate_cmd::run(*a),
        Command::Eval(a) => eval_cmd::run(*a),
        Command::Pose(a) => pose_cmd::run(*a),
        Command::Model(a) => model_cmd::run(a),
        Command::Sample(a) => sample_cmd::run(*a),
        Command::Recording(a) => recording_cmd::run(a),
        Command::Train(a) => train_cmd::run(*a),
        Command::Posterior(a) => posterior_cmd::run(*a),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", tactile_derender::error::render_anyhow(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// No command has two arguments with one id (a flattened settings struct's field meeting a command's own flag of
    /// the same name, which clap's parser then confuses), and `tnd bench posterior --native` parses.
    #[test]
    fn argument_ids_are_unique_in_every_command() {
        fn walk(cmd: &clap::Command, path: &str, clashes: &mut Vec<String>) {
            let mut seen = std::collections::HashSet::new();
            for a in cmd.get_arguments() {
                if !seen.insert(a.get_id().as_str().to_string()) {
                    clashes.push(format!("{path}: {}", a.get_id()));
                }
            }
            for s in cmd.get_subcommands() {
                walk(s, &format!("{path} {}", s.get_name()), clashes);
            }
        }
        let mut clashes = Vec::new();
        walk(&super::Cli::command(), "tnd", &mut clashes);
        assert!(clashes.is_empty(), "{clashes:#?}");
        use clap::Parser;
        assert!(super::Cli::try_parse_from(["tnd", "bench", "posterior", "--native"]).is_ok());
    }

    /// Every subcommand says what it does and every flag what it means (clap's `--help`).
    #[test]
    fn every_command_and_flag_has_help_text() {
        fn walk(cmd: &clap::Command, path: &str, missing: &mut Vec<String>) {
            for a in cmd.get_arguments() {
                let id = a.get_id().as_str();
                if id == "help" || id == "version" {
                    continue;
                }
                if a.get_help().is_none() && a.get_long_help().is_none() {
                    missing.push(format!("{path}: --{id}"));
                }
            }
            for s in cmd.get_subcommands() {
                let sub = format!("{path} {}", s.get_name());
                if s.get_name() != "help" && s.get_about().is_none() {
                    missing.push(format!("{sub}: no description"));
                }
                walk(s, &sub, missing);
            }
        }
        let mut missing = Vec::new();
        walk(&super::Cli::command(), "tnd", &mut missing);
        assert!(missing.is_empty(), "without help text: {missing:#?}");
    }
}
