//! The `physnap` command line: parse flags, set up logging, dispatch.
//!
//! Every flag has a `PHYSNAP_*` environment twin (clap `env`), so the same settings work from
//! a shell, a container or a compose file. Errors from the library layers are reported once,
//! here, with their full cause chain.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};

use physnap::export::{ExportOptions, export_dir, mesh_parts};
use physnap::mesh::MeshingOptions;

mod client_cmd;
mod data_cmd;
mod eval_cmd;
mod model_cmd;
mod real_cmd;
mod serve_cmd;

// mimalloc instead of glibc malloc: the ML stack allocates and frees many short-lived buffers
// per step, and glibc's allocator roughly doubles backward-pass time (ml-stack.md §TL;DR).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// PhysNAP: complete, physically plausible articulated 3D models from partial point clouds.
#[derive(Parser, Debug)]
#[command(version, about, long_about = None)]
struct Cli {
    /// Log filter (tracing EnvFilter syntax), e.g. "info" or "physnap=debug".
    #[arg(long, env = "PHYSNAP_LOG", default_value = "info", global = true)]
    log: String,

    /// Seconds between progress log lines when stderr is not a terminal (logs, CI, containers),
    /// where the progress bar is hidden; 0 turns them off.
    #[arg(
        long,
        env = "PHYSNAP_PROGRESS_INTERVAL",
        default_value_t = 30.0,
        global = true
    )]
    progress_interval: f64,

    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Write GLB + URDF (+ meshes, zip bundle) for an articulated-object JSON.
    Export(ExportArgs),
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
    Serve(serve_cmd::ServeArgs),
    /// Exit 0 when a running server's admin /readyz answers 200 (container health checks).
    Healthcheck(serve_cmd::HealthcheckArgs),
    /// Submit a point cloud to a running server (gRPC); with --out, watch it and download.
    Submit(client_cmd::SubmitArgs),
    /// Follow a job on a running server (progress bar); with --out, download its artefacts.
    Watch(client_cmd::WatchArgs),
}

#[derive(Subcommand, Debug)]
enum EvalCommand {
    /// Sample the prior and compare with the test split: validity, MMD / COV / 1-NNA by
    /// instantiation distance, category accuracy of conditioned samples.
    Generative(EvalGenerativeArgs),
    /// Guidance metrics (E_pc, D_pc, E_pen, E_mob medians) per variant on test scans, in the
    /// paper's Table 1 layout; writes guided_table.md and guided_table.json.
    Guided(Box<EvalGuidedArgs>),
    /// Shape prior IoU (issue 4's "mean IoU on val parts at a 64³ grid"): per part and by kind
    /// (single primitive, several primitives, mesh, thinner than a grid cell, with a primitive
    /// under a cell thick, every primitive at least 2 cells thick), plus SDF L1.
    Shape(EvalShapeArgs),
    /// Test objects passed through the representation (graph, shape codes from the encoder,
    /// projection, decoder meshing) against the originals: what the shape prior loses, and
    /// the category accuracy a perfect denoiser could reach with it.
    Reconstruction(EvalReconstructionArgs),
    /// The denoiser's ε-loss on a held-out split at fixed noise levels, with each object's
    /// category and with the "no category" row: generalisation and category use in about a
    /// minute, without sampling (paired: the same seed gives every model the same inputs).
    Denoiser(EvalDenoiserArgs),
    /// Real-scan metrics (real-scans.md §3) on a benchmark set: parts and joint types exact,
    /// axis and hinge errors, Chamfer/diag, sim-clean in MuJoCo, seconds; per object, per
    /// category and overall, for the prior, guided and best-of-N rows. Writes real.md/json.
    Real(Box<real_cmd::EvalRealArgs>),
}

#[derive(Args, Debug)]
struct EvalDenoiserArgs {
    /// Weights directory with manifest.json: its denoiser and feature scales are measured.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    weights: PathBuf,
    /// Imported data set (output of `physnap data import`).
    #[arg(long, env = "PHYSNAP_DATA")]
    data: PathBuf,
    /// Shape prior directory holding every part's code (`train shape` or `train encode`
    /// output): the codes the denoiser was trained on.
    #[arg(long, env = "PHYSNAP_SHAPE")]
    shape: PathBuf,
    /// Split to measure: val (default), test, or train (the gap to val is the overfitting).
    #[arg(long, env = "PHYSNAP_EVAL_SPLIT", default_value = "val")]
    split: String,
    /// Noise levels t (0..999), comma-separated.
    #[arg(
        long,
        env = "PHYSNAP_EVAL_LEVELS",
        value_delimiter = ',',
        default_value = "10,50,100,200,300,400,500,600,800,950"
    )]
    levels: Vec<usize>,
    /// Seed of the node permutations and noise (the same seed pairs two models' inputs).
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    seed: u64,
    /// Also write the report as JSON here.
    #[arg(long, env = "PHYSNAP_EVAL_OUT")]
    out: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct EvalReconstructionArgs {
    /// Weights directory with manifest.json, or a `train shape` output directory
    /// (shape_prior.safetensors + shape_train.json, or + shape_checkpoint.json of a run
    /// stopped at a checkpoint): its shape prior is evaluated.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    weights: PathBuf,
    /// Imported data set whose test split is reconstructed.
    #[arg(long, env = "PHYSNAP_DATA")]
    data: PathBuf,
    /// Test objects (seeded choice); 0: the whole test split.
    #[arg(long, env = "PHYSNAP_EVAL_OBJECTS", default_value_t = 0)]
    objects: usize,
    /// Joint states per object for the instantiation distance (method.md: 10).
    #[arg(long, env = "PHYSNAP_EVAL_STATES", default_value_t = 4)]
    states: usize,
    /// Surface points per state for the instantiation distance (method.md: 2048).
    #[arg(long, env = "PHYSNAP_EVAL_POINTS", default_value_t = 256)]
    points: usize,
    /// Marching-cubes grid cells per axis for the reconstructions.
    #[arg(long, env = "PHYSNAP_MC_RESOLUTION", default_value_t = 32)]
    resolution: usize,
    /// Seed (object choice, state sampling).
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 12345)]
    seed: u64,
    /// Part shapes of the reconstructions: encoded (codes from the shape prior's encoder,
    /// meshed by its decoder), original (the originals' meshes on the projected graph: what
    /// the graph representation alone loses, the control) or analytic (the originals'
    /// primitive shapes meshed by marching cubes like decoded ones: what meshing alone loses).
    #[arg(long, env = "PHYSNAP_EVAL_SHAPES", default_value = "encoded", value_parser = ["encoded", "original", "analytic"])]
    shapes: String,
    /// Also write the report as JSON here.
    #[arg(long, env = "PHYSNAP_EVAL_OUT")]
    out: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct EvalShapeArgs {
    /// Weights directory with manifest.json, or a `train shape` output directory
    /// (shape_prior.safetensors + shape_train.json, or + shape_checkpoint.json of a run
    /// stopped at a checkpoint): its shape prior is evaluated.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    weights: PathBuf,
    /// Imported data set (output of `physnap data import`).
    #[arg(long, env = "PHYSNAP_DATA")]
    data: PathBuf,
    /// Split to evaluate: val (the target's), test, or train (to tell under- from overfitting).
    #[arg(long, env = "PHYSNAP_EVAL_SPLIT", default_value = "val")]
    split: String,
    /// Parts, spread evenly over the split (training evaluates 32 of val).
    #[arg(long, env = "PHYSNAP_EVAL_PARTS", default_value_t = 64)]
    parts: usize,
    /// IoU grid cells per axis over [-0.55, 0.55]³.
    #[arg(long, env = "PHYSNAP_EVAL_IOU_RESOLUTION", default_value_t = 64)]
    resolution: usize,
    /// Also write the report (with every part) as JSON here.
    #[arg(long, env = "PHYSNAP_EVAL_OUT")]
    out: Option<PathBuf>,
    /// Record the summary (no per-part list) under `metrics.shape` in the weights'
    /// manifest.json.
    #[arg(long, env = "PHYSNAP_EVAL_WRITE_MANIFEST")]
    write_manifest: bool,
    /// Fit each part's code to its SDF samples for this many Adam steps, decoder frozen
    /// (DeepSDF's auto-decoder inference), before measuring. Default: the encoding the
    /// weights' codebook was made with (`train encode --fit-steps`; 0 for NAP's); another
    /// count measures the decoder with other codes than the denoiser learns.
    #[arg(long, env = "PHYSNAP_EVAL_FIT_CODES")]
    fit_codes: Option<usize>,
    /// Encoder calls per part whose codes are averaged. Default: the codebook's encoding
    /// (`train encode --encoder-views`; 1 for NAP's).
    #[arg(long, env = "PHYSNAP_EVAL_ENCODER_VIEWS")]
    encoder_views: Option<usize>,
    /// SDF samples per part a fit uses. Default: the codebook's encoding (2048 for NAP's).
    #[arg(long, env = "PHYSNAP_EVAL_FIT_QUERIES")]
    fit_queries: Option<usize>,
    /// Weight λ of a fit's pull λ‖z − z₀‖² toward the encoder's code. Default: the codebook's
    /// encoding (0 for the plain fit).
    #[arg(long, env = "PHYSNAP_EVAL_FIT_PROX")]
    fit_prox: Option<f32>,
    /// Encoder input: the first N surface points of each part (cycled when a part has fewer).
    /// Default: the count the prior was trained with, which the codebook and so the denoiser
    /// use; another count measures what the encoder makes of more or fewer points.
    #[arg(long, env = "PHYSNAP_EVAL_SURFACE_POINTS")]
    surface_points: Option<usize>,
}

