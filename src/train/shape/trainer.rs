//! The training loop of `physnap train shape`: steps, evaluation, checkpoints, the final
//! codebook and report.

#[allow(unused_imports)]
use super::*;
use crate::data::rng::Rng;
use crate::model::shape_prior::ShapePrior;
use crate::model::{Compute, cpu};
use crate::train::TrainError;
use crate::train::ema::Ema;
use burn::module::Module;
use burn::optim::{AdamConfig, ModuleOptimizer};
use burn::tensor::Device;
use rayon::prelude::*;
use serde_json::json;
use std::time::Instant;

/// The optimisation state of a run: model, Adam, batch sampler.
pub(crate) struct Trainer<'a> {
    pub(crate) cfg: &'a ShapeTrainConfig,
    pub(crate) parts: &'a [PartSamples],
    /// The training parts' fixed codes (`codes_from`).
    pub(crate) codes: Option<&'a FixedCodes>,
    /// Always `Some` between steps (taken by value for the optimiser, so parameters are
    /// updated in place rather than copied).
    pub(crate) model: Option<ShapePrior>,
    pub(crate) optim: ModuleOptimizer,
    pub(crate) rng: Rng,
    /// What is left of the current shuffled epoch (popped from the back).
    pub(crate) epoch: Vec<usize>,
    /// The weight EMA (`ema_decay > 0`).
    pub(crate) ema: Option<Ema>,
    pub(crate) device: Device,
}

impl<'a> Trainer<'a> {
    /// The run's starting point: `init_from`'s weights, else the seeded initialisation.
    pub(crate) fn new(
        cfg: &'a ShapeTrainConfig,
        parts: &'a [PartSamples],
        codes: Option<&'a FixedCodes>,
    ) -> Result<Self, TrainError> {
        let device = cfg.compute.autodiff();
        let model = match &cfg.init_from {
            Some(init) => load_init(init, &cfg.model, cfg.seed, &device)?,
            None => ShapePrior::with_seed(&cfg.model, cfg.seed, &device),
        };
        Ok(Trainer {
            cfg,
            parts,
            codes,
            ema: (cfg.ema_decay > 0.0).then(|| Ema::new(&model, cfg.ema_decay, 0)),
            model: Some(model),
            optim: AdamConfig::new().with_epsilon(1e-8).init(),
            rng: Rng::fork(cfg.seed, 1),
            epoch: Vec::new(),
            device,
        })
    }

    /// One optimiser step (0-based `step`): (loss, learning rate).
    pub(crate) fn step(&mut self, step: usize) -> Result<(f64, f64), TrainError> {
        let cfg = self.cfg;
        let mut order = Vec::with_capacity(cfg.batch_parts);
        while order.len() < cfg.batch_parts {
            if self.epoch.is_empty() {
                self.epoch = (0..self.parts.len()).collect();
                for i in (1..self.epoch.len()).rev() {
                    self.epoch.swap(i, self.rng.int(0, i));
                }
            }
            order.extend(self.epoch.pop());
        }
        let batch = sample_batch(self.parts, &order, cfg, self.codes, &mut self.rng);
        let model = self.model.take().expect("model is present between steps");
        let (value, grads) = sharded_loss(&model, batch, cfg, &self.device);
        if !value.is_finite() || value > DIVERGED_LOSS {
            return Err(TrainError::Diverged { step, loss: value });
        }
        let lr = cfg.lr_at(step);
        let model = self.optim.step(lr, model, grads);
        if let Some(ema) = self.ema.as_mut() {
            ema.update(&model);
        }
        self.model = Some(model);
        Ok((value, lr))
    }

    /// The raw (last-iterate) model in inference mode.
    pub(crate) fn raw_model(&self) -> ShapePrior {
        self.model
            .as_ref()
            .expect("model is present between steps")
            .valid()
    }

    /// The model the run evaluates and saves, on the CPU: the EMA weights when there is an
    /// EMA, else the raw ones.
    pub(crate) fn inference_model(&self) -> ShapePrior {
        let model = match &self.ema {
            Some(ema) => ema.install(self.raw_model()),
            None => self.raw_model(),
        };
        match self.cfg.compute {
            Compute::Cpu => model,
            Compute::Gpu(_) => model.to_device(&cpu()),
        }
    }
}

