//! The category list and its fixed indices.
//!
//! Why it exists: the category-aware denoiser embeds a category *index*; the index of a
//! category must never change once weights are trained. The list is PartNet-Mobility's 46
//! categories in the order of NAP's `resource/partnet_m_split.json` (method.md §1.1, read
//! row-wise from its table), with PartNet-Mobility's CamelCase names (`meta.json` `model_cat`).
//! Lookup accepts either spelling, case-insensitively ("storagefurniture", "StorageFurniture").
//!
//! The procedural generator covers [`SYNTH_CATEGORIES`], a subset.

/// All categories, index = position. Never reorder; append only.
pub const CATEGORIES: [&str; 46] = [
    "Door",
    "Window",
    "Lighter",
    "Pen",
    "StorageFurniture",
    "Dispenser",
    "Refrigerator",
    "TrashCan",
    "Dishwasher",
    "Oven",
    "Laptop",
    "Table",
    "Globe",
    "Printer",
    "KitchenPot",
    "Faucet",
    "Box",
    "WashingMachine",
    "Eyeglasses",
    "Knife",
    "Mouse",
    "Phone",
    "Scissors",
    "Toilet",
    "Suitcase",
    "Cart",
    "Clock",
    "Camera",
    "Stapler",
    "Kettle",
    "Bottle",
    "Fan",
    "USB",
    "Toaster",
    "Chair",
    "Remote",
    "Safe",
    "CoffeeMachine",
    "Switch",
    "Keyboard",
    "Bucket",
    "Pliers",
    "Lamp",
    "FoldingChair",
    "Microwave",
    "Display",
];

/// Categories the procedural generator produces.
pub const SYNTH_CATEGORIES: [&str; 13] = [
    "StorageFurniture",
    "Table",
    "Refrigerator",
    "Microwave",
    "Oven",
    "Dishwasher",
    "WashingMachine",
    "Laptop",
    "Box",
    "Suitcase",
    "TrashCan",
    "Door",
    "Window",
];

/// Index of a category name (either spelling, any case).
pub fn category_index(name: &str) -> Option<usize> {
    CATEGORIES
        .iter()
        .position(|c| c.eq_ignore_ascii_case(name.trim()))
}

/// Canonical (CamelCase) name of a category given in any spelling.
pub fn canonical_name(name: &str) -> Option<&'static str> {
    category_index(name).map(|i| CATEGORIES[i])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indices_are_fixed() {
        assert_eq!(category_index("door"), Some(0));
        assert_eq!(category_index("StorageFurniture"), Some(4));
        assert_eq!(category_index("storagefurniture"), Some(4));
        assert_eq!(category_index("Microwave"), Some(44));
        assert_eq!(category_index("display"), Some(45));
        assert_eq!(category_index("spaceship"), None);
        for c in SYNTH_CATEGORIES {
            assert!(category_index(c).is_some(), "{c}");
        }
        let mut sorted = CATEGORIES.to_vec();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), 46);
    }
}