#[derive(Args, Debug)]
struct EvalGenerativeArgs {
    /// Weights directory with manifest.json.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    weights: PathBuf,
    /// Imported data set whose test split is the reference set.
    #[arg(long, env = "PHYSNAP_DATA")]
    data: PathBuf,
    /// Unconditional samples.
    #[arg(long, env = "PHYSNAP_SAMPLES", default_value_t = 64)]
    samples: usize,
    /// Reference (test-split) objects, chosen by the seed.
    #[arg(long, env = "PHYSNAP_EVAL_REFS", default_value_t = 64)]
    refs: usize,
    /// Category-conditioned samples per category of the test split (0: skip).
    #[arg(long, env = "PHYSNAP_EVAL_PER_CATEGORY", default_value_t = 6)]
    per_category: usize,
    /// Test objects a conditioned sample's nearest neighbour is searched among for the category
    /// accuracy (seeded choice); 0: the whole test split, the "nearest test object".
    #[arg(long, env = "PHYSNAP_EVAL_CATEGORY_REFS", default_value_t = 0)]
    category_refs: usize,
    /// Joint states per object for the instantiation distance (method.md: 10).
    #[arg(long, env = "PHYSNAP_EVAL_STATES", default_value_t = 4)]
    states: usize,
    /// Surface points per state for the instantiation distance (method.md: 2048).
    #[arg(long, env = "PHYSNAP_EVAL_POINTS", default_value_t = 512)]
    points: usize,
    /// MMD/COV/1-NNA set order: pointflow (PhysNAP, default) or nap (NAP's original code).
    #[arg(long, env = "PHYSNAP_EVAL_ORDER", default_value = "pointflow")]
    order: String,
    /// Marching-cubes grid cells per axis for the samples.
    #[arg(long, env = "PHYSNAP_MC_RESOLUTION", default_value_t = 32)]
    resolution: usize,
    /// Seed (samples, reference choice, state sampling).
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 12345)]
    seed: u64,
    /// Also write the report as JSON here.
    #[arg(long, env = "PHYSNAP_EVAL_OUT")]
    out: Option<PathBuf>,
    /// Category guidance.
    #[command(flatten)]
    category: CategoryGuidanceArgs,
    /// Record the report under `metrics` in the weights' manifest.json.
    #[arg(long, env = "PHYSNAP_EVAL_WRITE_MANIFEST")]
    write_manifest: bool,
    /// Replace part shapes by their nearest training code of the weights' codebook: auto
    /// (empty shapes when the weights have a codebook, else off), off, empty (shapes that mesh
    /// empty), all (every latent shape: NAP's retrieval variant), category (every latent shape
    /// of a category-conditioned sample, from that category's codes; samples without a
    /// category: as empty).
    #[arg(long, env = "PHYSNAP_RETRIEVAL", default_value = "auto", value_parser = ["auto", "off", "empty", "all", "category"])]
    retrieval: String,
    /// Joint motions of the projected samples: screw (default here: NAP's protocol, which the
    /// manifest's figures use; both ranges kept) or dominant (`generate`'s default: each joint
    /// keeps only its wider range, in units of the feature scales).
    #[arg(long, env = "PHYSNAP_JOINT_MOTION", default_value = "screw", value_parser = ["screw", "dominant"])]
    joint_motion: String,
    /// Reverse-step rule: ddpm (default here: the paper's sampler, which every generative
    /// figure uses) or ddim (`generate`'s default).
    #[arg(long, env = "PHYSNAP_SAMPLER", default_value = "ddpm", value_parser = ["ddpm", "ddim"])]
    sampler: String,
    /// Reverse steps (0: all 1000, the paper's; `generate` defaults to 200).
    #[arg(long, env = "PHYSNAP_STEPS", default_value_t = 0)]
    steps: usize,
    /// DDIM noise level η in [0, 1] (ddim only).
    #[arg(long, env = "PHYSNAP_DDIM_ETA", default_value_t = 0.0)]
    eta: f64,
}

#[derive(Subcommand, Debug)]
enum TrainCommand {
    /// Train the part-shape auto-encoder on an imported data set; writes weights + codebook.
    Shape(Box<ShapeArgs>),
    /// Train the articulation denoiser; writes denoiser weights, the shape prior, the retrieval
    /// codebook and manifest.json.
    Diffusion(DiffusionArgs),
    /// (Re)build the retrieval codebook of a weights directory from a `train shape` output.
    Codebook(CodebookArgs),
    /// Make a `train shape` output directory from a weights directory's shape prior (its
    /// weights, its training report and every part of --data encoded), so `train diffusion`
    /// can train a new denoiser on it without retraining the shape prior.
    Encode(EncodeArgs),
    /// Install a `train shape --freeze-encoder` output into a weights directory: its decoder
    /// replaces the installed one while every code, and so the denoiser, stays valid (refused
    /// when the encoder differs). The decoder may be larger (`train shape --init-from` with a
    /// larger `--pe-freqs`, `--decoder-hidden` or `--decoder-blocks` grows it), never
    /// smaller. Rewrites the manifest and the codebook and clears the metrics, which
    /// `eval generative --write-manifest` measures again.
    InstallShape(InstallShapeArgs),
}

