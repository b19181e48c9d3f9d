//! The procedural generator of articulated objects (data.md §C.5).
//!
//! Why it exists: the shape and diffusion priors need thousands of articulated objects with
//! exact part shapes and PartNet-Mobility-like structure, and PartNet-Mobility itself cannot be
//! downloaded here. [`generate`] draws one object of a category from a seeded [`Rng`];
//! [`generate_valid`] redraws until [`validity::check`] passes.
//!
//! Conventions (data.md §C.5, ARCHITECTURE.md "Canonical frame"): metres, +Z up, the front
//! faces −X, floor at z = 0, roughly centred on x = y = 0, never rotated. Rest state q = 0 is
//! closed; every range is `[0, upper]` with the sign carried by the axis, so "open" is
//! positive: doors swing outward (towards −X), drawers slide along −X, bottom-hinged doors
//! rotate about −Y, lids about +Y through their back bottom edge. A joint's `origin` is the
//! child's attachment point (a door: a point on the hinge edge; a drawer: the front centre of
//! the drawer when closed). Parts are unions of analytic primitives with tight boxes; labels
//! come from PartNet-Mobility's vocabulary. Handles and knobs are sometimes parts of their own
//! (fixed or revolute joints) and sometimes merged into their door or drawer, as in
//! PartNet-Mobility.
//!
//! Determinism: everything is drawn from the given [`Rng`], so the same state gives the same
//! object on every machine.
//!
//! Layout: `parts` holds the shared builders, `furniture`, `appliances` and `misc` the
//! categories.

mod appliances;
mod furniture;
mod misc;
pub(crate) mod parts;

use crate::data::categories::{SYNTH_CATEGORIES, canonical_name};
use crate::data::rng::Rng;
use crate::data::validity::{self, ValidityOptions};
use crate::data::{DataError, LabelledObject};
use crate::error::CoreError;

/// Draw one object of `category` (any spelling of one of [`SYNTH_CATEGORIES`]).
///
/// The object is structurally valid (`validate()` passed) but not necessarily physically valid;
/// use [`generate_valid`] for objects that pass [`validity::check`].
pub fn generate(category: &str, rng: &mut Rng) -> Result<LabelledObject, DataError> {
    let canonical = canonical_name(category)
        .filter(|c| SYNTH_CATEGORIES.contains(c))
        .ok_or_else(|| {
            DataError::Option(crate::error::Invalid {
                field: "category".into(),
                limit: format!("one of {}", SYNTH_CATEGORIES.join(", ")),
                value: format!("{category:?}"),
            })
        })?;
    match canonical {
        "StorageFurniture" => furniture::storage_furniture(rng),
        "Table" => furniture::table(rng),
        "Refrigerator" => appliances::refrigerator(rng),
        "Microwave" => appliances::microwave(rng),
        "Oven" => appliances::oven(rng),
        "Dishwasher" => appliances::dishwasher(rng),
        "WashingMachine" => appliances::washing_machine(rng),
        "Laptop" => misc::laptop(rng),
        "Box" => misc::box_(rng),
        "Suitcase" => misc::suitcase(rng),
        "TrashCan" => misc::trash_can(rng),
        "Door" => misc::door(rng),
        "Window" => misc::window(rng),
        other => unreachable!("SYNTH_CATEGORIES lists {other} but generate does not"),
    }
}

/// Draws behind [`typical_diagonal`].
const TYPICAL_DRAWS: usize = 64;

/// The median box diagonal (metres, at rest) of `category`'s procedural objects — the size the
/// prior trained on them draws — from [`TYPICAL_DRAWS`] draws of a fixed seed; None for a
/// category the generator does not make.
pub fn typical_diagonal(category: &str) -> Option<f64> {
    median_diagonal(&[category])
}

/// The median box diagonal over every category the generator makes ([`TYPICAL_DRAWS`] draws of
/// each): the prior's typical size for a category it has no objects of, or for no category.
pub fn typical_diagonal_any() -> f64 {
    median_diagonal(&SYNTH_CATEGORIES).unwrap_or(1.0)
}

/// The size the prior draws for `category`: its [`typical_diagonal`], or
/// [`typical_diagonal_any`] for no category or one the generator does not make (what
/// `--scale auto` scales a scan to, in the CLI and the service alike).
pub fn prior_diagonal(category: Option<&str>) -> f64 {
    category
        .and_then(typical_diagonal)
        .unwrap_or_else(typical_diagonal_any)
}

fn median_diagonal(categories: &[&str]) -> Option<f64> {
    let mut d: Vec<f64> = Vec::new();
    for c in categories {
        let mut rng = Rng::new(0x007e_512e);
        d.extend(
            (0..TYPICAL_DRAWS)
                .filter_map(|_| generate(c, &mut rng).ok())
                .map(|o| o.object.box_diagonal())
                .filter(|d| d.is_finite() && *d > 0.0),
        );
    }
    if d.is_empty() {
        return None;
    }
    d.sort_by(f64::total_cmp);
    Some(d[d.len() / 2])
}

/// Draw objects of `category` until one passes [`validity::check`] with default options;
/// returns it and the number of rejected draws. After `max_attempts` draws without success the
/// error names the category, the number of attempts and the last violation.
pub fn generate_valid(
    category: &str,
    rng: &mut Rng,
    max_attempts: usize,
) -> Result<(LabelledObject, usize), DataError> {
    if max_attempts == 0 {
        return Err(DataError::Option(crate::error::Invalid {
            field: "max_attempts".into(),
            limit: ">= 1".into(),
            value: "0".into(),
        }));
    }
    let opts = ValidityOptions::default();
    let mut last = None;
    for attempt in 0..max_attempts {
        let obj = generate(category, rng)?;
        match validity::check(&obj.object, &opts) {
            Ok(()) => return Ok((obj, attempt)),
            Err(v) => last = Some(v),
        }
    }
    let last = last.map(|v| v.to_string()).unwrap_or_default();
    Err(DataError::Core(CoreError::Structure(format!(
        "no physically valid {category} object in {max_attempts} attempts (last failure: {last})"
    ))))
}

#[cfg(test)]
mod tests;
