//! The `physnap` command line: the top-level parser, logging set-up and dispatch to one module
//! per subcommand. The work itself lives in the library; these modules turn flags into library
//! calls, show progress and print what happened.
//!
//! Every flag has a `PHYSNAP_*` environment twin (clap `env`), so the same settings work from
//! a shell, a container or a compose file. Errors from the library layers are reported once,
//! here, with their full cause chain.

pub(crate) mod check_sim;
mod client;
mod data;
mod eval;
mod export;
mod generate;
mod progress;
mod render;
mod serve;
mod train;

pub(crate) use progress::progress_bar;

use clap::{Parser, Subcommand};
use data::DataCommand;
use eval::EvalCommand;
use export::ExportArgs;
use generate::GenerateArgs;
use render::RenderArgs;
use std::process::ExitCode;
use train::TrainCommand;

/// PhysNAP: complete, physically plausible articulated 3D models from partial point clouds.
#[derive(Parser, Debug)]
#[command(version, about, long_about = None)]
pub(crate) struct Cli {
    /// Log filter (tracing EnvFilter syntax), e.g. "info" or "physnap=debug".
    #[arg(long, env = "PHYSNAP_LOG", default_value = "info", global = true)]
    pub(crate) log: String,

    /// Seconds between progress log lines when stderr is not a terminal (logs, CI, containers),
    /// where the progress bar is hidden; 0 turns them off.
    #[arg(
        long,
        env = "PHYSNAP_PROGRESS_INTERVAL",
        default_value_t = 30.0,
        global = true
    )]
    pub(crate) progress_interval: f64,

    #[command(subcommand)]
    pub(crate) command: Command,
}

#[derive(Subcommand, Debug)]
pub(crate) enum Command {
    /// Write GLB + URDF (+ meshes, zip bundle) for an articulated-object JSON.
    Export(ExportArgs),
    /// Check an export directory for contacts at rest and along its joints (exit 1: not clean).
    CheckSim(check_sim::CheckSimArgs),
    /// Draw objects to a PNG: one object at rest and at its joint limits, or a contact sheet.
    Render(RenderArgs),
    /// Train the shape prior or the articulation denoiser.
    Train {
        #[command(subcommand)]
        command: TrainCommand,
    },
    /// Generate articulated objects with trained weights (GLB + URDF per sample).
    Generate(GenerateArgs),
    /// Data sets: procedural objects, PartNet-Mobility import, partial scans.
    Data {
        #[command(subcommand)]
        command: DataCommand,
    },
    /// Evaluate trained weights with the paper's metrics.
    Eval {
        #[command(subcommand)]
        command: EvalCommand,
    },
    /// Run the inference service: REST + SSE, gRPC, admin (metrics, health); see README.
    Serve(serve::ServeArgs),
    /// Exit 0 when a running server's admin /readyz answers 200 (container health checks).
    Healthcheck(serve::HealthcheckArgs),
    /// Submit a point cloud to a running server (gRPC); with --out, watch it and download.
    Submit(client::SubmitArgs),
    /// Follow a job on a running server (progress bar); with --out, download its artefacts.
    Watch(client::WatchArgs),
}