#[derive(Args, Debug)]
struct InstallShapeArgs {
    /// Shape prior directory (output of `physnap train shape`, trained with --freeze-encoder
    /// from these weights).
    #[arg(long, env = "PHYSNAP_SHAPE")]
    shape: PathBuf,
    /// Weights directory to update (manifest.json + shape_prior.safetensors).
    #[arg(long, env = "PHYSNAP_WEIGHTS")]
    weights: PathBuf,
    /// Do not rebuild the retrieval codebook (≈ 1 min): for a decoder that a later cycle
    /// replaces. The old codebook, made with the old decoder, is removed; `physnap train
    /// codebook` builds one.
    #[arg(long, env = "PHYSNAP_NO_CODEBOOK")]
    no_codebook: bool,
}

#[derive(Args, Debug)]
struct EncodeArgs {
    /// Weights directory whose shape prior to use (manifest.json + shape_prior.safetensors),
    /// or a `train shape` output directory (shape_train.json + shape_prior.safetensors).
    #[arg(long, env = "PHYSNAP_WEIGHTS")]
    weights: PathBuf,
    /// Imported data set to encode (output of `physnap data import`).
    #[arg(long, env = "PHYSNAP_DATA")]
    data: PathBuf,
    /// Output shape directory (shape_prior.safetensors, shape_train.json, codebook.npy/json).
    #[arg(long, env = "PHYSNAP_OUT")]
    out: PathBuf,
    /// Encoder calls per part, each on the next block of surface points (as many as the prior
    /// was trained with); a part's code is their mean. 1: NAP's single call.
    #[arg(long, env = "PHYSNAP_ENCODER_VIEWS", default_value_t = 1)]
    encoder_views: usize,
    /// Then fit each code to its part's SDF samples for this many Adam steps, decoder frozen
    /// (DeepSDF's auto-decoder inference from the encoder's code). 0: the encoder's code.
    #[arg(long, env = "PHYSNAP_FIT_STEPS", default_value_t = 0)]
    fit_steps: usize,
    /// SDF samples per part the fit uses (half uniform, half near-surface; even).
    #[arg(long, env = "PHYSNAP_FIT_QUERIES", default_value_t = 2048)]
    fit_queries: usize,
    /// Weight λ of the fit's pull λ‖z − z₀‖² toward the encoder's code z₀, which keeps fitted
    /// codes near the encoder's (0: the plain fit).
    #[arg(long, env = "PHYSNAP_FIT_PROX", default_value_t = 0.0)]
    fit_prox: f32,
}

#[derive(Args, Debug)]
struct CodebookArgs {
    /// Shape prior directory (output of `physnap train shape`: weights + codebook.npy/json).
    #[arg(long, env = "PHYSNAP_SHAPE")]
    shape: PathBuf,
    /// Weights directory to add codebook.safetensors to (its manifest.json is updated).
    #[arg(long, env = "PHYSNAP_WEIGHTS")]
    weights: PathBuf,
    /// Meshing resolution of the check that keeps only codes that decode non-empty.
    #[arg(long, env = "PHYSNAP_CODEBOOK_CHECK_RESOLUTION", default_value_t = physnap::train::codebook::DEFAULT_CHECK_RESOLUTION)]
    check_resolution: usize,
}

#[derive(Args, Debug)]
struct ShapeArgs {
    /// Imported data set (output of `physnap data import`).
    #[arg(long, env = "PHYSNAP_DATA")]
    data: PathBuf,
    /// Output directory (shape_prior.safetensors, codebook.npy/json, shape_train.json).
    #[arg(long, env = "PHYSNAP_OUT")]
    out: PathBuf,
    /// Optimiser steps.
    #[arg(long, env = "PHYSNAP_TRAIN_STEPS", default_value_t = 3000)]
    steps: usize,
    /// Seed.
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    seed: u64,
    /// Parts per step (default: the trainer's).
    #[arg(long, env = "PHYSNAP_SHAPE_BATCH_PARTS")]
    batch_parts: Option<usize>,
    /// Use at most this many training parts.
    #[arg(long, env = "PHYSNAP_SHAPE_MAX_PARTS")]
    max_parts: Option<usize>,
    /// How the SDF decoder's gradients are computed: `host` (hand-written backward pass on the
    /// host, the fast default on the CPU) or `burn` (burn autodiff through every layer, the
    /// reference; the default with --device gpu).
    #[arg(long, env = "PHYSNAP_SHAPE_DECODER_BACKWARD", value_parser = ["host", "burn"])]
    decoder_backward: Option<String>,
    /// Where the optimiser steps run: `cpu`, or `gpu` / `gpu:N` (Vulkan) in a binary built with
    /// `--features gpu`.
    #[arg(long, env = "PHYSNAP_TRAIN_DEVICE", default_value = "cpu")]
    device: String,
    /// Start from these weights instead of the seeded initialisation: a shape_prior.safetensors
    /// of the same sizes, or a directory holding one (weights/, a train shape output).
    #[arg(long, env = "PHYSNAP_SHAPE_INIT_FROM")]
    init_from: Option<PathBuf>,
    /// Keep the encoder fixed (needs --init-from): only the decoder trains, so every part's code
    /// stays what it was and a denoiser trained on those codes stays valid.
    #[arg(long, env = "PHYSNAP_SHAPE_FREEZE_ENCODER")]
    freeze_encoder: bool,
    /// Keep the decoder fixed (needs --init-from; not with --freeze-encoder): only the encoder
    /// trains, towards the codes the decoder decodes best. Every code changes, so a denoiser
    /// must be trained on the new ones.
    #[arg(long, env = "PHYSNAP_SHAPE_FREEZE_DECODER")]
    freeze_decoder: bool,
    /// Train the decoder on fixed codes instead of the encoder's (needs --freeze-encoder): a
    /// directory with codebook.npy + codebook.json of the same data set, e.g. a `train encode`
    /// output. The decoder learns to decode exactly those codes, so a denoiser trained on them
    /// stays valid; the run's codebook is a copy of them and its report keeps their encoding.
    #[arg(long, env = "PHYSNAP_SHAPE_CODES")]
    codes: Option<PathBuf>,
    /// Evaluate val IoU every this many steps (0: only at the end).
    #[arg(long, env = "PHYSNAP_SHAPE_EVAL_EVERY", default_value_t = 1000)]
    eval_every: usize,
    /// Steps between checkpoints (weights + shape_checkpoint.json in --out; 0: none).
    #[arg(long, env = "PHYSNAP_CHECKPOINT_EVERY", default_value_t = 1000)]
    checkpoint_every: usize,
    /// Continue from the checkpoint in --out (same data and training options).
    #[arg(long, env = "PHYSNAP_RESUME")]
    resume: bool,
    /// End this run after this many steps in total, with a checkpoint (the learning-rate
    /// schedule still spans --steps; continue with --resume).
    #[arg(long, env = "PHYSNAP_SHAPE_STOP_AT")]
    stop_at: Option<usize>,
    /// SDF decoder width (default 128; NAP: 256). The latent stays 128, the denoiser's F.
    /// Above --init-from's, the decoder is grown function-preservingly (new channels unread
    /// until they train), so the codes, and the denoiser trained on them, stay valid.
    #[arg(long, env = "PHYSNAP_SHAPE_DECODER_HIDDEN")]
    decoder_hidden: Option<usize>,
    /// SDF decoder residual blocks (default 4; NAP: 5). Above --init-from's, new blocks start
    /// as identities.
    #[arg(long, env = "PHYSNAP_SHAPE_DECODER_BLOCKS")]
    decoder_blocks: Option<usize>,
    /// Point encoder width (default 128; NAP: 512).
    #[arg(long, env = "PHYSNAP_SHAPE_ENCODER_HIDDEN")]
    encoder_hidden: Option<usize>,
    /// Point encoder residual blocks (default 4; NAP: 5).
    #[arg(long, env = "PHYSNAP_SHAPE_ENCODER_BLOCKS")]
    encoder_blocks: Option<usize>,
    /// Positional-encoding octaves of the query (default 8, as NAP). Above --init-from's, the
    /// decoder is grown (as for --decoder-hidden and --decoder-blocks): training starts from
    /// the same SDF and codes.
    #[arg(long, env = "PHYSNAP_SHAPE_PE_FREQS")]
    pe_freqs: Option<usize>,
    /// Add the code to every residual block's input of the SDF decoder (ConvONet's decoder),
    /// not only to the first layer as NAP does.
    #[arg(long, env = "PHYSNAP_SHAPE_CODE_EVERY_BLOCK")]
    code_every_block: bool,
    /// SDF queries per part and step, half uniform and half near-surface (default 2048).
    #[arg(long, env = "PHYSNAP_SHAPE_QUERIES_PER_PART")]
    queries_per_part: Option<usize>,
    /// Share of the queries drawn near the surface (default 0.5, as NAP; the rest uniform).
    #[arg(long, env = "PHYSNAP_SHAPE_NEAR_FRACTION")]
    near_fraction: Option<f64>,
    /// Encoder input points per part (default 512).
    #[arg(long, env = "PHYSNAP_SHAPE_SURFACE_POINTS")]
    surface_points: Option<usize>,
    /// Adam learning rate at step 0 (default 1e-3).
    #[arg(long, env = "PHYSNAP_SHAPE_LR")]
    lr: Option<f64>,
    /// Cosine decay to lr × this at the last step (default 0.1; 1: constant).
    #[arg(long, env = "PHYSNAP_SHAPE_LR_FINAL_FACTOR")]
    lr_final_factor: Option<f64>,
    /// Truncate the L1 loss to the band [−δ, δ] (DeepSDF); default: plain L1, as NAP.
    #[arg(long, env = "PHYSNAP_SHAPE_TRUNCATION")]
    truncation: Option<f32>,
    /// Weight w of the wrong-side term w · mean relu(−f̂ · sign f): queries on the wrong side
    /// of the surface count 1 + w times (default 0: off, as NAP).
    #[arg(long, env = "PHYSNAP_SHAPE_WRONG_SIDE")]
    wrong_side: Option<f64>,
    /// Weight EMA decay, e.g. 0.999 (default 0: off). With an EMA the val IoU, the saved
    /// weights and the codebook use the averaged weights.
    #[arg(long, env = "PHYSNAP_SHAPE_EMA_DECAY")]
    ema_decay: Option<f64>,
    /// Val parts evaluated every --eval-every steps (default 32, at most 64).
    #[arg(long, env = "PHYSNAP_SHAPE_VAL_PARTS")]
    val_parts: Option<usize>,
    /// Weight of the eikonal term (|∇f| = 1 by forward differences on a quarter of the
    /// near-surface queries; default 0: off, as NAP).
    #[arg(long, env = "PHYSNAP_SHAPE_EIKONAL")]
    eikonal: Option<f64>,
    /// Each step's parts in this many slices computed in parallel (default 2: both cores busy,
    /// 1.33× the steps per second of one pass on the recipe's first prior, 1.18× on a decoder
    /// cycle; the same loss up to float rounding; 1 = the single pass of runs before
    /// 2026-11-29). At most --batch-parts.
    #[arg(long, env = "PHYSNAP_SHAPE_BATCH_SHARDS")]
    batch_shards: Option<usize>,
}

