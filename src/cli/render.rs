//! `physnap render`: objects drawn to a PNG (one object at rest and at its limits, or a contact sheet).

use anyhow::Context;
use clap::Args;
use physnap::mesh::MeshingOptions;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub(crate) struct RenderArgs {
    /// Object JSON file(s) (physnap.object/v1). Several files make a contact sheet.
    #[arg(required = true, num_args = 1.., env = "PHYSNAP_RENDER_OBJECTS", value_delimiter = ',')]
    pub(crate) objects: Vec<PathBuf>,
    /// Output PNG.
    #[arg(long, env = "PHYSNAP_OUT")]
    pub(crate) out: PathBuf,
    /// Panel size in pixels.
    #[arg(long, env = "PHYSNAP_RENDER_SIZE", default_value_t = 320)]
    pub(crate) size: usize,
    /// Contact-sheet columns.
    #[arg(long, env = "PHYSNAP_RENDER_COLUMNS", default_value_t = 4)]
    pub(crate) columns: usize,
    /// Weights directory, used to mesh parts with latent (generated) shapes.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    pub(crate) weights: PathBuf,
    /// Marching-cubes resolution for latent shapes.
    #[arg(long, env = "PHYSNAP_MC_RESOLUTION", default_value_t = physnap::mesh::DEFAULT_RESOLUTION)]
    pub(crate) resolution: usize,
}

pub(crate) fn render(a: RenderArgs) -> anyhow::Result<()> {
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