pub(crate) fn main() -> ExitCode {
    let matches = <Cli as clap::CommandFactory>::command().get_matches();
    let mut cli =
        <Cli as clap::FromArgMatches>::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    // Presets need to know which flags were given, which only the matches tell.
    if let (Command::Generate(a), Some(("generate", m))) = (&mut cli.command, matches.subcommand())
    {
        a.apply_quality(m);
    }
    let filter = tracing_subscriber::EnvFilter::try_new(&cli.log)
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    if !(cli.progress_interval.is_finite() && cli.progress_interval >= 0.0) {
        eprintln!(
            "error: --progress-interval must be finite and >= 0 seconds (0: off), got {}",
            cli.progress_interval
        );
        return ExitCode::FAILURE;
    }
    let _ = progress::PROGRESS_INTERVAL.set(cli.progress_interval);
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

pub(crate) fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Export(a) => export::export(a),
        Command::CheckSim(a) => check_sim::check_sim(a),
        Command::Render(a) => render::render(a),
        Command::Train { command } => train::run(command),
        Command::Generate(a) => generate::generate(a),
        Command::Serve(a) => serve::serve(a),
        Command::Healthcheck(a) => serve::healthcheck(a),
        Command::Submit(a) => client::submit(a),
        Command::Watch(a) => client::watch(a),
        Command::Data { command } => data::run(command),
        Command::Eval { command } => eval::run(command),
    }
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    use super::Cli;

    /// Every flag of every subcommand has a `PHYSNAP_*` environment twin (help and version
    /// excepted), so a container or compose file can set anything a shell can.
    #[test]
    fn every_flag_has_an_env_twin() {
        fn walk(cmd: &clap::Command, path: &str, missing: &mut Vec<String>) {
            for arg in cmd.get_arguments() {
                let id = arg.get_id().as_str();
                if matches!(id, "help" | "version") {
                    continue;
                }
                match arg.get_env() {
                    Some(env) if env.to_string_lossy().starts_with("PHYSNAP_") => {}
                    _ => missing.push(format!("{path} --{id}")),
                }
            }
            for sub in cmd.get_subcommands() {
                walk(sub, &format!("{path} {}", sub.get_name()), missing);
            }
        }
        let mut cmd = Cli::command();
        cmd.build();
        let mut missing = Vec::new();
        walk(&cmd, "physnap", &mut missing);
        assert!(
            missing.is_empty(),
            "flags without a PHYSNAP_* env twin: {missing:?}"
        );
    }

    /// `generate -h` lists the flags most runs need; the research knobs are in `--help`.
    #[test]
    fn generate_short_help_hides_the_research_knobs() {
        let mut cmd = Cli::command();
        cmd.build();
        let generate = cmd
            .find_subcommand_mut("generate")
            .expect("generate exists");
        let short = generate.render_help().to_string();
        let long = generate.render_long_help().to_string();
        for user in [
            "--points",
            "--category",
            "--samples",
            "--seed",
            "--out",
            "--weights",
            "--camera",
            "--frame",
            "--quality",
        ] {
            assert!(short.contains(user), "{user} missing from -h:\n{short}");
        }
        for knob in [
            "--tau",
            "--guidance-max-step",
            "--w-pc",
            "--category-guidance-below",
        ] {
            assert!(!short.contains(knob), "{knob} in -h:\n{short}");
            assert!(long.contains(knob), "{knob} missing from --help");
        }
        assert!(long.contains("Sampling and guidance schedule"), "{long}");
    }

    /// `--quality` sets the flags left at their defaults; a flag or env twin given wins.
    #[test]
    fn quality_presets_fill_only_the_flags_not_given() {
        use clap::FromArgMatches;
        let parse = |args: &[&str]| {
            let m = Cli::command()
                .try_get_matches_from(
                    ["physnap", "generate", "--out", "o"]
                        .iter()
                        .chain(args.iter()),
                )
                .unwrap();
            let mut cli = Cli::from_arg_matches(&m).unwrap();
            let super::Command::Generate(a) = &mut cli.command else {
                panic!("not generate");
            };
            a.apply_quality(m.subcommand_matches("generate").unwrap());
            (
                a.sampling.steps,
                a.sampling.guidance_refine_steps,
                a.resolution,
                a.samples,
            )
        };
        let standard = parse(&[]);
        assert_eq!(standard, parse(&["--quality", "standard"]));
        assert_eq!(
            parse(&["--quality", "fast"]),
            (100, standard.1, 24, standard.3)
        );
        // Explicit flags win, even when they equal the default.
        assert_eq!(
            parse(&["--quality", "fast", "--resolution", "32", "--steps", "200"]),
            (200, standard.1, 32, standard.3)
        );
        // n_g keeps its old flag name as an alias.
        let m = Cli::command()
            .try_get_matches_from([
                "physnap",
                "generate",
                "--out",
                "o",
                "--guidance-steps",
                "300",
            ])
            .unwrap();
        let super::Command::Generate(a) = Cli::from_arg_matches(&m).unwrap().command else {
            panic!("not generate");
        };
        assert_eq!(a.sampling.n_g, 300);
        let bad = Cli::command()
            .try_get_matches_from(["physnap", "generate", "--out", "o", "--quality", "best"])
            .unwrap_err()
            .to_string();
        assert!(bad.contains("--quality") && bad.contains("best"), "{bad}");
    }
}