#[derive(Args, Debug)]
struct DiffusionArgs {
    /// Imported data set (output of `physnap data import`).
    #[arg(long, env = "PHYSNAP_DATA")]
    data: PathBuf,
    /// Shape prior directory (output of `physnap train shape`: weights + codebook).
    #[arg(long, env = "PHYSNAP_SHAPE")]
    shape: PathBuf,
    /// Output (weights) directory: denoiser.safetensors, shape_prior.safetensors, manifest.json.
    #[arg(long, env = "PHYSNAP_OUT")]
    out: PathBuf,
    /// Optimiser steps.
    #[arg(long, env = "PHYSNAP_TRAIN_STEPS", default_value_t = 20000)]
    steps: usize,
    /// Objects per step.
    #[arg(long, env = "PHYSNAP_DIFFUSION_BATCH_OBJECTS", default_value_t = 32)]
    batch_objects: usize,
    /// Noise levels per object per step.
    #[arg(long, env = "PHYSNAP_DIFFUSION_NOISE_LEVELS", default_value_t = 4)]
    noise_levels: usize,
    /// Adam learning rate.
    #[arg(long, env = "PHYSNAP_DIFFUSION_LR", default_value_t = 2e-4)]
    lr: f64,
    /// Denoiser width.
    #[arg(long, env = "PHYSNAP_DENOISER_WIDTH", default_value_t = 160)]
    width: usize,
    /// Denoiser graph layers.
    #[arg(long, env = "PHYSNAP_DENOISER_LAYERS", default_value_t = 4)]
    layers: usize,
    /// Also add a learned category row to every graph layer's inputs, not only to the initial
    /// embeddings (physnap's option, not the paper's; the shipped weights are trained with it).
    #[arg(long, env = "PHYSNAP_DENOISER_CATEGORY_LAYERS")]
    category_layers: bool,
    /// Seed.
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 12345)]
    seed: u64,
    /// Steps between checkpoints (0: only the one at the end of the run).
    #[arg(long, env = "PHYSNAP_CHECKPOINT_EVERY", default_value_t = 1000)]
    checkpoint_every: usize,
    /// Step from which the learning rate decays (cosine) to lr × --lr-final-factor.
    #[arg(long, env = "PHYSNAP_DIFFUSION_LR_DECAY_START", default_value_t = 0)]
    lr_decay_start: usize,
    /// Final learning rate as a fraction of --lr (1 = constant).
    #[arg(long, env = "PHYSNAP_DIFFUSION_LR_FINAL_FACTOR", default_value_t = 0.1)]
    lr_final_factor: f64,
    /// Decay of the weight EMA that is shipped as denoiser.safetensors (0 = no EMA).
    #[arg(long, env = "PHYSNAP_DIFFUSION_EMA_DECAY", default_value_t = 0.999)]
    ema_decay: f64,
    /// Continue from the checkpoint in --out.
    #[arg(long, env = "PHYSNAP_RESUME")]
    resume: bool,
    /// End this run after this many steps in total, with a checkpoint (the learning-rate
    /// schedule still spans --steps; continue with --resume). For splitting long runs.
    #[arg(long, env = "PHYSNAP_DIFFUSION_STOP_AT")]
    stop_at: Option<usize>,
    /// Min-SNR-γ loss weighting: each sample's ε-loss × min(1, γ/SNR(t)); 0 = off (NAP).
    #[arg(long, env = "PHYSNAP_DIFFUSION_MIN_SNR_GAMMA", default_value_t = 0.0)]
    min_snr_gamma: f64,
    /// High-noise weighting: each sample's ε-loss × clamp(1/SNR(t), 1, CAP), an x̂₀-loss at
    /// high noise up to the cap; 1 = off (NAP).
    #[arg(long, env = "PHYSNAP_DIFFUSION_HIGH_NOISE_CAP", default_value_t = 1.0)]
    high_noise_cap: f64,
    /// Box-overlap penalty λ: for samples with t < --overlap-max-t, x̂₀'s part boxes pay
    /// λ · (depth beyond the data pair's depth)² per intersecting pair; 0 = off (NAP).
    #[arg(long, env = "PHYSNAP_DIFFUSION_OVERLAP_WEIGHT", default_value_t = 0.0)]
    overlap_weight: f64,
    /// The box-overlap penalty counts only samples with t below this (1..=500).
    #[arg(long, env = "PHYSNAP_DIFFUSION_OVERLAP_MAX_T", default_value_t = physnap::train::diffusion::DEFAULT_OVERLAP_MAX_T)]
    overlap_max_t: usize,
    /// Layout gain G: the part boxes' and centres' feature scales are divided by G, so the
    /// layout spans G times NAP's max-abs range in model space and survives G times as much
    /// noise (0.25..=8; 1 = NAP). Recorded in the manifest's feature scales.
    #[arg(long, env = "PHYSNAP_DIFFUSION_LAYOUT_GAIN", default_value_t = physnap::train::diffusion::DEFAULT_LAYOUT_GAIN)]
    layout_gain: f64,
    /// Code gain G_z: the 128 shape-code channels' feature scales are divided by G_z, so the
    /// generated codes are denoised at G_z times NAP's max-abs range in model space
    /// (0.25..=8; 1 = NAP). Recorded in the manifest's feature scales.
    #[arg(long, env = "PHYSNAP_DIFFUSION_CODE_GAIN", default_value_t = physnap::train::diffusion::DEFAULT_CODE_GAIN)]
    code_gain: f64,
    /// Share of training samples that see the "no category" row instead of their category
    /// (0..=1): what classifier-free category guidance and unconditional sampling use.
    #[arg(long, env = "PHYSNAP_DIFFUSION_CATEGORY_DROPOUT", default_value_t = physnap::train::diffusion::DEFAULT_CATEGORY_DROPOUT)]
    category_dropout: f64,
    /// Slices each step's batch is split into, their passes run in parallel (one per core is
    /// the point; results depend on this number, not on the thread count; 1 = the single-pass
    /// step of runs before 2026-11-28). Measured on the CPU only: with `--device gpu` the
    /// slices share the one device, so 1 is likely the better choice there.
    #[arg(long, env = "PHYSNAP_DIFFUSION_BATCH_SHARDS", default_value_t = 2)]
    batch_shards: usize,
    /// Do not build the retrieval codebook (≈ 1 min) into --out: for a run that a later run
    /// continues (--stop-at, --resume) or whose decoder a later cycle replaces. `physnap train
    /// codebook` builds it.
    #[arg(long, env = "PHYSNAP_NO_CODEBOOK")]
    no_codebook: bool,
    /// Where the optimiser steps run: `cpu`, or `gpu` / `gpu:N` (Vulkan) in a binary built with
    /// `--features gpu`.
    #[arg(long, env = "PHYSNAP_TRAIN_DEVICE", default_value = "cpu")]
    device: String,
}

