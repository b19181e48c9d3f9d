//! Stable, safe names for URDF links/joints, mesh files and glTF nodes.
//!
//! Why it exists: part names come from users and data sets ("Door #2", "抽屉", "") but end up
//! as XML attribute values and file names. A safe name uses only `[A-Za-z0-9_]`, does not
//! start with a digit, is unique within the object and never looks like a name the writers
//! derive from a link (`<link>_screw_helper`, `<link>_collision_<k>`: such a part name gets
//! `_part` appended); the mapping depends only on the names and their order, so re-exporting
//! gives the same names.

/// The URDF link / MJCF body name of every part: [`safe_unique`] of the part names.
pub fn link_names(obj: &crate::object::ArticulatedObject) -> Vec<String> {
    safe_unique(&obj.parts.iter().map(|p| p.name.clone()).collect::<Vec<_>>())
}

/// One safe, unique name per input name, in order.
pub fn safe_unique(names: &[String]) -> Vec<String> {
    let mut out: Vec<String> = Vec::with_capacity(names.len());
    for n in names {
        let mut s: String = n
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
            .collect();
        if s.is_empty() || s.starts_with(|c: char| c.is_ascii_digit()) {
            s.insert_str(0, "part_");
        }
        s.truncate(64);
        if derived(&s) {
            s.push_str("_part");
        }
        let base = s.clone();
        let mut k = 2;
        while out.contains(&s) || RESERVED.contains(&s.as_str()) || derived(&s) {
            s = format!("{base}_{k}");
            if derived(&s) {
                // `x_collision` + `_2` would read as a collision piece of `x`.
                s = format!("{base}_part_{k}");
            }
            k += 1;
        }
        out.push(s);
    }
    out
}

/// Names we generate for helper links and joints; parts may not take them.
const RESERVED: &[&str] = &["world"];

/// Whether `s` has the form of a name the writers derive from a link name: the URDF's screw
/// helper link `<link>_screw_helper`, collision mesh files and geoms `<link>_collision_<k>`.
fn derived(s: &str) -> bool {
    if s.ends_with("_screw_helper") {
        return true;
    }
    let digits = s.trim_end_matches(|c: char| c.is_ascii_digit());
    digits.len() < s.len() && digits.ends_with("_collision_")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_safe_unique_and_stable() {
        let input: Vec<String> = ["Door #2", "Door_2", "", "3rd", "body", "body"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let out = safe_unique(&input);
        assert_eq!(
            out,
            ["Door__2", "Door_2", "part_", "part_3rd", "body", "body_2"]
        );
        assert_eq!(out, safe_unique(&input));
        assert_eq!(safe_unique(&out), out, "safe names map to themselves");
    }

    #[test]
    fn names_the_writers_derive_are_not_taken() {
        let input: Vec<String> = [
            "door",
            "door_collision_0",
            "lid_screw_helper",
            "a_collision_",
            "x_collision",
            "x collision",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        let out = safe_unique(&input);
        assert_eq!(
            out,
            [
                "door",
                "door_collision_0_part",
                "lid_screw_helper_part",
                "a_collision_",
                "x_collision",
                "x_collision_part_2"
            ]
        );
        assert_eq!(safe_unique(&out), out);
    }
}