/// Train the shape prior on `data` (a `physnap data import` output) and write weights, codebook
/// and report into `out`. `progress` is called after every step.
pub fn train_shape(
    data: &Path,
    cfg: &ShapeTrainConfig,
    out: &Path,
    progress: &mut dyn FnMut(&ShapeTrainProgress),
) -> Result<ShapeTrainReport, TrainError> {
    cfg.validate()?;
    let Some(n) = cfg.threads else {
        return run(data, cfg, out, progress);
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build()
        .map_err(|e| TrainError::config("threads", "a buildable thread pool", e))?;
    // Burn runs on the *current* rayon pool, so the loop runs inside `pool`; `progress` need
    // not be `Send`, so it is called here, on the caller's thread, from a channel.
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::scope(|s| {
        let worker = s.spawn(move || {
            pool.install(|| {
                run(data, cfg, out, &mut |p| {
                    let _ = tx.send(p.clone());
                })
            })
        });
        for p in rx {
            progress(&p);
        }
        worker
            .join()
            .unwrap_or_else(|e| std::panic::resume_unwind(e))
    })
}

pub(crate) fn mean_of(xs: &[f64]) -> f64 {
    xs.iter().sum::<f64>() / xs.len().max(1) as f64
}

pub(crate) fn run(
    data: &Path,
    cfg: &ShapeTrainConfig,
    out: &Path,
    progress: &mut dyn FnMut(&ShapeTrainProgress),
) -> Result<ShapeTrainReport, TrainError> {
    let t0 = Instant::now();
    let all = read_index(data)?;
    let mut train: Vec<&PartRef> = all.iter().filter(|p| p.split == "train").collect();
    if let Some(m) = cfg.max_parts {
        train.truncate(m);
    }
    if train.is_empty() {
        return Err(TrainError::data(
            data.join("dataset.json"),
            "no train parts (split \"train\")",
        ));
    }
    let fixed = match &cfg.codes_from {
        Some(dir) => Some(FixedCodes::read(dir, cfg.model.latent, &train)?),
        None => None,
    };
    // What the run's evaluations encode the val parts by: the fixed codes' encoding, else
    // NAP's (the encoder's code).
    let encoding = fixed
        .as_ref()
        .map_or_else(Encoding::default, |f| f.encoding);
    let val_refs = val_selection(&all, cfg);
    let parts: Vec<PartSamples> = train
        .par_iter()
        .map(|p| load_part(data, p))
        .collect::<Result<_, _>>()?;
    let grid_pts = iou_grid(cfg.iou_resolution);
    let val: Vec<ValPart> = val_refs
        .iter()
        .map(|p| load_val_part(data, p, cfg, &encoding, &grid_pts))
        .collect::<Result<_, _>>()?;
    let grid: Vec<f32> = grid_pts.into_iter().flatten().collect();
    std::fs::create_dir_all(out).map_err(TrainError::io(out))?;

    let mut trainer = Trainer::new(cfg, &parts, fixed.as_ref())?;
    let mut losses = Vec::with_capacity(cfg.steps);
    let mut curve = Vec::new();
    let mut train_s = 0.0;
    // Seconds of training before this run (resumed runs), so `elapsed_s` spans the whole run.
    let mut elapsed_before = 0.0;
    let mut start = 0;
    let ckpt_path = out.join(CHECKPOINT_FILE);
    if cfg.resume && ckpt_path.is_file() {
        let c = read_checkpoint(out, cfg)?;
        trainer.model = Some(load_shape_prior(
            &out.join(WEIGHTS_FILE),
            &cfg.model,
            &trainer.device,
        )?);
        if let Some(steps) = c.ema_steps {
            let path = out.join(EMA_CHECKPOINT_FILE);
            let averaged = load_shape_prior(&path, &cfg.model, &trainer.device)?;
            trainer.ema = Some(Ema::new(&averaged, cfg.ema_decay, steps));
        }
        trainer.rng = Rng::from_state(c.rng_state);
        trainer.epoch = c.epoch;
        (losses, curve, train_s, elapsed_before, start) =
            (c.losses, c.curve, c.train_s, c.elapsed_s, c.step);
    }
    if cfg.freeze_encoder || cfg.freeze_decoder {
        let mut model = trainer
            .model
            .take()
            .expect("model is present between steps");
        if cfg.freeze_encoder {
            model.encoder = model.encoder.no_grad();
        }
        if cfg.freeze_decoder {
            model.decoder = model.decoder.no_grad();
        }
        trainer.model = Some(model);
    }
    let end = cfg.stop_at.unwrap_or(cfg.steps).max(start);
    let t_train = Instant::now();
    for step in start..end {
        let t_step = Instant::now();
        let (value, lr) = trainer.step(step)?;
        train_s += t_step.elapsed().as_secs_f64();
        losses.push(value);
        let done = step + 1;
        let eval_now = done == cfg.steps || (cfg.eval_every > 0 && done % cfg.eval_every == 0);
        let (mut val_iou, mut val_l1) = (None, None);
        if eval_now && !val.is_empty() {
            let (ious, l1) = evaluate(&trainer.inference_model(), &val, cfg, &grid, &encoding);
            let iou = ious.iter().sum::<f64>() / ious.len() as f64;
            let elapsed_s = elapsed_before + t_train.elapsed().as_secs_f64();
            curve.push(EvalPoint {
                step: done,
                elapsed_s,
                iou,
                l1,
            });
            (val_iou, val_l1) = (Some(iou), Some(l1));
        }
        progress(&ShapeTrainProgress {
            step: done,
            steps: cfg.steps,
            loss: value,
            lr,
            elapsed_s: elapsed_before + t_train.elapsed().as_secs_f64(),
            val_iou,
            val_l1,
        });
        let checkpoint_now =
            done == end || (cfg.checkpoint_every > 0 && done.is_multiple_of(cfg.checkpoint_every));
        if done < cfg.steps && checkpoint_now {
            write_checkpoint(
                out,
                cfg,
                &trainer,
                &Checkpoint {
                    step: done,
                    rng_state: trainer.rng.state(),
                    epoch: trainer.epoch.clone(),
                    losses: losses.clone(),
                    curve: curve.clone(),
                    train_s,
                    elapsed_s: elapsed_before + t_train.elapsed().as_secs_f64(),
                    ema_steps: None,
                },
            )?;
        }
    }
    let report = |codebook_rows: usize, curve: Vec<EvalPoint>| ShapeTrainReport {
        steps: end,
        wall_s: t0.elapsed().as_secs_f64(),
        train_s,
        initial_loss: mean_of(&losses[..losses.len().min(20)]),
        final_loss: mean_of(&losses[losses.len().saturating_sub(50)..]),
        val_iou: curve.last().map(|e| e.iou),
        curve,
        train_parts: parts.len(),
        val_parts: val.len(),
        codebook_rows,
        queries_per_s: (losses.len() * cfg.batch_parts * cfg.queries_per_part) as f64
            / train_s.max(1e-9),
    };
    if end < cfg.steps {
        // Stopped early (`stop_at`): the checkpoint holds the run; no final outputs yet.
        return Ok(report(0, curve));
    }

    let model = trainer.inference_model();
    save_shape_prior(&model, &out.join(WEIGHTS_FILE))?;
    let codebook_rows = match &fixed {
        Some(f) => f.copy_to(out)?,
        None => write_codebook(
            &model,
            data,
            &all,
            cfg,
            &Encoding::default(),
            out,
            &mut |_, _| {},
        )?,
    };
    let report = report(codebook_rows, curve);
    let mut doc = json!({
        "format": REPORT_FORMAT,
        "config": cfg.to_json(),
        "data": data.display().to_string(),
        "steps": report.steps,
        "wall_s": report.wall_s,
        "train_s": report.train_s,
        "initial_loss": report.initial_loss,
        "final_loss": report.final_loss,
        "val_iou": report.val_iou,
        "curve": report.curve.iter().map(EvalPoint::to_json).collect::<Vec<_>>(),
        "train_parts": report.train_parts,
        "val_parts": report.val_parts,
        "codebook_rows": report.codebook_rows,
        "queries_per_s": report.queries_per_s,
        "weights": WEIGHTS_FILE,
        "threads": rayon::current_num_threads(),
        "device": cfg.compute.name(),
    });
    if encoding != Encoding::default() {
        // As `encode_shape_dir` records it: what `eval shape` and `train diffusion` check.
        doc["encoding"] = encoding.to_json();
    }
    write_atomic(
        &out.join(REPORT_FILE),
        serde_json::to_string_pretty(&doc)
            .unwrap_or_default()
            .as_bytes(),
    )?;
    // The run is complete: a leftover checkpoint would describe older weights.
    for path in [ckpt_path, out.join(EMA_CHECKPOINT_FILE)] {
        if path.is_file() {
            std::fs::remove_file(&path).map_err(TrainError::io(&path))?;
        }
    }
    Ok(report)
}