#[derive(Args, Debug)]
struct GenerateArgs {
    /// Weights directory with manifest.json.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    weights: PathBuf,
    /// Category (e.g. StorageFurniture); omit for unconditional generation.
    #[arg(long, env = "PHYSNAP_CATEGORY")]
    category: Option<String>,
    /// Number of samples.
    #[arg(long, env = "PHYSNAP_SAMPLES", default_value_t = 1)]
    samples: usize,
    /// Seed of the first sample (sample i uses seed + i).
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    seed: u64,
    /// Output directory (one sample_NNN folder per sample).
    #[arg(long, env = "PHYSNAP_OUT")]
    out: PathBuf,
    /// Marching-cubes grid cells per axis.
    #[arg(long, env = "PHYSNAP_MC_RESOLUTION", default_value_t = physnap::mesh::DEFAULT_RESOLUTION)]
    resolution: usize,
    /// Observed partial point cloud (PLY, NPY or JSON; object frame, metres): PhysNAP guidance
    /// (pc+pen+mob by default), samples ranked by D_pc into ranking.json.
    #[arg(long, env = "PHYSNAP_POINTS")]
    points: Option<PathBuf>,
    /// Weight of the point-cloud loss (default with --points: 45 ÷ active terms).
    #[arg(long, env = "PHYSNAP_W_PC")]
    w_pc: Option<f64>,
    /// Weight of the penetration loss (default with --points: physnap's 3 × the paper's 2 ÷
    /// active terms, 2 for pc+pen+mob; 0 turns it off).
    #[arg(long, env = "PHYSNAP_W_PEN")]
    w_pen: Option<f64>,
    /// Weight of the mobility loss (default with --points: physnap's 3 × the paper's 2 ÷ active
    /// terms, 2 for pc+pen+mob; 0 turns it off).
    #[arg(long, env = "PHYSNAP_W_MOB")]
    w_mob: Option<f64>,
    /// Sampler and guidance schedule.
    #[command(flatten)]
    sampling: SamplingArgs,
}

/// The category-guidance flag of every command that samples locally.
#[derive(Args, Debug)]
struct CategoryGuidanceArgs {
    /// Classifier-free category guidance w for category-conditioned samples:
    /// ε̂ = ε̂(c) + w·(ε̂(c) − ε̂(∅)) (0: plain conditioning; > 0 doubles the denoiser's work).
    /// Default: 2 without loss guidance, 0 when a scan guides the sample (w = 2 completed scans
    /// worse).
    #[arg(long, env = "PHYSNAP_CATEGORY_GUIDANCE")]
    category_guidance: Option<f64>,
    /// Apply the category guidance only in steps with diffusion time t below this, 1-1000;
    /// above it the plain conditional prediction is used (one forward). Default: 500 without
    /// loss guidance, 1000 (every step) when a scan guides the sample.
    #[arg(long, env = "PHYSNAP_CATEGORY_GUIDANCE_BELOW")]
    category_guidance_below: Option<usize>,
}

impl CategoryGuidanceArgs {
    /// `--category-guidance`, or its default for a sample with or without loss guidance.
    fn weight(&self, loss_guided: bool) -> f64 {
        physnap::engine::sample::category_guidance(self.category_guidance, loss_guided)
    }

    /// `--category-guidance-below`, or its default for a sample with or without loss guidance.
    fn below(&self, loss_guided: bool) -> usize {
        physnap::engine::sample::category_guidance_below(self.category_guidance_below, loss_guided)
    }
}

/// Sampler and guidance-schedule flags shared by `generate` and `eval guided`.
#[derive(Args, Debug)]
struct SamplingArgs {
    /// Guide the steps with diffusion time t < this (n_g).
    #[arg(long, env = "PHYSNAP_GUIDANCE_STEPS", default_value_t = physnap::engine::guidance::DEFAULT_GUIDED_STEPS)]
    guidance_steps: usize,
    /// Temperature τ of the point-to-part soft assignment.
    #[arg(long, env = "PHYSNAP_TAU", default_value_t = physnap::engine::guidance::DEFAULT_TAU)]
    tau: f64,
    /// Clamp each guidance-gradient entry to ±this (model space); a deviation from the paper's
    /// raw gradient, which diverges with the shipped weights. 0: off (the paper's raw step).
    #[arg(long, env = "PHYSNAP_GUIDANCE_MAX_STEP", default_value_t = physnap::engine::guidance::DEFAULT_MAX_STEP)]
    guidance_max_step: f64,
    /// Refinement: small clamped gradient steps (a tenth of --guidance-max-step) on the guidance
    /// loss of the finished sample (physnap, not in the paper; 0: off).
    #[arg(long, env = "PHYSNAP_GUIDANCE_REFINE_STEPS", default_value_t = physnap::engine::guidance::DEFAULT_REFINE_STEPS)]
    guidance_refine_steps: usize,
    /// Physics-only refinement: this many more such steps after those, on ℓ_pen and ℓ_mob alone
    /// (ℓ_pc off), which push out the small overlaps ℓ_pc holds in place (physnap; 0: off).
    #[arg(long, env = "PHYSNAP_GUIDANCE_REFINE_PHYSICS_STEPS", default_value_t = physnap::engine::guidance::DEFAULT_REFINE_PHYSICS_STEPS)]
    guidance_refine_physics_steps: usize,
    /// Reverse-step rule: ddim (default) or ddpm (NAP; strided ancestral with --steps < 1000).
    /// The paper's sampler is `--sampler ddpm --steps 0`.
    #[arg(long, env = "PHYSNAP_SAMPLER", default_value = "ddim", value_parser = ["ddpm", "ddim"])]
    sampler: String,
    /// Reverse steps (0: all 1000). Guidance applies to those with t < --guidance-steps.
    #[arg(long, env = "PHYSNAP_STEPS", default_value_t = physnap::engine::sample::DEFAULT_STEPS)]
    steps: usize,
    /// DDIM noise level η in [0, 1].
    #[arg(long, env = "PHYSNAP_DDIM_ETA", default_value_t = 0.0)]
    eta: f64,
    /// Replace part shapes by their nearest training code of the weights' codebook: auto
    /// (empty shapes when the weights have a codebook, else off), off, empty (shapes that mesh
    /// empty), all (every latent shape: NAP's retrieval variant), category (every latent shape
    /// of a category-conditioned sample, from that category's codes; samples without a
    /// category: as empty).
    #[arg(long, env = "PHYSNAP_RETRIEVAL", default_value = "auto", value_parser = ["auto", "off", "empty", "all", "category"])]
    retrieval: String,
    /// Joint motions of the projected samples: dominant (default: each joint keeps only its
    /// wider range, in units of the feature scales, so it rotates, slides or is fixed) or
    /// screw (NAP: both ranges kept).
    #[arg(long, env = "PHYSNAP_JOINT_MOTION", default_value = "dominant", value_parser = ["screw", "dominant"])]
    joint_motion: String,
    /// Category guidance.
    #[command(flatten)]
    category: CategoryGuidanceArgs,
}

#[derive(Args, Debug)]
struct EvalGuidedArgs {
    /// Weights directory with manifest.json.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    weights: PathBuf,
    /// Test scans: a `physnap data testset` folder (testset.json gives categories) or a folder
    /// of .ply/.npy/.json clouds (no categories: category-aware rows are skipped).
    #[arg(long, env = "PHYSNAP_CLOUDS")]
    clouds: PathBuf,
    /// Samples per cloud and variant (paper: 15).
    #[arg(long, env = "PHYSNAP_SAMPLES_PER_CLOUD", default_value_t = 15)]
    samples_per_cloud: usize,
    /// Use at most this many clouds (0: all; paper: 30).
    #[arg(long, env = "PHYSNAP_MAX_CLOUDS", default_value_t = 0)]
    max_clouds: usize,
    /// Skip the first N clouds (then take --max-clouds). The samples keep the seeds a run over
    /// all the clouds gives them, so two slices make up one full run's samples (the per-cloud
    /// MMD / 1-NNA references after the scanned object are drawn anew and can differ).
    #[arg(long, env = "PHYSNAP_SKIP_CLOUDS", default_value_t = 0)]
    skip_clouds: usize,
    /// Seed of the first sample.
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    seed: u64,
    /// Sampler and guidance schedule.
    #[command(flatten)]
    sampling: SamplingArgs,
    /// Marching-cubes grid cells per axis (for D_pc).
    #[arg(long, env = "PHYSNAP_MC_RESOLUTION", default_value_t = physnap::mesh::DEFAULT_RESOLUTION)]
    resolution: usize,
    /// Output directory for guided_table.md / .json.
    #[arg(long, env = "PHYSNAP_OUT")]
    out: PathBuf,
    /// Imported data set (`data import` output) holding the scanned objects and the test split:
    /// enables the per-cloud MMD / 1-NNA columns and ID_gt (each sample's instantiation distance
    /// to the object its scan came from). Without it they show "—".
    #[arg(long, env = "PHYSNAP_DATA")]
    data: Option<PathBuf>,
    /// Reference objects per cloud for MMD / 1-NNA: the scanned object, then test objects of its
    /// category (0: as many as --samples-per-cloud).
    #[arg(long, env = "PHYSNAP_REFS_PER_CLOUD", default_value_t = 0)]
    refs_per_cloud: usize,
    /// Rows to run: comma-separated variants among pc+pen+mob, pc+pen, pc+mob, pc, uncond
    /// (default: all five).
    #[arg(long, env = "PHYSNAP_VARIANTS", value_delimiter = ',')]
    variants: Vec<String>,
    /// Category-aware blocks: no, yes, or both (both when the weights are category-conditional).
    #[arg(long, env = "PHYSNAP_CATEGORY_AWARE", default_value = "both", value_parser = ["no", "yes", "both"])]
    category_aware: String,
    /// Multipliers of the paper's weights of ℓ_pc, ℓ_pen and ℓ_mob in every guided row
    /// (PC,PEN,MOB; each in [0, 100]). Default: physnap's, 1,3,3 (what `generate` and the
    /// service run); 1,1,1 is the paper's table.
    #[arg(long, env = "PHYSNAP_LOSS_SCALES", value_delimiter = ',')]
    loss_scales: Option<Vec<f64>>,
    /// Run a hyper-parameter sweep of the supplementary material instead of Table 1: pc, pen or
    /// mob (that loss alone over --sweep-ng × --sweep-weights) or tau (ℓ_pc alone over
    /// --sweep-tau); each block starts with the unguided baseline. Writes sweep_<kind>.md/json.
    #[arg(long, env = "PHYSNAP_SWEEP", value_parser = ["pc", "pen", "mob", "tau"])]
    sweep: Option<String>,
    /// n_g values of a sweep (diffusion time t < n_g is guided).
    #[arg(
        long,
        env = "PHYSNAP_SWEEP_NG",
        value_delimiter = ',',
        default_value = "100,500,1000"
    )]
    sweep_ng: Vec<usize>,
    /// Weight multipliers of a sweep (× the loss's base weight: 45, 2, 2).
    #[arg(
        long,
        env = "PHYSNAP_SWEEP_WEIGHTS",
        value_delimiter = ',',
        default_value = "0.1,0.3,1,3,10"
    )]
    sweep_weights: Vec<f64>,
    /// τ values of a `--sweep tau` (paper: 10² and 10³ were the candidates).
    #[arg(
        long,
        env = "PHYSNAP_SWEEP_TAU",
        value_delimiter = ',',
        default_value = "10,100,1000,10000"
    )]
    sweep_tau: Vec<f64>,
    /// Joint states per object of the instantiation distance (NAP: 10).
    #[arg(long, env = "PHYSNAP_ID_STATES", default_value_t = 4)]
    id_states: usize,
    /// Surface points per state of the instantiation distance (NAP: 2048).
    #[arg(long, env = "PHYSNAP_ID_POINTS", default_value_t = 256)]
    id_points: usize,
}

#[derive(Subcommand, Debug)]
enum DataCommand {
    /// Generate procedural articulated objects in the PartNet-Mobility layout.
    Synth(SynthArgs),
    /// Build the training set (graph records, part meshes, SDF samples, splits) from a
    /// folder of PartNet-Mobility-layout objects (real or synthetic).
    Import(ImportArgs),
    /// Render one partial point-cloud scan of an object folder (PartNet-Mobility layout).
    Scan(ScanArgs),
    /// Make a test set: COUNT objects of a split of an imported data set, one scan each.
    Testset(TestsetArgs),
}

#[derive(Args, Debug)]
struct SynthArgs {
    /// Output directory (one folder per object, plus synth.json).
    #[arg(long, env = "PHYSNAP_OUT")]
    out: PathBuf,
    /// Number of objects.
    #[arg(long, env = "PHYSNAP_SYNTH_OBJECTS", default_value_t = 1000)]
    objects: usize,
    /// Random seed; the same seed gives byte-identical output.
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    seed: u64,
    /// Comma-separated categories (default: all the generator supports).
    #[arg(long, env = "PHYSNAP_SYNTH_CATEGORIES", value_delimiter = ',')]
    categories: Vec<String>,
    /// Draws per object before giving up on it.
    #[arg(long, env = "PHYSNAP_SYNTH_MAX_ATTEMPTS", default_value_t = 200)]
    max_attempts: usize,
}

#[derive(Args, Debug)]
struct ImportArgs {
    /// Folder of PartNet-Mobility-layout object folders.
    #[arg(long = "partnet-mobility", env = "PHYSNAP_PARTNET_MOBILITY")]
    src: PathBuf,
    /// Output directory for the training set.
    #[arg(long, env = "PHYSNAP_OUT")]
    out: PathBuf,
    /// Seed for SDF sampling and splits.
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    seed: u64,
    /// Uniform SDF samples per part.
    #[arg(long, env = "PHYSNAP_IMPORT_UNIFORM", default_value_t = 4096)]
    uniform: usize,
    /// Near-surface SDF samples per part.
    #[arg(long, env = "PHYSNAP_IMPORT_NEAR", default_value_t = 4096)]
    near: usize,
    /// Surface points per part (shape-encoder input).
    #[arg(long, env = "PHYSNAP_IMPORT_SURFACE", default_value_t = 1024)]
    surface: usize,
}

#[derive(Args, Debug)]
struct ScanArgs {
    /// Object folder (PartNet-Mobility layout, e.g. one written by `data synth`).
    #[arg(long, env = "PHYSNAP_SCAN_OBJECT")]
    object: PathBuf,
    /// Output point cloud: .ply, .npy or .json.
    #[arg(long, env = "PHYSNAP_OUT")]
    out: PathBuf,
    /// Random seed (camera pose and pixels).
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    seed: u64,
    /// Points per scan.
    #[arg(long, env = "PHYSNAP_SCAN_POINTS", default_value_t = 1000)]
    points: usize,
    /// Also write a coloured PLY with the object's surface (grey) and the scan (red).
    #[arg(long, env = "PHYSNAP_SCAN_PREVIEW")]
    preview: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct TestsetArgs {
    /// Imported data set (output of `data import`).
    #[arg(long, env = "PHYSNAP_DATA")]
    data: PathBuf,
    /// Output directory: <id>.ply per object plus testset.json.
    #[arg(long, env = "PHYSNAP_OUT")]
    out: PathBuf,
    /// Number of objects (the paper uses 30).
    #[arg(long, env = "PHYSNAP_TESTSET_COUNT", default_value_t = 30)]
    count: usize,
    /// Split to draw from.
    #[arg(long, env = "PHYSNAP_TESTSET_SPLIT", default_value = "test")]
    split: String,
    /// Random seed (object choice, camera poses).
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    seed: u64,
}

#[derive(Args, Debug)]
struct RenderArgs {
    /// Object JSON file(s) (physnap.object/v1). Several files make a contact sheet.
    #[arg(required = true, num_args = 1.., env = "PHYSNAP_RENDER_OBJECTS", value_delimiter = ',')]
    objects: Vec<PathBuf>,
    /// Output PNG.
    #[arg(long, env = "PHYSNAP_OUT")]
    out: PathBuf,
    /// Panel size in pixels.
    #[arg(long, env = "PHYSNAP_RENDER_SIZE", default_value_t = 320)]
    size: usize,
    /// Contact-sheet columns.
    #[arg(long, env = "PHYSNAP_RENDER_COLUMNS", default_value_t = 4)]
    columns: usize,
    /// Weights directory, used to mesh parts with latent (generated) shapes.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    weights: PathBuf,
    /// Marching-cubes resolution for latent shapes.
    #[arg(long, env = "PHYSNAP_MC_RESOLUTION", default_value_t = physnap::mesh::DEFAULT_RESOLUTION)]
    resolution: usize,
}

#[derive(Args, Debug)]
struct ExportArgs {
    /// The articulated-object JSON to export (format physnap.object/v1).
    #[arg(long, env = "PHYSNAP_OBJECT")]
    object: PathBuf,

    /// Output directory (created if missing).
    #[arg(long, env = "PHYSNAP_OUT")]
    out: PathBuf,

    /// Marching-cubes grid cells per axis (8..=256).
    #[arg(long, env = "PHYSNAP_MC_RESOLUTION", default_value_t = physnap::mesh::DEFAULT_RESOLUTION)]
    resolution: usize,

    /// URDF joint effort limit written on every movable joint.
    #[arg(long, env = "PHYSNAP_JOINT_EFFORT", default_value_t = 100.0)]
    effort: f64,

    /// URDF joint velocity limit written on every movable joint.
    #[arg(long, env = "PHYSNAP_JOINT_VELOCITY", default_value_t = 1.0)]
    velocity: f64,
}

/// `--guidance-max-step` to the engine's option: 0 turns the clamp off (the paper's raw step);
/// other values, negative ones included, go to the engine, which validates them.
fn max_step(flag: f64) -> Option<f64> {
    (flag != 0.0).then_some(flag)
}

/// `--progress-interval`, set once in `main`.
static PROGRESS_INTERVAL: std::sync::OnceLock<f64> = std::sync::OnceLock::new();

/// One progress log line: "what: pos/len (pct), rate, eta".
///
/// The rate is the average since the first logged tick (`since_first`: seconds and items), or,
/// before there is one or while no item finished since, since the bar was made
/// (`since_start` seconds, `pos` items). A resumed run's bar jumps to its start position,
/// which an average since creation would count as done at once; the tick-based average does
/// not. indicatif's own rate is a short moving window that decays to 0/s between items that
/// take longer than the window (guided samples: ~20 s each), which made the ETA meaningless.
/// Slow items print as "N s each" rather than "0.05/s".
fn progress_line(
    what: &str,
    pos: u64,
    len: u64,
    since_start: f64,
    since_first: Option<(f64, u64)>,
) -> String {
    let pct = 100.0 * pos as f64 / len.max(1) as f64;
    let (secs, done) = match since_first {
        Some((s, d)) if d > 0 && s > 0.0 => (s, d),
        _ => (since_start, pos),
    };
    if done == 0 || secs <= 0.0 {
        return format!("{what}: {pos}/{len} ({pct:.1}%), eta unknown");
    }
    let rate = done as f64 / secs;
    let speed = if rate >= 1.0 {
        format!("{rate:.2}/s")
    } else {
        format!("{:.1} s each", 1.0 / rate)
    };
    let eta = len.saturating_sub(pos) as f64 / rate;
    format!("{what}: {pos}/{len} ({pct:.1}%), {speed}, eta {eta:.0}s")
}

/// A progress bar on stderr. indicatif hides it when stderr is not a terminal; then a watcher
/// thread logs "what: pos/len, rate, eta" every `--progress-interval` seconds instead, so a long
/// run under nohup, CI or docker still shows that it moves. The watcher holds only a weak
/// reference and stops when the bar is finished or dropped.
fn progress_bar(total: usize, what: &str) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::new(total as u64);
    let every = PROGRESS_INTERVAL.get().copied().unwrap_or(30.0);
    if pb.is_hidden() && every > 0.0 {
        let weak = pb.downgrade();
        let what = what.to_string();
        let spawned = std::thread::Builder::new()
            .name("progress-log".into())
            .spawn(move || {
                let started = std::time::Instant::now();
                let mut first: Option<(std::time::Instant, u64)> = None;
                loop {
                    std::thread::sleep(std::time::Duration::from_secs_f64(every));
                    let Some(pb) = weak.upgrade() else { break };
                    if pb.is_finished() {
                        break;
                    }
                    let (pos, len) = (pb.position(), pb.length().unwrap_or(0));
                    let since_first =
                        first.map(|(t, p)| (t.elapsed().as_secs_f64(), pos.saturating_sub(p)));
                    first.get_or_insert((std::time::Instant::now(), pos));
                    tracing::info!(
                        "{}",
                        progress_line(
                            &what,
                            pos,
                            len,
                            started.elapsed().as_secs_f64(),
                            since_first
                        )
                    );
                }
            });
        if let Err(e) = spawned {
            tracing::warn!("no progress logging: {e}");
        }
    }
    pb.set_style(
        indicatif::ProgressStyle::with_template(
            "{msg:>10} [{bar:40}] {pos}/{len} {per_sec} eta {eta} {prefix}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    pb.set_message(what.to_string());
    pb
}

fn main() -> ExitCode {
    let cli = Cli::parse();
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
    let _ = PROGRESS_INTERVAL.set(cli.progress_interval);
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Export(a) => export(a),
        Command::Render(a) => render(a),
        Command::Train { command } => match command {
            TrainCommand::Shape(a) => model_cmd::shape(*a),
            TrainCommand::Diffusion(a) => model_cmd::diffusion(a),
            TrainCommand::Codebook(a) => model_cmd::codebook(a),
            TrainCommand::Encode(a) => model_cmd::encode(a),
            TrainCommand::InstallShape(a) => model_cmd::install_shape(a),
        },
        Command::Generate(a) => model_cmd::generate(a),
        Command::Serve(a) => serve_cmd::serve(a),
        Command::Healthcheck(a) => serve_cmd::healthcheck(a),
        Command::Submit(a) => client_cmd::submit(a),
        Command::Watch(a) => client_cmd::watch(a),
        Command::Data { command } => match command {
            DataCommand::Synth(a) => data_cmd::synth(a),
            DataCommand::Import(a) => data_cmd::import(a),
            DataCommand::Scan(a) => data_cmd::scan(a),
            DataCommand::Testset(a) => data_cmd::testset(a),
        },
        Command::Eval { command } => match command {
            EvalCommand::Generative(a) => eval_cmd::generative(a),
            EvalCommand::Guided(a) => model_cmd::eval_guided(*a),
            EvalCommand::Shape(a) => eval_cmd::shape(a),
            EvalCommand::Reconstruction(a) => eval_cmd::reconstruction(a),
            EvalCommand::Denoiser(a) => eval_cmd::denoiser(a),
            EvalCommand::Real(a) => real_cmd::eval_real(*a),
        },
    }
}

fn render(a: RenderArgs) -> anyhow::Result<()> {
    if !(16..=4096).contains(&a.size) {
        anyhow::bail!("invalid --size: {} (must be between 16 and 4096)", a.size);
    }
    let mut items = Vec::new();
    let mut models = None;
    for path in &a.objects {
        let obj = physnap::io::object_json::read(path)
            .with_context(|| format!("reading {}", path.display()))?;
        let latent = obj
            .parts
            .iter()
            .any(|p| matches!(p.shape, physnap::PartShape::Latent(_)));
        let meshes = if latent {
            if models.is_none() {
                let loaded = physnap::io::manifest::load_models(&a.weights, &physnap::model::cpu())
                    .with_context(|| {
                        format!(
                            "{} has generated (latent) part shapes; meshing them needs the weights",
                            path.display()
                        )
                    })?;
                models = Some(loaded);
            }
            let m = models.as_ref().expect("loaded just above");
            let decoder =
                physnap::model::shape_prior::LatentSdfDecoder::new(&m.shape_prior.decoder);
            let opts = MeshingOptions {
                resolution: a.resolution,
            };
            opts.validate()?;
            physnap::mesh::mesh_parts(&obj, Some(&decoder), &opts)?
        } else {
            // No part is latent here, and only latent parts lack a primitive mesh.
            obj.parts
                .iter()
                .filter_map(physnap::mesh::primitives::part_primitive_mesh)
                .collect()
        };
        items.push((obj, meshes));
    }
    let img = if items.len() == 1 {
        physnap::render::render_limits(&items[0].0, &items[0].1, a.size)
    } else {
        physnap::render::contact_sheet(&items, a.columns, a.size)
    };
    std::fs::write(&a.out, img.to_png()).with_context(|| format!("writing {}", a.out.display()))?;
    println!("{} ({}x{})", a.out.display(), img.width, img.height);
    Ok(())
}

fn export(a: ExportArgs) -> anyhow::Result<()> {
    let obj = physnap::io::object_json::read(&a.object)
        .with_context(|| format!("reading {}", a.object.display()))?;
    let opts = ExportOptions {
        meshing: MeshingOptions {
            resolution: a.resolution,
        },
        effort: a.effort,
        velocity: a.velocity,
        ..ExportOptions::default()
    };
    opts.meshing.validate()?;
    let t0 = std::time::Instant::now();
    let meshes = mesh_parts(&obj, None, &opts.meshing)?;
    let t_mesh = t0.elapsed();
    let report = export_dir(&obj, &meshes, &a.out, &opts)
        .with_context(|| format!("exporting to {}", a.out.display()))?;
    tracing::info!(
        parts = obj.parts.len(),
        joints = obj.joints.len(),
        triangles = report.triangles.iter().sum::<usize>(),
        mesh_ms = t_mesh.as_millis() as u64,
        total_ms = t0.elapsed().as_millis() as u64,
        "exported {}",
        obj.name
    );
    for p in &report.empty_parts {
        tracing::warn!(part = %p, "part mesh is empty; it has no geometry in the outputs");
    }
    for f in &report.files {
        println!("{}", a.out.join(f).display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::progress_line;

    #[test]
    fn progress_line_rate_and_eta_for_slow_and_fast_items() {
        // Before anything finished there is no rate to extrapolate.
        assert_eq!(
            progress_line("sample", 0, 300, 30.0, None),
            "sample: 0/300 (0.0%), eta unknown"
        );
        // Slow items (20 s each): seconds per item, and the ETA of the remaining 290.
        assert_eq!(
            progress_line("sample", 10, 300, 200.0, Some((160.0, 8))),
            "sample: 10/300 (3.3%), 20.0 s each, eta 5800s"
        );
        // No item finished since the first tick: fall back to the average since the start.
        assert_eq!(
            progress_line("sample", 2, 300, 40.0, Some((10.0, 0))),
            "sample: 2/300 (0.7%), 20.0 s each, eta 5960s"
        );
        // A resumed run jumps to step 5000; the rate counts only steps done since.
        assert_eq!(
            progress_line("shape", 5090, 12000, 60.0, Some((30.0, 90))),
            "shape: 5090/12000 (42.4%), 3.00/s, eta 2303s"
        );
    }
}
